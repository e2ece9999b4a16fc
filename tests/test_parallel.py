"""handcap.parallel: the same ordered results serially, on local processes and on a Dask cluster."""

import math

import pytest

from handcap import HandcapError
from handcap.core.checks import check_rate
from handcap.parallel import map_chunks

# Workers are separate interpreters: the functions must be importable there (not defined in a test module).
NUMBERS = list(range(40, 0, -1))
EXPECTED = [math.factorial(n) for n in NUMBERS]


@pytest.mark.parametrize("workers", [1, 2])
def test_local_results_come_in_order(workers):
    assert map_chunks(math.factorial, NUMBERS, workers=workers) == EXPECTED
    assert map_chunks(math.factorial, [], workers=workers) == []


def test_errors_in_workers_reach_the_caller():
    with pytest.raises(ValueError):
        map_chunks(math.sqrt, [4.0, -1.0, 9.0], workers=2)
    # handcap's own errors keep their type and line
    with pytest.raises(HandcapError, match="must be a positive finite number"):
        map_chunks(check_rate, [100.0, -5.0], workers=2)


def test_dask_client_gives_the_same_results():
    distributed = pytest.importorskip("distributed")
    with (distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                   dashboard_address=None) as cluster,
          distributed.Client(cluster, set_as_default=False) as client):
        assert map_chunks(math.factorial, NUMBERS, scheduler=client) == EXPECTED
        with pytest.raises(HandcapError, match="must be a positive finite number"):
            map_chunks(check_rate, [100.0, 0.0], scheduler=client)


def test_bad_settings(monkeypatch):
    import handcap.parallel as parallel
    monkeypatch.setattr(parallel, "_CONNECT_TIMEOUT", "1s")  # refused at once; Dask tries again until then
    with pytest.raises(HandcapError, match="workers must be"):
        map_chunks(math.factorial, NUMBERS, workers=0)
    with pytest.raises(HandcapError, match="scheduler must be an address"):
        map_chunks(math.factorial, NUMBERS, scheduler=5)
    with pytest.raises(HandcapError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:9"):
        map_chunks(math.factorial, NUMBERS, scheduler="tcp://127.0.0.1:9")


@pytest.mark.parametrize("cpus, load, cores, expected", [
    (2, 0.3, 2, 2),     # idle machine: every core
    (2, 7.8, 2, 1),     # busy machine: stay in this process
    (64, 30.0, 2, 2),   # a container's 2 cores on a half-busy host
    (16, 9.0, 16, 8),
])
def test_idle_workers_from_the_load_average(monkeypatch, cpus, load, cores, expected):
    import os

    import handcap.parallel as parallel
    monkeypatch.setattr(os, "getloadavg", lambda: (load, load, load))
    monkeypatch.setattr(os, "cpu_count", lambda: cpus)
    monkeypatch.setattr(parallel, "default_workers", lambda: cores)
    assert parallel.idle_workers() == expected
