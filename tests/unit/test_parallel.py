"""animsim.parallel.map_cases: same results in case order, wherever it runs.

The functions mapped are from the standard library so that spawned workers
can unpickle them without importing this test module.
"""

from __future__ import annotations

import math
import os
import sys

import pytest

from animsim.errors import UsageError
from animsim.parallel import map_cases

CASES = [5, 1, 7, 3, 0, 6]  # unsorted, so order is checked, not assumed
EXPECTED = [math.factorial(c) for c in CASES]


def failed(case: float, exc: BaseException) -> str:
    return f"failed {case}: {type(exc).__name__}"


def test_serial() -> None:
    assert map_cases(math.factorial, CASES) == EXPECTED


def test_processes_keep_case_order() -> None:
    assert map_cases(math.factorial, CASES, jobs=2) == EXPECTED


def test_process_workers_share_the_cores_among_numba_threads(monkeypatch) -> None:
    """Each of N workers may start cores // N numba threads, unless the user set a count."""
    import os

    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    share = str(max(1, (os.cpu_count() or 1) // 2))
    assert map_cases(os.getenv, ["NUMBA_NUM_THREADS"] * 2, jobs=2) == [share, share]
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    assert map_cases(os.getenv, ["NUMBA_NUM_THREADS"] * 2, jobs=2) == ["1", "1"]


def test_local_dask_workers_share_the_cores_among_numba_threads(monkeypatch) -> None:
    """The local Dask cluster's worker processes get their share of the cores as well."""
    pytest.importorskip("distributed")
    from dask.system import CPU_COUNT

    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    share = str(max(1, CPU_COUNT // 2))
    assert map_cases(os.getenv, ["NUMBA_NUM_THREADS"] * 2, jobs=2, scheduler="local") == [share, share]
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    assert map_cases(os.getenv, ["NUMBA_NUM_THREADS"] * 2, jobs=2, scheduler="local") == ["1", "1"]


def test_a_failing_case_is_a_result_not_a_lost_map() -> None:
    cases = [4.0, -1.0, 9.0]  # sqrt(-1) raises ValueError
    want = [2.0, "failed -1.0: ValueError", 3.0]
    assert map_cases(math.sqrt, cases, on_error=failed) == want
    assert map_cases(math.sqrt, cases, jobs=2, on_error=failed) == want
    with pytest.raises(ValueError):
        map_cases(math.sqrt, cases, jobs=2)


@pytest.mark.parametrize("jobs", [1, 2])
def test_progress_counts_every_finished_case(jobs: int) -> None:
    calls: list[tuple[int, int]] = []
    map_cases(math.factorial, CASES, jobs=jobs, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(k, len(CASES)) for k in range(1, len(CASES) + 1)]


def test_jobs_must_be_positive() -> None:
    with pytest.raises(UsageError):
        map_cases(math.factorial, CASES, jobs=0)


@pytest.fixture(scope="module")
def dask_client():
    """A 2-worker in-process cluster (processes=False: starts in well under a second)."""
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield client


def test_dask_keeps_case_order(dask_client) -> None:
    calls: list[tuple[int, int]] = []
    got = map_cases(math.factorial, CASES, scheduler=dask_client, progress=lambda d, t: calls.append((d, t)))
    assert got == EXPECTED
    assert calls == [(k, len(CASES)) for k in range(1, len(CASES) + 1)]
    cases = [4.0, -1.0, 9.0]
    assert map_cases(math.sqrt, cases, scheduler=dask_client, on_error=failed) == [
        2.0,
        "failed -1.0: ValueError",
        3.0,
    ]


def test_missing_distributed_is_a_usage_error_with_the_pip_command(monkeypatch) -> None:
    # A None entry in sys.modules makes `import distributed` raise ImportError.
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(UsageError, match=r"pip install .*distributed"):
        map_cases(math.factorial, CASES, scheduler="local")


def test_unreachable_scheduler_is_a_usage_error() -> None:
    pytest.importorskip("distributed")
    import animsim.parallel as parallel

    old = parallel.CONNECT_TIMEOUT
    parallel.CONNECT_TIMEOUT = 1.0
    try:
        with pytest.raises(UsageError, match="cannot reach"):
            map_cases(math.factorial, CASES, scheduler="tcp://127.0.0.1:9")
    finally:
        parallel.CONNECT_TIMEOUT = old
