"""Run independent chunks of work in parallel: a local process pool, or a Dask cluster.

The work of a long session splits into chunks (blocks of frames to
triangulate, later images to search for markers) that need nothing from each
other. :func:`map_chunks` runs a function over them and returns the results in
the order of the chunks, whichever way it runs:

* ``scheduler=None`` (default): a pool of local worker processes, one per core
  (``workers`` to choose); one worker or one chunk runs in this process.
* ``scheduler="tcp://HOST:PORT"``: the workers of a running Dask cluster
  (``dask scheduler`` plus ``dask worker`` on each machine, or a
  ``distributed.LocalCluster``); the workers need handcap installed.
* ``scheduler`` a ``distributed.Client``: that client's cluster.

The function and its chunks must be picklable (a module-level function and
plain data), and the result of each chunk depends only on the chunk, so every
way gives the same results, bit for bit.

Scripts without a ``if __name__ == "__main__":`` guard
--------------------------------------------------------
Local workers start as fresh interpreters ("spawn"), and Python's
multiprocessing makes each of them import the main script again so that
functions defined there can be found. A plain script that calls handcap at its
top level would then run again in every worker, try to start workers of its
own there, and the pool would break (``BrokenProcessPool``). When ``func``
lives in a module of its own (every handcap function does), the workers need
nothing from the main script, so :func:`map_chunks` starts them without it;
only a function defined in the main script still needs the guard.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import sys
import types
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from handcap.core.errors import HandcapError

# How long to try reaching a Dask scheduler before giving up.
_CONNECT_TIMEOUT = "5s"


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def idle_workers() -> int:
    """Cores this process may use that other work is not already using (at least 1).

    The one-minute load average counts the runnable processes of the whole machine (this one
    included), so ``os.cpu_count() - load + 1`` cores are idle, at most :func:`default_workers`.
    Without a load average (Windows), every core available counts as idle.
    """
    cores = default_workers()
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        return cores
    return int(max(1, min(cores, np.floor((os.cpu_count() or cores) - load + 1))))


def map_chunks(func: Callable, chunks: Sequence, *, scheduler=None, workers: int | None = None,
               progress: bool | None = None, desc: str = "chunks") -> list:
    """``[func(chunk) for chunk in chunks]``, computed in parallel.

    Parameters
    ----------
    func : callable
        A module-level function of one argument.
    chunks : sequence
        Its arguments, picklable.
    scheduler : None, str or distributed.Client
        None for local processes; ``"tcp://HOST:PORT"`` (or any address Dask
        accepts) for a Dask scheduler; or a connected client.
    workers : int, optional
        Local processes (default: the cores available). Ignored with a scheduler.
    progress : bool, optional
        Show a progress bar; default when standard error is a terminal.
    desc : str
        Label of the progress bar.

    Returns
    -------
    list
        The results, in the order of ``chunks``.

    Raises
    ------
    HandcapError
        A bad ``workers`` or ``scheduler``, or a scheduler that cannot be
        reached; errors raised by ``func`` reach the caller unchanged.
    """
    chunks = list(chunks)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise HandcapError(f"workers must be a whole number of at least 1, got {workers!r}")
    show = sys.stderr.isatty() if progress is None else bool(progress)
    if scheduler is not None:
        return _map_dask(func, chunks, scheduler, show, desc)
    workers = min(workers or default_workers(), len(chunks))
    bar = _bar(len(chunks), show, desc)
    try:
        if workers <= 1:
            results = []
            for chunk in chunks:
                results.append(func(chunk))
                bar.update()
            return results
        # spawn: a clean interpreter per worker, safe whatever threads this process runs.
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            with _main_script_hidden(func):  # the workers start while the chunks are submitted
                futures = [pool.submit(func, chunk) for chunk in chunks]
            for future in futures:
                future.add_done_callback(lambda _: bar.update())
            return [future.result() for future in futures]
    finally:
        bar.close()


@contextlib.contextmanager
def _main_script_hidden(func):
    """Start spawned workers without re-running the main script, when ``func`` does not come from it.

    multiprocessing's spawn tells each new worker to import ``sys.modules["__main__"]`` (by its
    ``__spec__`` name or its ``__file__``) before it unpickles the work; an unguarded script would
    run again there (see the module docstring). While the workers start, an empty stand-in takes
    the main module's place in ``sys.modules`` only; the script's own code keeps its globals.
    """
    while isinstance(func, functools.partial):
        func = func.func
    main = sys.modules.get("__main__")
    if main is None or getattr(func, "__module__", "__main__") == "__main__" or (
            getattr(main, "__spec__", None) is None and getattr(main, "__file__", None) is None):
        yield
        return
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        sys.modules["__main__"] = main


def _map_dask(func, chunks, scheduler, show, desc) -> list:
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover - a dependency
        raise HandcapError("--scheduler needs dask.distributed: pip install 'dask[distributed]'") from None
    own = not isinstance(scheduler, Client)
    if own:
        if not isinstance(scheduler, str) or not scheduler.strip():
            raise HandcapError(f"scheduler must be an address such as tcp://HOST:8786, got {scheduler!r}")
        try:
            client = Client(scheduler, timeout=_CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as err:
            raise HandcapError(f"cannot reach the Dask scheduler at {scheduler} ({err})") from None
    else:
        client = scheduler
    bar = _bar(len(chunks), show, desc)
    try:
        # Chunks go to the workers first, so the task graph stays small whatever their size.
        futures = client.map(func, client.scatter(chunks), pure=False)
        for _ in as_completed(futures, loop=client.loop):
            bar.update()
        return client.gather(futures)
    finally:
        bar.close()
        if own:
            client.close()


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _bar(total: int, show: bool, desc: str):
    if not show:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="chunk", leave=False)


__all__ = ["default_workers", "idle_workers", "map_chunks"]
