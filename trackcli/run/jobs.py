"""One job of a batch: one clip tracked, exported and scored into ``OUTDIR/NAME/``, and its result.

:func:`run_job` runs :func:`trackcli.run.clips.track_clip` exactly as ``trackcli track`` does,
writes masks and VOT region lines when asked (the sinks of
:func:`trackcli.run.export.export_sinks`), scores the track with
:func:`trackcli.run.evaluate.evaluate` when there is a truth, and writes ``result.json`` last;
:func:`completed_result` finds the result of an identical earlier run (same *fingerprint*,
:func:`job_fingerprint`) so that it is skipped.  The layout of a job's folder and the rules
of completion are described in :mod:`trackcli.run.batch`, which runs the jobs of a manifest
(:mod:`trackcli.run.executors`: where they run).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from trackcli import __version__
from trackcli.errors import TrackcliError
from trackcli.io.outputs import ensure_dir, partial_name, write_text
from trackcli.run.clips import output_files, track_clip
from trackcli.run.manifest import Job
from trackcli.settings import to_dict
from trackcli.trackers import TRACKERS

log = logging.getLogger(__name__)

#: File that marks a job complete, and the scores beside it.
RESULT_FILE = "result.json"
SCORE_FILE = "score.json"
#: The folder of a job's masks, and the ending of its VOT region lines (after ``NAME.TRACKER``).
MASKS_FOLDER = "masks"
VOT_SUFFIX = ".vot.txt"

STATUSES = ("ok", "skipped", "failed")


# ---------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class JobResult:
    """What became of one job.

    Attributes
    ----------
    name, clip : str
    status : {"ok", "skipped", "failed"}
        ``skipped``: complete outputs of an identical earlier run were found.
    error : str or None
        The one-line error of a failed job.
    frames, frames_lost : int or None
        Frames tracked, and those the tracker judged lost.
    tracker_fps : float or None
        Frames per second of the tracker alone (no decoding or recording).
    precision, centre_error_mean, success_auc, mean_iou : float or None
        Scores against the truth (None without a truth, or if undefined).
    seconds : float
        Wall time of the job (of the earlier run, for a skipped job).
    folder : str
        The job's output folder.
    outputs : dict of str to str
        Output files by kind (``csv``, ``rrd``, ``config``, ``masks``, ``vot``, ``score``, ``result``).
    missing : bool
        The job did not run: a file its entry names does not exist (``error`` says which).
    warnings : tuple of str
        One-line warnings about the run (a collapsed sample set).
    """

    name: str
    clip: str
    status: str
    error: str | None = None
    tracker: str = "condensation"
    frames: int | None = None
    frames_lost: int | None = None
    tracker_fps: float | None = None
    precision: float | None = None
    centre_error_mean: float | None = None
    success_auc: float | None = None
    mean_iou: float | None = None
    seconds: float = 0.0
    folder: str = ""
    outputs: dict[str, str] = field(default_factory=dict)
    missing: bool = False
    warnings: tuple[str, ...] = ()

    @property
    def succeeded(self) -> bool:
        return self.status in ("ok", "skipped")

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dictionary (non-finite numbers become None)."""
        return {
            # the keys of CLIP_JSON_KEYS first: the same shape as `track --json` gives a clip
            "name": self.name, "clip": self.clip, "tracker": self.tracker, "status": self.status, "error": self.error,
            "frames": self.frames, "frames_lost": self.frames_lost,
            "tracker_fps": _finite(self.tracker_fps, 2),
            "csv": self.outputs.get("csv"), "rrd": self.outputs.get("rrd"),
            "precision": _finite(self.precision),
            "centre_error_mean": _finite(self.centre_error_mean), "success_auc": _finite(self.success_auc),
            "mean_iou": _finite(self.mean_iou), "seconds": round(self.seconds, 3),
            "folder": self.folder, "outputs": dict(self.outputs), "missing": self.missing,
            "warnings": list(self.warnings),
        }



def _finite(v: Any, digits: int | None = None) -> float | None:
    if v is None:
        return None
    v = float(v)
    if not math.isfinite(v):
        return None
    return round(v, digits) if digits is not None else v


# ---------------------------------------------------------------------------------------------
# Completion


def job_fingerprint(job: Job) -> str:
    """Hash of everything a job's outputs depend on (hex, 16 characters).

    Covers the trackcli version, the clip's path (and a file's size and modification time),
    the tracker, the effective settings, the contents of the model, template and truth
    files, the truth object, the precision threshold and whether a recording is written.
    """
    def digest(p: str | None) -> str | None:
        if p is None:
            return None
        h = hashlib.sha256()
        try:
            with open(p, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
        except IsADirectoryError:
            return "folder"
        except OSError:
            return None
        return h.hexdigest()

    clip_stat = None
    with contextlib.suppress(OSError):
        st = os.stat(job.clip)
        if not os.path.isdir(job.clip):
            clip_stat = [st.st_size, st.st_mtime_ns]
    spec = {
        "version": __version__, "clip": job.clip, "clip_stat": clip_stat, "tracker": job.tracker,
        "settings": to_dict(job.settings), "model": digest(job.model), "template": digest(job.template),
        "truth": digest(job.truth), "object": job.object_id, "threshold": job.threshold, "rrd": job.rrd,
    }
    if job.masks or job.vot:  # left out otherwise: results of earlier versions stay current
        spec.update(masks=job.masks, vot=job.vot)
    text = json.dumps(spec, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def job_folder(outdir: str | os.PathLike[str], job: Job) -> Path:
    """``outdir/NAME``."""
    return Path(outdir) / job.name


def _output_files(folder: Path, job: Job, scored: bool) -> dict[str, Path]:
    every = output_files(folder, job.name, job.tracker)
    files = {"csv": every["csv"], "config": every["config"]}
    if job.rrd and job.settings.output.rrd:
        files["rrd"] = every["rrd"]
    if job.masks:
        files["masks"] = folder / MASKS_FOLDER
    if job.vot:
        files["vot"] = Path(f"{every['csv'].with_suffix('')}{VOT_SUFFIX}")
    if scored:
        files["score"] = folder / SCORE_FILE
    files["result"] = folder / RESULT_FILE
    return files


def completed_result(job: Job, outdir: str | os.PathLike[str]) -> JobResult | None:
    """The stored result of ``job`` if its outputs are complete and current, else None.

    Complete and current: ``result.json`` reads, says ``ok``, has this job's fingerprint,
    and every output file it lists exists.  The result comes back with status ``skipped``.
    """
    folder = job_folder(outdir, job)
    try:
        stored = json.loads((folder / RESULT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(stored, dict) or stored.get("status") != "ok" or stored.get("fingerprint") != job_fingerprint(job):
        return None
    files = _output_files(folder, job, scored=job.truth is not None)
    if not all(p.is_dir() if k == "masks" else p.is_file() for k, p in files.items()):
        return None
    keys = ("frames", "frames_lost", "tracker_fps", "precision", "centre_error_mean", "success_auc", "mean_iou",
            "seconds")
    values = {k: stored.get(k) for k in keys}
    values["seconds"] = float(values["seconds"] or 0.0)
    return JobResult(name=job.name, clip=job.clip, status="skipped", tracker=job.tracker, folder=str(folder),
                     outputs={k: str(p) for k, p in files.items()},
                     warnings=tuple(str(w) for w in stored.get("warnings") or ()), **values)


def _clear_outputs(folder: Path, job: Job) -> None:
    """Remove what earlier runs of this job left: result first, then outputs and temporaries."""
    import shutil

    from trackcli.run.export import MASK_FOLDER_MARK

    names = [RESULT_FILE, SCORE_FILE]
    for tracker in TRACKERS:
        names += [p.name for p in output_files(folder, job.name, tracker).values()]
        names.append(f"{job.name}.{tracker}{VOT_SUFFIX}")
    for n in names:
        for p in (folder / n, partial_name(folder / n)):
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    masks = folder / MASKS_FOLDER
    for p in (masks, partial_name(masks)):
        if (p / MASK_FOLDER_MARK).is_file():  # only a folder of masks trackcli wrote
            shutil.rmtree(p, ignore_errors=True)


def _write_json(path: Path, obj: Any) -> Path:
    return write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


# ---------------------------------------------------------------------------------------------
# Running one job


class _StopCheck:
    """A progress sink that raises KeyboardInterrupt at the next frame once ``interrupted()``."""

    def __init__(self, interrupted: Callable[[], bool]):
        self._interrupted = interrupted

    def __enter__(self) -> "_StopCheck":
        return self

    def __exit__(self, *exc: Any) -> None:
        pass

    def update(self, n: int) -> None:
        if self._interrupted():
            raise KeyboardInterrupt


def run_job(job: Job, outdir: str | os.PathLike[str], *,
            interrupted: Callable[[], bool] | None = None) -> JobResult:
    """Track and score one job, writing its outputs in ``outdir/NAME/``.

    Never raises for a failing clip: a :class:`~trackcli.errors.TrackcliError` or any other
    exception becomes a ``failed`` result carrying the error message.  ``KeyboardInterrupt``
    propagates after the job's files are removed (those being written and those already
    complete: an interrupted job leaves nothing).  ``interrupted()``, if given, is asked
    after every frame and before the results are written; when it says yes, the job stops
    as if Ctrl-C had been pressed at that point.

    Returns
    -------
    JobResult
    """
    t0 = time.perf_counter()
    folder = job_folder(outdir, job)
    try:
        fingerprint = job_fingerprint(job)
        ensure_dir(folder)
        _clear_outputs(folder, job)
        check = (lambda label, n: _StopCheck(interrupted)) if interrupted is not None else None
        files = _output_files(folder, job, scored=job.truth is not None)
        sinks = None
        if job.masks or job.vot:
            from trackcli.run.export import export_sinks

            sinks = export_sinks(files.get("masks"), files.get("vot"), palette=job.masks == "palette")
        summary = track_clip(job.clip, settings=job.settings, outdir=folder, model=job.model,
                             template=job.template, tracker=job.tracker, name=job.name, rrd=job.rrd,
                             progress=check, sinks=sinks)
        from trackcli.run.checks import track_warnings

        warnings = track_warnings(summary.csv, job.settings.condensation.particles, name=job.name)
        for w in warnings:
            log.warning("%s", w)
        score = None
        if job.truth is not None:
            from trackcli.run.evaluate import evaluate, load_truth

            try:
                score = evaluate(summary.csv, load_truth(job.truth, object_id=job.object_id),
                                 threshold=job.threshold)
            except TrackcliError as exc:
                raise type(exc)(f"scoring against {job.truth}: {exc}") from None
            _write_json(folder / SCORE_FILE, {"truth": job.truth, "object": job.object_id, "csv": summary.csv,
                                              **score.to_dict()})
        if interrupted is not None and interrupted():
            raise KeyboardInterrupt
        result = JobResult(
            name=job.name, clip=job.clip, status="ok", tracker=job.tracker, frames=summary.frames,
            frames_lost=summary.frames_lost,
            tracker_fps=summary.tracker_fps,
            precision=score.precision if score else None,
            centre_error_mean=score.centre_error_mean if score else None,
            success_auc=score.success_auc if score else None,
            mean_iou=score.mean_iou if score else None,
            seconds=time.perf_counter() - t0, folder=str(folder), outputs={k: str(p) for k, p in files.items()},
            warnings=tuple(warnings),
        )
        record = {**result.to_dict(), "fingerprint": fingerprint, "worker": _worker_id(), "tracker": job.tracker,
                  "model": job.model, "template": job.template, "truth": job.truth, "object": job.object_id,
                  "run": _clean(summary.to_dict()), "score": score.to_dict() if score else None}
        _write_json(folder / RESULT_FILE, record)
        return result
    except TrackcliError as exc:
        return _failed(job, folder, str(exc), t0)
    except KeyboardInterrupt:
        with contextlib.suppress(OSError):  # also outputs renamed into place before result.json
            _clear_outputs(folder, job)
        raise
    except Exception as exc:  # a bug, or a library error trackcli does not translate
        log.debug("job %s failed", job.name, exc_info=True)
        return _failed(job, folder, _one_line(exc), t0)


def _one_line(exc: BaseException) -> str:
    """``Type: first line of the message`` of an unexpected exception."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def _worker_id() -> dict[str, Any]:
    import socket

    return {"host": socket.gethostname(), "pid": os.getpid()}


def _failed(job: Job, folder: Path, message: str, t0: float | None = None, *, missing: bool = False) -> JobResult:
    seconds = time.perf_counter() - t0 if t0 is not None else 0.0
    with contextlib.suppress(OSError):  # a job that wrote nothing leaves no folder
        folder.rmdir()
    return JobResult(name=job.name, clip=job.clip, status="failed", error=message, tracker=job.tracker,
                     seconds=seconds, folder=str(folder), missing=missing)



__all__ = ["MASKS_FOLDER", "RESULT_FILE", "SCORE_FILE", "STATUSES", "VOT_SUFFIX", "JobResult", "completed_result",
           "job_fingerprint", "job_folder", "run_job"]
