"""Batch runs: many clips from one manifest, each tracked and scored, on local processes or Dask.

A *manifest* is a YAML file listing clips and how to track them::

    format: 1
    defaults:                      # apply to every clip unless the clip says otherwise
      tracker: condensation
      model: models/head-model.yaml
      config: configs/default.yaml
      settings: {condensation: {particles: 300}, video.end: 100}
      seed: 0
    clips:
      - clip: footage/test.mp4
        template: models/head-test.yaml
        truth: footage/test.truth.csv   # optional: the run is scored against it
        name: test                      # optional; default the clip's stem (a folder's name)
      - clip: footage/crossing          # an image folder
        fps: 25
        template: models/crossing.yaml
      - footage/other.mp4               # a bare path: the defaults say everything else

Every relative path is relative to the manifest's folder.  Keys of a clip entry:

=============  ==============================================================================
``clip``       video file or image folder (required; not in ``defaults``)
``name``       output folder name (default: the clip's stem; not in ``defaults``)
``truth``      ground truth as ``trackcli eval`` reads it: truth CSV, box file or folder
``object``     object id in a truth CSV with several objects (default 0)
``threshold``  centre-error threshold of precision, px (default 20)
``model``      model learned by ``trackcli learn``
``template``   template drawn on this clip (at least one of ``model`` and ``template``)
``tracker``    ``condensation`` (default) or ``kalman``
``config``     configuration file (YAML)
``settings``   overrides of the configuration: nested mappings or dotted keys
``seed``       shortcut for ``settings: {seed: ...}``
``fps``        shortcut for ``settings: {video.fps: ...}``, for image folders
``rrd``        ``false`` to write no recording (default ``true``)
=============  ==============================================================================

A clip's ``config`` replaces the default one; ``settings`` are applied in the order config
file, ``defaults.settings``, ``defaults`` shortcuts, the clip's ``settings``, the clip's
shortcuts.  :func:`load_manifest` checks everything it can before any clip runs (files
exist, settings are valid, names are distinct) and raises one-line errors naming the entry
and key, e.g. ``batch.yaml: clips[2].template: no such file: /data/head.yaml``.

One job is one clip.  It runs :func:`trackcli.run.clips.track_clip` exactly as ``trackcli track``
does, scores the track with :func:`trackcli.run.evaluate.evaluate` when there is a truth, and
writes in ``OUTDIR/NAME/``::

    NAME.TRACKER.config.yaml   effective settings
    NAME.TRACKER.csv           per-frame estimates
    NAME.TRACKER.rrd           recording (unless rrd: false)
    score.json                 scores (with a truth)
    result.json                written last: the job is complete

Every file is written to a temporary name and renamed when complete, so a job that is
interrupted or killed leaves no ``result.json`` and no half-written file.  A job starts by
removing the outputs of earlier runs in its folder.  A later batch skips a job whose
``result.json`` is present, reports success, and records the same *fingerprint* (a hash of
the resolved job: clip, tracker, settings, and the contents of the model, template and truth
files), unless ``force`` is given; a changed manifest or input therefore runs again.

A job that fails (unreadable video, template that does not fit, ...) is recorded with its
error message and does not stop the others.  ``OUTDIR/summary.json`` lists every job's
result after the batch.

Executors: in-process one after another (``workers=1``), a pool of ``workers`` local
processes (:class:`concurrent.futures.ProcessPoolExecutor`), or a Dask cluster (``scheduler``,
an address or a ``distributed.Client``; needs ``pip install 'trackcli[dask]'``, and the
workers must see the same file paths).

One module (over 600 lines): manifest parsing, the job loop and the three schedulers
(in process, worker processes, Dask) share the job and result types and the interrupt
handling, which must stay in one place to be right.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import signal
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence


from trackcli import __version__
from trackcli.settings import Settings, load_settings, set_dotted, settings_from_dict, to_dict
from trackcli.errors import ConfigError, InputError, TrackcliError, short_repr
from trackcli.io.outputs import ensure_dir, partial_name, write_text
from trackcli.run.clips import clip_name, output_files, track_clip
from trackcli.trackers import TRACKERS

log = logging.getLogger(__name__)

#: Manifest format version this module reads.
FORMAT = 1

#: Keys of a clip entry, and those ``defaults`` may also give.
CLIP_KEYS = ("clip", "name", "truth", "object", "threshold", "model", "template", "tracker", "config",
             "settings", "seed", "fps", "rrd")
DEFAULT_KEYS = tuple(k for k in CLIP_KEYS if k not in ("clip", "name", "truth"))

#: File that marks a job complete, and the scores beside it.
RESULT_FILE = "result.json"
SCORE_FILE = "score.json"
#: Batch summary in the output folder.
SUMMARY_FILE = "summary.json"

STATUSES = ("ok", "skipped", "failed")


# ---------------------------------------------------------------------------------------------
# Jobs and results


@dataclass(frozen=True)
class Job:
    """One clip to track (and score), fully resolved.

    Attributes
    ----------
    name : str
        Output folder name, unique in the batch.
    clip : str
        Absolute path of the video file or image folder.
    settings : Settings
        Effective settings (seed, frame selection, tracker parameters).
    tracker : {"condensation", "kalman"}
    model, template : str or None
        Absolute paths; at least one is given.
    truth : str or None
        Absolute path of the ground truth, if the run is to be scored.
    object_id : int
        Object of a truth CSV with several objects.
    threshold : float
        Centre-error threshold (px) of precision.
    rrd : bool
        Write a recording.
    entry : str
        Where the job came from, e.g. ``"clips[2]"`` (for messages).
    """

    name: str
    clip: str
    settings: Settings
    tracker: str = "condensation"
    model: str | None = None
    template: str | None = None
    truth: str | None = None
    object_id: int = 0
    threshold: float = 20.0
    rrd: bool = True
    entry: str = ""


@dataclass(frozen=True)
class Manifest:
    """A validated manifest: its path and its jobs, in file order."""

    path: Path
    jobs: tuple[Job, ...]


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
        Output files by kind (``csv``, ``rrd``, ``config``, ``score``, ``result``).
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
            "folder": self.folder, "outputs": dict(self.outputs),
        }


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
            "failed": self.count("failed"), "precision_mean": mean("precision"),
            "success_auc_mean": mean("success_auc"), "centre_error_mean": mean("centre_error_mean"),
            "seconds": round(self.seconds, 3), "executor": self.executor, "outdir": self.outdir,
        }


def _finite(v: Any, digits: int | None = None) -> float | None:
    if v is None:
        return None
    v = float(v)
    if not math.isfinite(v):
        return None
    return round(v, digits) if digits is not None else v


# ---------------------------------------------------------------------------------------------
# The manifest


def load_manifest(path: str | os.PathLike[str]) -> Manifest:
    """Read and validate a batch manifest (format in the module docstring).

    Returns
    -------
    Manifest

    Raises
    ------
    InputError
        The manifest file is missing or unreadable, or a path in it names no file.
    ConfigError
        Anything else wrong inside it.  Messages start with the manifest's path and name the
        entry and key (``clips[2].template: no such file: ...``).
    """
    from trackcli.io.outputs import read_yaml_file

    path = Path(path)
    data = read_yaml_file(path, "manifest", InputError, invalid=ConfigError)
    try:
        jobs = _parse(data, path.resolve().parent)
    except (ConfigError, InputError) as exc:
        raise type(exc)(f"{path}: {exc}") from None
    return Manifest(path, jobs)


def _parse(data: Any, base: Path) -> tuple[Job, ...]:
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping with 'clips' (and optionally 'format', 'defaults') at the top level")
    unknown = [k for k in data if k not in ("format", "defaults", "clips")]
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown key (valid at the top level: format, defaults, clips)")
    fmt = data.get("format", FORMAT)
    if isinstance(fmt, bool) or fmt != FORMAT:
        raise ConfigError(f"format: this version reads manifest format {FORMAT}, got {short_repr(fmt)}")
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise ConfigError(f"defaults: expected a mapping of clip settings, got {short_repr(defaults)}")
    _check_keys(defaults, DEFAULT_KEYS, "defaults")
    clips = data.get("clips")
    if not isinstance(clips, list) or not clips:
        raise ConfigError(f"clips: expected a non-empty list of clips, got {short_repr(clips)}")
    jobs = [_job(entry, f"clips[{i}]", defaults, base) for i, entry in enumerate(clips)]
    seen: dict[str, str] = {}
    for job in jobs:
        key = job.name.casefold()
        if key in seen:
            raise ConfigError(f"{job.entry}.name: {job.name!r} is also the name of {seen[key]}; "
                              "give one of them a distinct 'name'")
        seen[key] = job.entry
    return tuple(jobs)


def _check_keys(entry: Mapping[str, Any], valid: Sequence[str], where: str) -> None:
    for k in entry:
        if k not in valid:
            raise ConfigError(f"{where}.{k}: unknown key (valid: {', '.join(valid)})")


def _job(entry: Any, where: str, defaults: Mapping[str, Any], base: Path) -> Job:
    if isinstance(entry, str):
        entry = {"clip": entry}
    if not isinstance(entry, dict):
        raise ConfigError(f"{where}: expected a clip path or a mapping with 'clip', got {short_repr(entry)}")
    _check_keys(entry, CLIP_KEYS, where)
    if "clip" not in entry:
        raise ConfigError(f"{where}: missing 'clip' (the video file or image folder)")

    def get(key: str) -> tuple[Any, str]:
        """The value of ``key`` and the label naming where it came from."""
        if key in entry:
            return entry[key], f"{where}.{key}"
        return defaults.get(key), f"defaults.{key}"

    clip = _path(*get("clip"), base, folder_ok=True)
    paths = {k: _path(*get(k), base, folder_ok=(k == "truth")) for k in ("model", "template", "config", "truth")}
    if not paths["model"] and not paths["template"]:
        raise ConfigError(f"{where}: give a model, a template, or both (here or in defaults)")
    tracker, label = get("tracker")
    tracker = "condensation" if tracker is None else tracker
    if tracker not in TRACKERS:
        raise ConfigError(f"{label}: expected one of {', '.join(TRACKERS)}, got {short_repr(tracker)}")
    object_id = _integer(*get("object"), default=0)
    threshold = _positive(*get("threshold"), default=20.0)
    rrd, label = get("rrd")
    if rrd is None:
        rrd = True
    if not isinstance(rrd, bool):
        raise ConfigError(f"{label}: expected true or false, got {short_repr(rrd)}")
    name, label = get("name")
    name = clip_name(clip) if name is None else name
    if (not isinstance(name, str) or name in ("", ".", "..") or name.startswith(".")
            or any(c in name for c in "/\\\0")):
        raise ConfigError(f"{label}: expected a folder name (no '/', not starting with '.'), got {short_repr(name)}")
    settings = _settings(where, entry, defaults, paths["config"])
    return Job(name=name, clip=clip, settings=settings, tracker=tracker, model=paths["model"],
               template=paths["template"], truth=paths["truth"], object_id=object_id, threshold=threshold,
               rrd=rrd, entry=where)


def _path(value: Any, label: str, base: Path, *, folder_ok: bool) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{label}: expected a path, got {short_repr(value)}")
    p = Path(os.path.expanduser(value))
    p = Path(os.path.normpath(p if p.is_absolute() else base / p))
    if folder_ok and p.exists():
        return str(p)
    if not p.is_file():
        what = "no such file or folder" if folder_ok else ("is a folder, expected a file" if p.is_dir() else "no such file")
        raise InputError(f"{label}: {what}: {p}")
    return str(p)


def _integer(value: Any, label: str, *, default: int) -> int:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(f"{label}: expected an integer >= 0, got {short_repr(value)}")
    return value


def _positive(value: Any, label: str, *, default: float) -> float:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{label}: expected a number > 0, got {short_repr(value)}")
    return float(value)


def _flatten(overrides: Any, label: str) -> dict[str, Any]:
    """Nested mappings and dotted keys as one mapping of dotted keys."""
    if not isinstance(overrides, dict):
        raise ConfigError(f"{label}: expected a mapping of settings (nested or dotted keys), got {short_repr(overrides)}")
    flat: dict[str, Any] = {}

    def walk(node: dict, prefix: str) -> None:
        for k, v in node.items():
            if not isinstance(k, str) or not k:
                raise ConfigError(f"{label}: setting names are strings, got {short_repr(k)}")
            key = f"{prefix}{k}"
            if isinstance(v, dict):
                walk(v, key + ".")
            else:
                flat[key] = v

    walk(overrides, "")
    return flat


def _settings(where: str, entry: Mapping[str, Any], defaults: Mapping[str, Any], config: str | None) -> Settings:
    config_label = f"{where}.config" if "config" in entry else "defaults.config"
    try:
        data = to_dict(load_settings(config))
    except ConfigError as exc:
        raise ConfigError(f"{config_label}: {exc}") from None
    for source, label in ((defaults, "defaults"), (entry, where)):
        steps = []
        if source.get("settings") is not None:
            steps.append((f"{label}.settings", _flatten(source["settings"], f"{label}.settings")))
        if source.get("seed") is not None:
            steps.append((label, {"seed": source["seed"]}))
        if source.get("fps") is not None:
            steps.append((label, {"video.fps": _positive(source["fps"], f"{label}.fps", default=0.0)}))
        for step_label, overrides in steps:
            for dotted, value in overrides.items():
                set_dotted(data, dotted, value, step_label)
            try:
                settings_from_dict(data)
            except ConfigError as exc:
                raise ConfigError(f"{step_label}.{exc}") from None
    return settings_from_dict(data)


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
    if not all(p.is_file() for p in files.values()):
        return None
    keys = ("frames", "frames_lost", "tracker_fps", "precision", "centre_error_mean", "success_auc", "mean_iou",
            "seconds")
    values = {k: stored.get(k) for k in keys}
    values["seconds"] = float(values["seconds"] or 0.0)
    return JobResult(name=job.name, clip=job.clip, status="skipped", tracker=job.tracker, folder=str(folder),
                     outputs={k: str(p) for k, p in files.items()}, **values)


def _clear_outputs(folder: Path, job: Job) -> None:
    """Remove what earlier runs of this job left: result first, then outputs and temporaries."""
    names = [RESULT_FILE, SCORE_FILE]
    for tracker in TRACKERS:
        names += [p.name for p in output_files(folder, job.name, tracker).values()]
    for n in names:
        for p in (folder / n, partial_name(folder / n)):
            with contextlib.suppress(FileNotFoundError):
                p.unlink()


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
        summary = track_clip(job.clip, settings=job.settings, outdir=folder, model=job.model,
                             template=job.template, tracker=job.tracker, name=job.name, rrd=job.rrd,
                             progress=check)
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
        files = _output_files(folder, job, scored=score is not None)
        result = JobResult(
            name=job.name, clip=job.clip, status="ok", tracker=job.tracker, frames=summary.frames,
            frames_lost=summary.frames_lost,
            tracker_fps=summary.tracker_fps,
            precision=score.precision if score else None,
            centre_error_mean=score.centre_error_mean if score else None,
            success_auc=score.success_auc if score else None,
            mean_iou=score.mean_iou if score else None,
            seconds=time.perf_counter() - t0, folder=str(folder), outputs={k: str(p) for k, p in files.items()},
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


def _failed(job: Job, folder: Path, message: str, t0: float | None = None) -> JobResult:
    seconds = time.perf_counter() - t0 if t0 is not None else 0.0
    with contextlib.suppress(OSError):  # a job that wrote nothing leaves no folder
        folder.rmdir()
    return JobResult(name=job.name, clip=job.clip, status="failed", error=message, tracker=job.tracker,
                     seconds=seconds, folder=str(folder))


# ---------------------------------------------------------------------------------------------
# Executors


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
        Called with each :class:`JobResult` as it arrives (skipped ones first, then in order
        of completion).

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
        done = None if force else completed_result(job, out)
        if done is not None:
            take(done)
        else:
            pending.append(job)
    if scheduler is not None:
        executor = "dask"
        stream = _run_dask(pending, out, scheduler) if pending else iter(())
    elif workers > 1 and len(pending) > 1:
        executor = f"processes:{min(workers, len(pending))}"
        stream = _run_processes(pending, out, min(workers, len(pending)))
    else:
        executor = "in-process"
        stream = (run_job(j, out) for j in pending)
    for r in stream:
        take(r)
    batch = BatchResult(tuple(results[n] for n in names), time.perf_counter() - t0, str(out), executor)
    _write_json(out / SUMMARY_FILE, {"summary": batch.summary(), "clips": [r.to_dict() for r in batch.results]})
    return batch


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


def _worker_job(job: Job, outdir: str) -> JobResult:
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


def _run_processes(jobs: list[Job], outdir: Path, workers: int) -> Iterator[JobResult]:
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


def _dask_job(job: Job, outdir: str, threads: int) -> JobResult:
    """One job on a Dask worker, OpenCV capped to the worker's share of the cores, and the
    worker's allocator left fast (:func:`_restore_malloc`)."""
    _cap_threads(threads)
    _restore_malloc()
    return run_job(job, outdir)


def _run_dask(jobs: list[Job], outdir: Path, scheduler: Any) -> Iterator[JobResult]:
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
