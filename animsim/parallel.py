"""Where independent cases run: in this process, in local processes, or on Dask.

One function, :func:`map_cases`, used by ``animsim sweep`` (and meant for
``compare``): it applies ``fn`` to every case and returns the results **in
case order**, whatever finished first, so a table built from them does not
depend on where it ran.

* ``jobs=1`` and no scheduler: a plain loop in this process (the default; the
  quietest for timings).
* ``jobs=N``: a :class:`concurrent.futures.ProcessPoolExecutor` with the
  ``spawn`` start method, each worker given its share of the cores for numba's
  threads (unless ``NUMBA_NUM_THREADS`` is set). Spawn (not fork) because forking a process that
  holds threads (BLAS pools, rich, a Dask client) can deadlock, and it behaves
  the same on Linux, macOS and Windows. ``fn`` and the cases must therefore be
  picklable: a module-level function and plain data.
* ``scheduler="local"``: a throwaway ``distributed.LocalCluster`` (``jobs``
  worker processes, one thread each; or the Dask default when ``jobs`` is 1).
* ``scheduler="tcp://host:8786"`` (any address ``distributed.Client`` takes):
  an existing cluster, whose workers must be able to import animsim.
* ``scheduler=<distributed.Client>``: a client the caller already holds (tests
  use an in-process ``LocalCluster(processes=False)``, which starts fastest).

``distributed`` is optional (the ``dask`` extra) and imported only when a
scheduler is asked for.

A case whose call raises does not lose the others: with ``on_error`` the
exception becomes that case's result (``on_error(case, exc)``); without it,
the first failure is raised after every case has finished or failed.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, TypeVar

from animsim.errors import UsageError

C = TypeVar("C")
R = TypeVar("R")
Progress = Callable[[int, int], None]  # (cases done, total)

LOCAL_SCHEDULER = "local"
DASK_INSTALL_HINT = 'pip install "animsim[dask]"  (or: pip install "distributed>=2024.1")'
# How long to wait for a remote scheduler before telling the user (s).
CONNECT_TIMEOUT = 10.0
# One thread per Dask worker: the cases are NumPy-bound and hold the GIL.
THREADS_PER_WORKER = 1


def map_cases(
    fn: Callable[[C], R],
    cases: Sequence[C],
    *,
    jobs: int = 1,
    scheduler: Any = None,
    on_error: Callable[[C, BaseException], R] | None = None,
    progress: Progress | None = None,
) -> list[R]:
    """``[fn(case) for case in cases]``, run serially, on local processes or on Dask.

    See the module docstring for ``jobs`` and ``scheduler``. Results come back
    in the order of ``cases``; ``progress(done, total)`` is called as each
    case finishes, in the order they finish.
    """
    tick = _ticker(progress, len(cases))
    if jobs < 1:
        raise UsageError(f"--jobs: must be at least 1, not {jobs}")
    cases = list(cases)
    if scheduler is not None:
        return _map_dask(fn, cases, scheduler, jobs, on_error, tick)
    if jobs == 1 or len(cases) <= 1:
        results = []
        for c in cases:
            results.append(_call(fn, c, on_error))
            tick()
        return results
    return _map_processes(fn, cases, jobs, on_error, tick)


def _ticker(progress: Progress | None, total: int) -> Callable[[], None]:
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    return tick


def _call(fn: Callable[[C], R], case: C, on_error: Callable[[C, BaseException], R] | None) -> R:
    if on_error is None:
        return fn(case)
    try:
        return fn(case)
    except Exception as exc:
        return on_error(case, exc)


def _collect(
    cases: list[C],
    outcomes: list[tuple[bool, Any]],
    on_error: Callable[[C, BaseException], R] | None,
) -> list[R]:
    """Results in case order; failures through ``on_error``, else the first one raised."""
    results: list[R] = []
    for case, (ok, value) in zip(cases, outcomes, strict=True):
        if ok:
            results.append(value)
        elif on_error is not None:
            results.append(on_error(case, value))
        else:
            raise value
    return results


def _map_processes(
    fn: Callable[[C], R],
    cases: list[C],
    jobs: int,
    on_error: Callable[[C, BaseException], R] | None,
    tick: Callable[[], None],
) -> list[R]:
    context = multiprocessing.get_context("spawn")
    workers = min(jobs, len(cases))
    # numba steps large particle systems on every core it may use; several workers each
    # using every core would wait on each other's threads, so each gets its share
    share = str(max(1, (os.cpu_count() or 1) // workers))
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_init_worker, initargs=(share,)
    )
    try:
        futures = [pool.submit(fn, c) for c in cases]
        for _ in as_completed(futures):
            tick()
        outcomes: list[tuple[bool, Any]] = []
        for f in futures:
            try:
                outcomes.append((True, f.result()))
            except Exception as exc:  # the case raised, or its worker died
                outcomes.append((False, exc))
    except BaseException:
        # Ctrl-C (or SIGTERM, raised as KeyboardInterrupt by the CLI): the executor's own exit
        # would wait for every running case to finish. Stop the workers instead.
        _stop_workers(pool)
        raise
    pool.shutdown(wait=True)
    return _collect(cases, outcomes, on_error)


#: how long stopped workers get to remove their temporary files before they are killed (s)
WORKER_STOP_SECONDS = 0.5


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel the cases not started and end the running ones within a second.

    Each worker turns SIGTERM into KeyboardInterrupt (:func:`_init_worker`), so
    a case that is writing removes its temporary file as on Ctrl-C; a worker
    still alive after WORKER_STOP_SECONDS is killed.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    _stop_processes([p.pid for p in processes if p.is_alive() and p.pid is not None])
    for p in processes:
        p.join(1.0)  # reaped: each has ended or been killed


def _dask_worker_pids(cluster: Any) -> list[int]:
    """The process ids of a LocalCluster's worker processes (each nanny's child), each
    nanny told first not to start its worker again once it is gone (Dask's own
    shutdown does the same): otherwise closing the cluster waits for new workers."""
    pids = []
    for nanny in getattr(cluster, "workers", {}).values():
        pid = getattr(nanny, "pid", None)
        if isinstance(pid, int):
            nanny.close_gracefully(reason="animsim-interrupted")
            pids.append(pid)
    return pids


def _stop_processes(pids: list[int]) -> None:
    """SIGTERM to each process, then SIGKILL to any still alive after WORKER_STOP_SECONDS.

    Worker processes (the pool's, which take SIGTERM as an interrupt, and Dask's) end on
    SIGTERM, their case's temporary files removed as the interpreter unwinds; one busy in
    compiled code past the deadline is killed.
    """
    import signal
    import time

    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + WORKER_STOP_SECONDS
    alive = list(pids)
    while alive and time.monotonic() < deadline:
        time.sleep(0.02)
        alive = [pid for pid in alive if _alive(pid)]
    for pid in alive:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a child that has exited but is not yet reaped still answers: ask its state
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(") ", 1)[1][:1] != "Z"
    except (OSError, IndexError):
        return True


def _init_worker(share: str) -> None:
    """In a worker, before numba loads: its thread count, unless NUMBA_NUM_THREADS says one.

    Ctrl-C at a terminal reaches every process of the group; the main process
    decides (it stops the workers), so a worker ignores SIGINT and takes
    SIGTERM as the interrupt that unwinds its case.
    """
    import signal

    os.environ.setdefault("NUMBA_NUM_THREADS", share)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _interrupt)


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _import_distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise UsageError(
            f"--scheduler needs the optional package 'distributed', which is not installed: {DASK_INSTALL_HINT}"
        ) from None
    return distributed


def _map_dask(
    fn: Callable[[C], R],
    cases: list[C],
    scheduler: Any,
    jobs: int,
    on_error: Callable[[C, BaseException], R] | None,
    tick: Callable[[], None],
) -> list[R]:
    distributed = _import_distributed()
    if not isinstance(scheduler, str):  # a Client the caller owns (and closes)
        return _gather(distributed, scheduler, fn, cases, on_error, tick)
    if scheduler == LOCAL_SCHEDULER:
        from dask.system import CPU_COUNT

        # One worker process per core unless --jobs says how many, and each its share of
        # the cores for numba's threads, as the process pool's workers get theirs (a
        # NUMBA_NUM_THREADS the user set reaches the workers as it is).
        workers = jobs if jobs > 1 else max(1, CPU_COUNT // THREADS_PER_WORKER)
        env = (
            {}
            if "NUMBA_NUM_THREADS" in os.environ
            else {"NUMBA_NUM_THREADS": str(max(1, CPU_COUNT // workers))}
        )
        # dashboard_address=None: no web server, no port to collide with. silence_logs:
        # a case's failure reaches the user through its future, so Dask's own log lines
        # (a stopped worker's cancelled tasks, a nanny killing it) are noise here.
        with (
            distributed.LocalCluster(
                n_workers=workers,
                threads_per_worker=THREADS_PER_WORKER,
                dashboard_address=None,
                env=env,
                silence_logs=logging.CRITICAL,
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            try:
                return _gather(distributed, client, fn, cases, on_error, tick)
            except BaseException:
                # Ctrl-C (or SIGTERM): closing the cluster would ask each worker to stop
                # and wait four seconds before its nanny kills it, still running its case
                _stop_processes(_dask_worker_pids(cluster))
                raise
    try:
        client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise UsageError(f"--scheduler {scheduler}: cannot reach the Dask scheduler: {exc}") from None
    with client:
        return _gather(distributed, client, fn, cases, on_error, tick)


def _gather(
    distributed: Any,
    client: Any,
    fn: Callable[[C], R],
    cases: list[C],
    on_error: Callable[[C, BaseException], R] | None,
    tick: Callable[[], None],
) -> list[R]:
    # pure=False: two equal cases are still two runs (their wall times differ).
    futures = client.map(fn, cases, pure=False)
    try:
        for _ in distributed.as_completed(futures):
            tick()
    except BaseException:
        # Ctrl-C: the scheduler drops the cases not started (a remote cluster's workers
        # finish the ones running; a LocalCluster's are stopped by the caller)
        with contextlib.suppress(Exception):
            client.cancel(futures, force=True)
        raise
    outcomes: list[tuple[bool, Any]] = []
    for f in futures:
        try:
            outcomes.append((True, f.result()))
        except Exception as exc:
            outcomes.append((False, exc))
    return _collect(cases, outcomes, on_error)
