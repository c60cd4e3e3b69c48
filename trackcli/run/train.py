"""The track → learn cycle of AC Fig 11.1: training a model on clean clips.

Cycle 1 tracks every training clip with the Kalman contour tracker under hand-set dynamics
(AC §9.6) and learns AR(2) dynamics by maximum likelihood from the tracked shape sequences
(AC Fig 11.6), pooling the clips' statistics.  Each further cycle re-tracks the clips with
the dynamics just learned and learns again.  With a PCA shape-space (``pca:K``) the first
cycle's tracked outlines also give a residual-PCA space on top of translation (AC eqs
8.26–8.27); its shape vectors are the L2 projections of those outlines, and later cycles
track in it.
"""

from __future__ import annotations

import logging
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from trackcli.shapes import shape_space as ss
from trackcli.settings import Settings, to_dict
from trackcli.dynamics.ar2 import AR2
from trackcli.errors import ConfigError, DataError
from trackcli.dynamics.learning import fit_ar2
from trackcli.dynamics.model import Model
from trackcli.run.clips import RunSummary, no_progress, output_files, run_clip
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.shapes.template import Template
from trackcli.shapes.outline import build_space
from trackcli.dynamics.handset import handset_dynamics
from trackcli.trackers.base import run_tracker
from trackcli.trackers.kalman_tracker import KalmanTracker
from trackcli.io.tracks import read_track

log = logging.getLogger(__name__)

#: Ways of learning dynamics: maximum likelihood on the tracked shapes, or EM on the measurements.
METHODS = ("mle", "em")


def parse_shape_space(spec: str | None, default: str) -> tuple[str, int | None]:
    """``"affine"`` → ("affine", None); ``"pca:3"`` → ("pca", 3)."""
    spec = spec or default
    m = re.fullmatch(r"pca:(\d+)", spec)
    if m:
        k = int(m.group(1))
        if k < 1:
            raise ConfigError(f"--shape-space pca:K needs K >= 1, got {spec!r}")
        return "pca", k
    if spec in ("translation", "similarity", "affine"):
        return spec, None
    raise ConfigError(f"--shape-space: expected translation, similarity, affine or pca:K, got {spec!r}")


@dataclass
class CycleRecord:
    cycle: int
    seconds: float
    runs: list[RunSummary] = field(default_factory=list)
    report: dict[str, Any] = field(default_factory=dict)


#: A piece of a track shorter than this has no frame triple to learn AR(2) dynamics from.
MIN_SEGMENT = 3
#: Dropping more than this fraction of the training frames is warned about.
DROP_WARN_FRACTION = 0.1


def held_segments(X: np.ndarray, lost: np.ndarray | None) -> list[np.ndarray]:
    """The runs of consecutive frames the tracker held (``lost`` false), of at least
    :data:`MIN_SEGMENT` frames, in order.  ``lost = None`` means every frame was held."""
    X = np.asarray(X, dtype=float)
    if lost is None:
        return [X] if len(X) >= MIN_SEGMENT else []
    lost = np.asarray(lost, dtype=bool)
    if lost.shape != (len(X),):
        raise DataError(f"{len(X)} frames but {lost.size} lost flags")
    out, start = [], None
    for k, bad in enumerate([*lost, True]):
        if not bad and start is None:
            start = k
        elif bad and start is not None:
            if k - start >= MIN_SEGMENT:
                out.append(X[start:k])
            start = None
    return out


def learn_from_sequences(sequences: Sequence[np.ndarray], tau: float, settings: Settings, *,
                         lost: Sequence[np.ndarray | None] | None = None,
                         labels: Sequence[str] | None = None) -> tuple[AR2, dict[str, Any]]:
    """Fit AR(2) dynamics to several shape sequences (statistics pooled).

    With ``lost`` (one array of flags per sequence, or None for a sequence held
    throughout), only the frames the tracker held are learned from: lost frames split a
    sequence into segments, and segments of at least :data:`MIN_SEGMENT` frames are pooled
    like separate sequences (AC §11.2), so that no frame triple spans a lost stretch.  A
    warning gives the counts when more than a tenth of the frames is dropped.

    Raises
    ------
    DataError
        Too few held frames are left to learn from.
    """
    sequences = [np.asarray(X, dtype=float) for X in sequences]
    flags = list(lost) if lost is not None else [None] * len(sequences)
    names = list(labels) if labels is not None else [f"sequence {i + 1}" for i in range(len(sequences))]
    if len(flags) != len(sequences) or len(names) != len(sequences):
        raise DataError("one list of lost flags and one label per sequence are needed")
    segments: list[np.ndarray] = []
    per_clip = []
    for X, fl, name in zip(sequences, flags, names):
        pieces = held_segments(X, fl)
        segments += pieces
        used = sum(len(p) for p in pieces)
        n_lost = int(np.count_nonzero(fl)) if fl is not None else 0
        per_clip.append({"name": name, "frames": len(X), "lost": n_lost, "used": used, "segments": len(pieces)})
    total = sum(c["frames"] for c in per_clip)
    used = sum(c["used"] for c in per_clip)
    dropped = total - used
    if total and dropped > DROP_WARN_FRACTION * total:
        detail = "; ".join(f"{c['name']}: {c['lost']} lost, {c['frames'] - c['used'] - c['lost']} in pieces "
                           f"shorter than {MIN_SEGMENT} frames, {c['used']} used in {c['segments']} segment(s)"
                           for c in per_clip if c["used"] < c["frames"])
        log.warning("learning from %d of %d training frames: %d dropped where the tracker had lost the object (%s)",
                    used, total, dropped, detail)
    nx = sequences[0].shape[1] if sequences and sequences[0].ndim == 2 else 1
    triples = sum(len(p) - 2 for p in segments)
    if triples <= 2 * nx + 1:
        raise DataError(f"too few frames held by the tracker to learn from: {used} of {total} frames in "
                        f"{len(segments)} segment(s) of at least {MIN_SEGMENT} held frames give {triples} frame "
                        f"triples, and {nx}-dimensional AR(2) dynamics need more than {2 * nx + 1}; "
                        "train on clips the tracker follows, or with settings that hold the object")
    model, report = fit_ar2(segments, tau, enforce_stability=settings.learning.enforce_stability,
                            max_spectral_radius=settings.learning.max_spectral_radius)
    out = report.to_dict()
    out["frames_total"] = total
    out["frames_dropped"] = dropped
    out["per_sequence"] = per_clip
    return model, out


def read_lost(path: str | Path, n_rows: int) -> np.ndarray:
    """The ``lost`` column of a track CSV (all false when the file has none)."""
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.reader(fh) if r]
    head = rows[0]
    if "lost" not in head:
        return np.zeros(n_rows, dtype=bool)
    i = head.index("lost")
    flags = []
    for k, r in enumerate(rows[1:], 2):
        cell = r[i].strip() if i < len(r) else ""
        if cell not in ("", "0", "1"):
            raise DataError(f"{path} line {k}: lost must be 0 or 1, got {cell!r}")
        flags.append(cell == "1")
    if len(flags) != n_rows:
        raise DataError(f"{path}: {n_rows} shape rows but {len(flags)} lost flags")
    return np.asarray(flags, dtype=bool)


def pca_space(template: Template, outlines_Q: np.ndarray, k: int) -> tuple[ShapeSpace, list[float]]:
    """Residual PCA on top of translation from tracked control vectors ``(T, 2Nq)``."""
    base = ss.translation(template.basis(), template.Q)
    space, explained = ss.residual_pca(base, outlines_Q, k)
    return space, [float(v) for v in explained]


def train(
    clips: Sequence[Any],
    template: Template,
    settings: Settings,
    *,
    cycles: int,
    shape_space: str | None,
    outdir: Path,
    write_rrd: bool = True,
    progress: Callable[[str, int], Any] | None = None,
    method: str = "mle",
) -> tuple[Model, list[CycleRecord]]:
    """Run the track → learn cycle on opened training clips (``trackcli.io.video.Video``).

    ``progress(label, n_frames)`` returns a context manager with ``update(1)`` (a progress bar).
    Writes ``outdir/CLIP.cycleC.csv`` and ``.rrd`` per clip and cycle.  ``method`` is
    ``"mle"`` (AC Fig 11.6 on the tracked shapes) or ``"em"`` (:mod:`trackcli.dynamics.em` on the
    measurements the tracker aggregated in each frame).
    """
    if method not in METHODS:
        raise ConfigError(f"learning method: expected one of {', '.join(METHODS)}, got {method!r}")
    kind, k = parse_shape_space(shape_space, settings.shape_space)
    taus = {round(1.0 / v.fps, 9) for v in clips}
    tau = 1.0 / clips[0].fps
    if len(taus) > 1:
        log.warning("training clips have different frame rates; learning with the first clip's (%.3g frames/s)",
                    clips[0].fps)
    space = build_space(template, "affine" if kind == "pca" else kind)
    dynamics = handset_dynamics(space, settings.dynamics, tau)
    records: list[CycleRecord] = []
    report: dict[str, Any] = {}
    explained: list[float] | None = None
    for cycle in range(1, cycles + 1):
        t0 = time.perf_counter()
        rec = CycleRecord(cycle, 0.0)
        sequences, flags, labels = [], [], []
        measured: list[Any] = []  # per clip, the tracker's (z, S) of each frame (method "em")
        for video in clips:
            stem = Path(str(video.path)).stem or Path(str(video.path)).name
            files = output_files(outdir, stem, f"cycle{cycle}")

            info: list[Any] = []
            measured.append(info)
            shapes: list[np.ndarray] = []
            lost: list[bool] = []

            def make(frames, space=space, dynamics=dynamics, info=info, shapes=shapes, lost=lost):
                # the loop's results feed learning directly: the shapes, the verdicts, and for
                # EM each frame's measurement
                for result in run_tracker(KalmanTracker(space, dynamics, settings), frames):
                    shapes.append(result.X)
                    lost.append(bool(result.lost))
                    if method == "em":
                        info.append(result.display["information"])
                    yield result

            label = f"cycle {cycle}: {stem}"
            ctx = progress(label, len(video)) if progress else no_progress()
            with ctx as bar:
                summary = run_clip(video, make, space, tracker="kalman", csv_path=files["csv"],
                                   rrd_path=files["rrd"] if write_rrd else None,
                                   params={"cycle": cycle, "clip": str(video.path), "settings": to_dict(settings)},
                                   jpeg_quality=settings.output.jpeg_quality, progress=bar.update,
                                   outline_points=settings.output.outline_points,
                                   frames_mode=settings.output.frames,
                                   recording_id=f"{stem}-cycle{cycle}")
            rec.runs.append(summary)
            sequences.append(np.asarray(shapes, dtype=float).reshape(len(shapes), space.Nx))
            flags.append(np.asarray(lost, dtype=bool))
            labels.append(f"{stem} (cycle {cycle})")
        tracked_space = space
        if kind == "pca" and cycle == 1:
            outlines = [space.to_control(X) for X in sequences]
            held = [Q[~fl] for Q, fl in zip(outlines, flags)]
            space, explained = pca_space(template, np.vstack(held), k)  # type: ignore[arg-type]
            sequences = [space.project(Q) for Q in outlines]
        if method == "em":
            dynamics, report = _learn_em(measured, sequences, tracked_space, space, tau, settings)
        else:
            dynamics, report = learn_from_sequences(sequences, tau, settings, lost=flags, labels=labels)
        if explained is not None:
            report["pca_explained"] = explained
        rec.report = report
        rec.seconds = time.perf_counter() - t0
        records.append(rec)
        log.info("cycle %d: learned from %d frames in %.1f s; spectral radius %.4f",
                 cycle, report.get("n_frames", 0), rec.seconds, report.get("spectral_radius", math.nan))
    provenance = {
        "method": method,
        "clips": [str(v.path) for v in clips],
        "frames": [len(v) for v in clips],
        "cycles": cycles,
        "shape_space": shape_space or settings.shape_space,
        "learning": report,
    }
    return Model(template, space, dynamics, settings, provenance), records


def _learn_em(measured: Sequence[Sequence[Any]], sequences: Sequence[np.ndarray], tracked: ShapeSpace,
              space: ShapeSpace, tau: float, settings: Settings) -> tuple[AR2, dict[str, Any]]:
    """EM on each clip's per-frame measurements (carried into ``space`` if it is new)."""
    from trackcli.dynamics.em import InformationSequence, change_space, learn_em

    seqs = []
    for info, X in zip(measured, sequences):
        z, S = np.array([z for z, _ in info]), np.array([S for _, S in info])
        seqs.append(InformationSequence(z, S, X) if space is tracked else change_space(z, S, tracked, space, X))
    return learn_em(seqs, tau, settings)


def learn_from_tracks(track_paths: Sequence[str], template: Template, settings: Settings, tau: float,
                      shape_space: str | None, method: str = "mle") -> Model:
    """Learn dynamics from track CSVs already made (no tracking).

    ``method="em"`` takes each row's shape with its reported standard deviations as the
    measurement of that frame, and rows marked lost as frames without one.
    """
    if method not in METHODS:
        raise ConfigError(f"learning method: expected one of {', '.join(METHODS)}, got {method!r}")
    kind, k = parse_shape_space(shape_space, settings.shape_space)
    if kind == "pca":
        raise ConfigError("--shape-space pca:K needs tracking (tracked outlines); not available with --from-tracks")
    space = build_space(template, kind)
    sequences, flags = [], []
    for p in track_paths:
        frames, X, _ = read_track(p, space.names)
        if len(frames) > 1 and len(set(np.diff(frames))) > 1:
            raise DataError(f"{p}: frames are not evenly spaced; learning needs a regular sequence")
        sequences.append(X)
        flags.append(read_lost(p, len(X)))
    if method == "em":
        from trackcli.dynamics.em import information_from_track, learn_em

        dynamics, report = learn_em([information_from_track(p, space.names) for p in track_paths], tau, settings)
    else:
        dynamics, report = learn_from_sequences(sequences, tau, settings, lost=flags,
                                                labels=[Path(str(p)).name for p in track_paths])
    provenance = {"method": method, "tracks": list(map(str, track_paths)), "frames": [len(s) for s in sequences],
                  "cycles": 0, "shape_space": kind, "learning": report}
    return Model(template, space, dynamics, settings, provenance)


def read_labels(label_files: Sequence[str | Path], n_tracks: int) -> list[list[tuple[int, int, str]]]:
    """The labelled ranges of ``learn --labels``, one file per training clip or track, checked
    before any tracking (:func:`trackcli.dynamics.mixed.read_label_ranges`)."""
    from trackcli.dynamics.mixed import read_label_ranges

    if len(label_files) != n_tracks:
        raise ConfigError(f"--labels: give one labels file per training clip or track ({n_tracks}), "
                          f"got {len(label_files)}")
    ranges = [read_label_ranges(p) for p in label_files]
    names = {lab for rs in ranges for _, _, lab in rs}
    if len(names) < 2:
        raise DataError(f"--labels: a mixed-state model needs at least two labels, the files name {sorted(names)}")
    return ranges


def learn_labelled(track_paths: Sequence[str | Path], label_files: Sequence[str | Path], template: Template,
                   space: ShapeSpace, tau: float, settings: Settings, provenance: dict[str, Any] | None = None,
                   ranges: Sequence[Sequence[tuple[int, int, str]]] | None = None) -> Any:
    """A mixed-state model from tracks and their labelled frame ranges (``learn --labels``).

    ``label_files[i]`` (``start,end,label`` rows, see
    :func:`trackcli.dynamics.mixed.read_label_ranges`) labels the frames of
    ``track_paths[i]``, by the track's ``frame`` column.  Frames the tracker lost and frames
    no range covers are left out.  Each label gets AR(2) dynamics by maximum likelihood from
    its runs of frames pooled over the tracks, and ``T`` is counted from the label sequences
    (:func:`trackcli.dynamics.mixed.learn_mixed`).  Returns a
    :class:`~trackcli.dynamics.mixed.MixedModel` holding ``template`` and ``space``.
    ``ranges``: the files already read by :func:`read_labels`.
    """
    from trackcli.dynamics.mixed import LabelSpec, MixedModel, learn_mixed

    if ranges is None:
        ranges = read_labels(label_files, len(track_paths))
    names = list(dict.fromkeys(lab for rs in ranges for _, _, lab in rs))  # in order of first mention
    sequences, label_seqs = [], []
    for path, rs, lf in zip(track_paths, ranges, label_files):
        frames, X, _ = read_track(path, space.names)
        lost = read_lost(path, len(X))
        seq = np.full(len(frames), -1, dtype=np.int64)
        for a, b, lab in rs:
            seq[(frames >= a) & (frames <= b)] = names.index(lab)
        if not (seq >= 0).any():
            raise DataError(f"{lf}: no range covers a frame of {path} (frames {int(frames[0])}-{int(frames[-1])})")
        seq[lost] = -1
        sequences.append(X)
        label_seqs.append(seq)
    models, T, report = learn_mixed(sequences, label_seqs, names, tau,
                                    max_spectral_radius=settings.learning.max_spectral_radius)
    labels = tuple(LabelSpec(n, ar2=m) for n, m in zip(names, models))
    prov = {**(provenance or {}), "labels_files": [str(p) for p in label_files], "mixed_learning": report}
    return MixedModel(labels, T, None, template, space, prov)
