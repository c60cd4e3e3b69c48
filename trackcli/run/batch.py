"""Batch runs: many clips from one manifest, each tracked and scored, on local processes or Dask.

The manifest (its format and checks: :mod:`trackcli.run.manifest`) resolves to
:class:`~trackcli.run.manifest.Job` objects.  One job is one clip.  It runs
:func:`trackcli.run.clips.track_clip` exactly as ``trackcli track`` does, writes masks and VOT
region lines when asked (the sinks of :func:`trackcli.run.export.export_sinks`), scores the track with
:func:`trackcli.run.evaluate.evaluate` when there is a truth, and writes in ``OUTDIR/NAME/``::

    NAME.TRACKER.config.yaml   effective settings
    NAME.TRACKER.csv           per-frame estimates
    NAME.TRACKER.rrd           recording (unless rrd: false)
    masks/                     one mask PNG per frame (with masks: true or palette)
    NAME.TRACKER.vot.txt       VOT region lines (with vot: true)
    score.json                 scores (with a truth)
    result.json                written last: the job is complete

Every file is written to a temporary name and renamed when complete, so a job that is
interrupted or killed leaves no ``result.json`` and no half-written file.  A job starts by
removing the outputs of earlier runs in its folder.  A later batch skips a job whose
``result.json`` is present, reports success, and records the same *fingerprint* (a hash of
the resolved job: clip, tracker, settings, and the contents of the model, template and truth
files), unless ``force`` is given; a changed manifest or input therefore runs again.

A job that fails (unreadable video, template that does not fit, ...) is recorded with its
error message and does not stop the others; so is a job whose clip entry names a file that
does not exist (:attr:`~trackcli.run.manifest.Job.missing`), which is not started at all.
A run whose CONDENSATION sample set collapsed carries a warning
(:func:`trackcli.run.checks.sample_collapse`).  ``OUTDIR/summary.json`` lists every job's
result after the batch.

Executors (:mod:`trackcli.run.executors`): in-process one after another (``workers=1``), a
pool of ``workers`` local processes, or a Dask cluster (``scheduler``).
"""


from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable

from trackcli.errors import ConfigError, InputError
from trackcli.io.outputs import ensure_dir
from trackcli.run.executors import (THREAD_ENV, _restore_malloc, _sweep_unfinished, _worker_init,  # noqa: F401
                                    _worker_job, require_dask, run_dask, run_processes, threads_per_worker)
from trackcli.run.jobs import (MASKS_FOLDER, RESULT_FILE, SCORE_FILE, STATUSES, VOT_SUFFIX, JobResult,  # noqa: F401
                               _clear_outputs, _failed, _finite, _write_json, completed_result, job_fingerprint,
                               job_folder, run_job)
from trackcli.run.manifest import CLIP_KEYS, DEFAULT_KEYS, FORMAT, Job, Manifest, load_manifest  # noqa: F401

#: Batch summary in the output folder.
SUMMARY_FILE = "summary.json"


@dataclass(frozen=True)
class BatchResult:
    """The results of all jobs, in manifest order, and the batch's wall time."""

    results: tuple[JobResult, ...]
    seconds: float
    outdir: str
    executor: str

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)

    @property
    def succeeded(self) -> bool:
        return all(r.succeeded for r in self.results)

    def summary(self) -> dict[str, Any]:
        """Counts, mean scores over the scored clips, wall time."""
        def mean(key: str) -> float | None:
            vals = [getattr(r, key) for r in self.results if r.succeeded and _finite(getattr(r, key)) is not None]
            return _finite(sum(vals) / len(vals)) if vals else None

        return {
            "clips": len(self.results), "ok": self.count("ok"), "skipped": self.count("skipped"),
            "failed": self.count("failed"), "missing": sum(r.missing for r in self.results),
            "precision_mean": mean("precision"),
            "success_auc_mean": mean("success_auc"), "centre_error_mean": mean("centre_error_mean"),
            "seconds": round(self.seconds, 3), "executor": self.executor, "outdir": self.outdir,
        }



# ---------------------------------------------------------------------------------------------
# The batch


def check_runnable(manifest: Manifest) -> None:
    """Raise InputError (naming the first missing file) when no job of ``manifest`` can run:
    every clip misses an input, so there is nothing to run and nothing is written."""
    if manifest.jobs and all(j.missing for j in manifest.jobs):
        more = f" (and {len(manifest.jobs) - 1} more clips miss an input)" if len(manifest.jobs) > 1 else ""
        raise InputError(f"{manifest.path}: {manifest.jobs[0].missing}{more}")


def with_exports(manifest: Manifest, *, masks: str | None = None, vot: bool = False) -> Manifest:
    """``manifest`` with masks (``"grey"`` or ``"palette"``) and VOT region lines asked of every
    job that does not ask for them itself (``batch --masks``, ``--vot``)."""
    if not masks and not vot:
        return manifest
    jobs = tuple(dataclasses.replace(j, masks=j.masks or masks, vot=j.vot or vot) for j in manifest.jobs)
    return dataclasses.replace(manifest, jobs=jobs)


def run_batch(
    jobs: Manifest | Iterable[Job],
    outdir: str | os.PathLike[str],
    *,
    workers: int = 1,
    scheduler: Any = None,
    force: bool = False,
    on_result: Callable[[JobResult], None] | None = None,
) -> BatchResult:
    """Run jobs: skip the complete ones, run the rest, write ``OUTDIR/summary.json``.

    Parameters
    ----------
    jobs : Manifest or iterable of Job
    outdir : path
        Output folder; job ``NAME`` writes in ``outdir/NAME/``.
    workers : int
        Local worker processes; 1 runs the jobs one after another in this process.
    scheduler : str or distributed.Client, optional
        Run on Dask instead: a scheduler address (``tcp://host:8786``) or a connected client.
    force : bool
        Run complete jobs again.
    on_result : callable, optional
        Called with each :class:`JobResult` as it arrives (jobs missing an input and skipped
        ones first, then in order of completion).

    Returns
    -------
    BatchResult
        Results in job order.

    Raises
    ------
    ConfigError
        ``workers`` < 1, or a scheduler is asked for without dask.distributed installed.
    InputError
        The output folder cannot be made, or the scheduler cannot be reached.
    KeyboardInterrupt
        After cancelling the jobs not yet started.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers: expected an integer >= 1, got {workers!r}")
    job_list = list(jobs.jobs if isinstance(jobs, Manifest) else jobs)
    names = [j.name for j in job_list]
    if len(set(names)) != len(names):
        raise ConfigError("jobs: names must be distinct (they name the output folders)")
    t0 = time.perf_counter()
    out = ensure_dir(outdir).resolve()
    results: dict[str, JobResult] = {}

    def take(r: JobResult) -> None:
        results[r.name] = r
        if on_result is not None:
            on_result(r)

    pending = []
    for job in job_list:
        if job.missing:
            take(_failed(job, job_folder(out, job), f"{job.entry}: {job.missing}", missing=True))
            continue
        done = None if force else completed_result(job, out)
        if done is not None:
            take(done)
        else:
            pending.append(job)
    if scheduler is not None:
        executor = "dask"
        stream = run_dask(pending, out, scheduler) if pending else iter(())
    elif workers > 1 and len(pending) > 1:
        executor = f"processes:{min(workers, len(pending))}"
        stream = run_processes(pending, out, min(workers, len(pending)))
    else:
        executor = "in-process"
        stream = (run_job(j, out) for j in pending)
    for r in stream:
        take(r)
    batch = BatchResult(tuple(results[n] for n in names), time.perf_counter() - t0, str(out), executor)
    _write_json(out / SUMMARY_FILE, {"summary": batch.summary(), "clips": [r.to_dict() for r in batch.results]})
    return batch



__all__ = [
    "CLIP_KEYS", "DEFAULT_KEYS", "FORMAT", "MASKS_FOLDER", "RESULT_FILE", "SCORE_FILE", "STATUSES", "SUMMARY_FILE",
    "THREAD_ENV", "VOT_SUFFIX", "BatchResult", "Job", "JobResult", "Manifest", "check_runnable", "completed_result",
    "job_fingerprint", "job_folder", "load_manifest", "require_dask", "run_batch", "run_job", "threads_per_worker", "with_exports",
]
