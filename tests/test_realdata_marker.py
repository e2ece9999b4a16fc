"""The ``realdata`` marker and the check that CI ran the real-data tests (tests/conftest.py, issue 15)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ONE = "tests/io/test_every_real_file.py::test_the_table_covers_every_file"


def _pytest(*args, **env):
    environment = {k: v for k, v in os.environ.items() if k != "HANDCAP_REQUIRE_REALDATA"}
    environment.update(env)
    # Without the hypothesis plugin (a second of imports each time; these runs use none of it).
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:hypothesispytest", *args]
    return subprocess.run(command, cwd=REPO, env=environment, capture_output=True, text=True, timeout=120)


def test_tests_that_read_the_shared_data_carry_the_marker():
    done = _pytest("--collect-only", "-m", "realdata", "tests/io/test_every_real_file.py", "tests/core/test_errors.py")
    assert done.returncode == 0, done.stdout + done.stderr
    collected = [line for line in done.stdout.splitlines() if "::" in line]
    assert collected and all(line.startswith("tests/io/test_every_real_file.py::") for line in collected)


def test_a_run_required_to_read_real_data_fails_when_none_ran(tmp_path):
    absent = str(tmp_path / "no-data")
    skipped = _pytest(ONE, HANDCAP_SHARED_DATA=absent)
    assert skipped.returncode == 0 and "1 skipped" in skipped.stdout
    required = _pytest(ONE, HANDCAP_SHARED_DATA=absent, HANDCAP_REQUIRE_REALDATA="1")
    assert required.returncode == 1
    assert "HANDCAP_REQUIRE_REALDATA is set but no real-data test ran" in required.stdout
    # Left out on purpose: not a failure.
    assert _pytest(ONE, "-m", "not realdata", HANDCAP_SHARED_DATA=absent,
                   HANDCAP_REQUIRE_REALDATA="1").returncode == 5  # no test collected


@pytest.mark.realdata
def test_with_the_data_the_required_run_passes(shared_data):
    assert _pytest(ONE, HANDCAP_SHARED_DATA=str(shared_data), HANDCAP_REQUIRE_REALDATA="1").returncode == 0
