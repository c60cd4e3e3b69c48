"""Where a batch's jobs run: worker processes on this machine, or a Dask cluster.

:func:`trackcli.run.batch.run_batch` runs jobs one after another in its own process, or hands
them to :func:`run_processes` (a pool of local processes,
:class:`concurrent.futures.ProcessPoolExecutor`, started by a fork server) or :func:`run_dask`
(a Dask scheduler's workers, which must see the same file paths; ``pip install 'trackcli[dask]'``).
Both yield each job's :class:`~trackcli.run.jobs.JobResult` as it completes, cap every
worker's OpenCV, OpenMP and BLAS threads to its share of the cores, and on Ctrl-C cancel the
jobs not started, let the running ones stop at their next frame and remove their files.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import uuid
from pathlib import Path
from typing import Any, Iterable, Iterator

from trackcli.errors import ConfigError, InputError
from trackcli.run.jobs import RESULT_FILE, _clear_outputs, _failed, _one_line, job_folder, run_job
from trackcli.run.manifest import Job

log = logging.getLogger(__name__)


# -- local processes ---------------------------------------------------------------------------

_interrupted = False
_stop_event: Any = None


#: environment variables that cap the threads of numpy's BLAS and OpenMP in a worker
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def threads_per_worker(workers: int) -> int:
    """The cores of this machine shared out among ``workers`` (at least one each).

    Without a cap every worker's OpenCV and BLAS start as many threads as there are cores,
    and the workers oversubscribe the machine.
    """
    return max(1, (os.cpu_count() or 1) // max(1, workers))


@contextlib.contextmanager
def _thread_env(threads: int) -> Iterator[None]:
    """Workers started inside this block inherit :data:`THREAD_ENV` set to ``threads``."""
    old = {k: os.environ.get(k) for k in THREAD_ENV}
    os.environ.update({k: str(threads) for k in THREAD_ENV})
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _cap_threads(threads: int) -> None:
    import cv2

    cv2.setNumThreads(int(threads))


def _worker_init(level: int, stop: Any, threads: int = 0) -> None:
    """Start of a worker process: logging like the parent's; Ctrl-C handling; ``threads``
    (if > 0) caps OpenCV's threads.

    Ctrl-C (to the worker, or ``stop`` set by the parent) makes the running job stop at its
    next frame, remove its files and raise KeyboardInterrupt, and the worker refuse jobs
    queued after it.  The signal handler only sets a flag: the job is never interrupted at
    an arbitrary point (say, between creating a temporary file and the code that removes
    it).  Until this runs, a worker ignores Ctrl-C (see :func:`_start_fork_server`); the
    parent's ``stop`` covers that moment.
    """
    global _stop_event
    if threads > 0:
        _cap_threads(threads)
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr)
    logging.getLogger("trackcli").setLevel(level)
    _stop_event = stop

    def on_sigint(signum: int, frame: Any) -> None:
        global _interrupted
        _interrupted = True

    signal.signal(signal.SIGINT, on_sigint)


def _worker_interrupted() -> bool:
    return _interrupted or (_stop_event is not None and _stop_event.is_set())


def _worker_job(job: Job, outdir: str) -> Any:
    if _worker_interrupted():
        raise KeyboardInterrupt
    return run_job(job, outdir, interrupted=_worker_interrupted)


def _start_fork_server(context: Any) -> None:
    """Start the fork server (if that is how workers start) ignoring Ctrl-C.

    A worker forked by the server gets the server's original SIGINT disposition until
    :func:`_worker_init` installs the real handler.  Started with SIGINT ignored (which
    survives ``exec``), the server hands "ignore" on, so a Ctrl-C that arrives while a worker
    is still starting cannot kill it with a traceback (which would break the pool and make
    it terminate the other workers in the middle of their clean-up).  The parent ignores
    Ctrl-C only for the few milliseconds of the server's fork and exec.
    """
    import threading

    if context.get_start_method() != "forkserver":
        return
    from multiprocessing import forkserver

    if threading.current_thread() is not threading.main_thread():
        forkserver.ensure_running()
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, old)


def _sweep_unfinished(jobs: Iterable[Job], outdir: Path) -> None:
    """Remove what unfinished jobs left (temporaries, outputs without a result.json).

    Called by the parent after every worker has exited, so nothing is being written any
    more: whatever moment a worker was interrupted or killed at, no ``.part`` file stays.
    """
    for job in jobs:
        folder = job_folder(outdir, job)
        if folder.is_dir() and not (folder / RESULT_FILE).is_file():
            with contextlib.suppress(OSError):
                _clear_outputs(folder, job)


def run_processes(jobs: list[Job], outdir: Path, workers: int) -> Iterator[Any]:
    """Run ``jobs`` in ``workers`` local processes; yield each :class:`~trackcli.run.jobs.JobResult`."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    methods = multiprocessing.get_all_start_methods()
    # forkserver: workers start from a clean process, not a copy of this (possibly threaded) one
    context = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    level = logging.getLogger("trackcli").getEffectiveLevel()
    pool = None
    finished: set[str] = set()
    threads = threads_per_worker(workers)
    try:
        with _thread_env(threads):
            _start_fork_server(context)
            stop = context.Event()
            pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_init,
                                       initargs=(level, stop, threads))
            futures = {pool.submit(_worker_job, job, str(outdir)): job for job in jobs}
        for fut in as_completed(futures):
            job = futures[fut]
            try:
                result = fut.result()
            except BrokenProcessPool as exc:
                result = _failed(job, job_folder(outdir, job), f"worker process died ({_one_line(exc)})")
            except Exception as exc:
                result = _failed(job, job_folder(outdir, job), _one_line(exc))
            if result.status == "ok":
                finished.add(job.name)
            yield result
    except BaseException:
        if pool is not None:
            stop.set()  # also reaches workers that were starting when Ctrl-C came
            pool.shutdown(wait=True, cancel_futures=True)
        _sweep_unfinished([j for j in jobs if j.name not in finished], outdir)
        raise
    pool.shutdown(wait=True)
    _sweep_unfinished([j for j in jobs if j.name not in finished], outdir)  # e.g. a worker that died


# -- Dask --------------------------------------------------------------------------------------


def require_dask() -> None:
    """Raise ConfigError (with the install command) unless dask.distributed can be imported."""
    import importlib.util

    if importlib.util.find_spec("distributed") is None:
        raise ConfigError("running on a Dask scheduler needs dask.distributed: pip install 'trackcli[dask]'")


#: glibc ``mallopt`` parameters, and the values :func:`_restore_malloc` sets
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 * 2**20  # glibc's largest dynamic mmap threshold on 64-bit systems
_TRIM_THRESHOLD = 2 * _MMAP_THRESHOLD


def _restore_malloc() -> bool:
    """Undo, in this process, the cost of ``MALLOC_TRIM_THRESHOLD_`` set in the environment.

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536`` so that they hand freed
    memory back to the system.  Setting it switches off glibc's dynamic mmap threshold: then
    every array over 128 KiB is mapped and unmapped afresh, and each CONDENSATION step, whose
    temporaries are megabytes, page-faults through them (a track runs at half speed: 70 instead
    of 153 frames/s on the sample ``train`` clip).  Here the mmap threshold is set to glibc's
    own dynamic maximum and the trim threshold to twice that, as glibc's dynamic rule would;
    memory beyond that is still returned.  Returns whether anything was changed (only with
    glibc, and only when the variable is set).
    """
    if "MALLOC_TRIM_THRESHOLD_" not in os.environ or not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
                    and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
    except (OSError, AttributeError):  # not glibc
        return False


def _dask_job(job: Job, outdir: str, threads: int) -> Any:
    """One job on a Dask worker, OpenCV capped to the worker's share of the cores, and the
    worker's allocator left fast (:func:`_restore_malloc`)."""
    _cap_threads(threads)
    _restore_malloc()
    return run_job(job, outdir)


def run_dask(jobs: list[Job], outdir: Path, scheduler: Any) -> Iterator[Any]:
    """Run ``jobs`` on a Dask scheduler (an address or a client); yield each result as it completes."""
    require_dask()
    from distributed import Client, as_completed

    own = isinstance(scheduler, str)
    if own:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
    else:
        client = scheduler
    futures = []
    try:
        tag = uuid.uuid4().hex[:8]
        try:
            n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        except Exception:
            n_workers = 1
        threads = threads_per_worker(n_workers)
        for job in jobs:
            futures.append(client.submit(_dask_job, job, str(outdir), threads, key=f"trackcli-{job.name}-{tag}",
                                         pure=False))
        by_key = {f.key: j for f, j in zip(futures, jobs)}
        for fut in as_completed(futures):
            job = by_key[fut.key]
            try:
                yield fut.result()
            except Exception as exc:  # the worker died, or the task could not run
                yield _failed(job, job_folder(outdir, job), _one_line(exc))
    except BaseException:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        raise
    finally:
        if own:
            with contextlib.suppress(Exception):
                client.close()

__all__ = ["THREAD_ENV", "require_dask", "run_dask", "run_processes", "threads_per_worker"]
