"""Score per-frame estimates against ground truth.

Two inputs meet here:

- **Predictions**: trackcli's per-frame estimates CSV (the "track format").  The columns used
  are ``frame`` (original frame index), ``cx, cy`` (centroid of the estimated contour),
  ``bbox_x, bbox_y, bbox_w, bbox_h`` (the object's box: the contour's, or the box the template
  was drawn from carried by it; clipped to the frame) and, if present,
  ``lost`` (0/1).  Every other column is ignored.  The rows may cover a subset of the clip
  (``--start`` / ``--step``).
- **Ground truth**, recognised by its content:

  1. a trackcli truth CSV (``<clip>.truth.csv``) whose header names at least ``frame, cx, cy,
     bbox_x, bbox_y, bbox_w, bbox_h``, usually also ``object`` (several objects per frame; one is
     chosen, ``0`` by default) and ``visible`` (the visible fraction of the object, 0 to 1);
  2. a benchmark box file (``groundtruth_rect.txt`` as in OTB-style folders): one ``x,y,w,h``
     line per frame, the first line being frame 0, fields separated by commas, tabs or spaces;
     a line of 8 numbers is a rotated box as VOT writes it (``x1,y1,...,x4,y4``), scored by the
     axis-aligned rectangle around it;
  3. a folder holding ``groundtruth_rect.txt`` or ``groundtruth.txt``.

Boxes are ``(x, y, w, h)`` in pixels in the package's image coordinates (``x`` right, ``y``
down).  The truth *centre* is ``(cx, cy)`` for a trackcli truth file and the box centre
``(x + w/2, y + h/2)`` for a benchmark box file.  The prediction centre is taken of the same
kind, so that like is compared with like: the contour centroid ``(cx, cy)`` against a truth
centroid, the centre of ``bbox`` against a truth box.  Benchmark annotations made with 1-based
(MATLAB) pixel indices are used as written; that convention differs from this package's by
about one pixel, far below the usual 20 px precision threshold.

Which frames are scored
-----------------------
A truth frame is *absent* (the target is not in view) when its ``visible`` fraction is 0, when any
of its box numbers is NaN, or when its box has zero width or height (the ``0,0,0,0`` lines of
benchmark files).  Absent frames are left out of every metric and counted in
``frames_absent``.

The predictions define the *scoring window*: frames from the first to the last predicted
frame, on the grid of the predicted frames (its step is the greatest common divisor of the
gaps between predicted frames, so a ``--step 3`` run is scored on every third frame).  Every
truth frame in the window whose target is present is scored.  A scored frame without a usable
estimate (no row, or a row with a NaN centre or box) is *missing*: its centre error is
``inf`` (it fails precision at every threshold) and its IoU is 0.

A scored frame is *lost* when any of these holds: it is missing; the prediction's ``lost``
column is 1; its IoU is 0; its centre error exceeds ``lost_threshold`` (when one is given).

Metrics (the usual OTB definitions)
-----------------------------------
- centre error: Euclidean distance in pixels between predicted and true centre; the mean,
  median and maximum are taken over the scored frames that have an estimate (missing frames
  enter precision, success and mean IoU instead);
- precision at ``threshold``: fraction of scored frames with centre error ``<= threshold``;
- IoU: area of the intersection of the two boxes over the area of their union;
- success rate at an overlap threshold ``t``: fraction of scored frames with ``IoU > t``; the
  success AUC is the mean of the success rates at ``t = np.linspace(0, 1, 21)``;
- mean IoU over the scored frames;
- outline IoU, when both sides have outlines (the track CSV's ``outline_x*, outline_y*``
  columns, and for a trackcli truth CSV ``<clip>.truth.csv`` the base outline
  ``<clip>.outline.json`` beside it, placed by the row's ``tx, ty, angle, scale``): area of
  the intersection of the two closed outlines over the area of their union, measured on a
  1/4-pixel raster; its mean over the scored frames (missing frames count 0) is
  ``outline_iou``.  It sees what the box hides: a contour that is rotated or hugs the wrong
  part of the object inside the right box.

When the track and the truth cover different frames (a track that stops early, a truth
file longer or shorter than the clip), :func:`coverage_notes` says so; ``trackcli eval``
prints the notes as warnings, with the frames that were scored.  :func:`mismatch_notes`
adds what suggests the truth is of another clip: a track whose box meets the truth's on no
frame, and, when the truth is a benchmark folder holding the frames, a track with frames
past the clip's last (refused) or estimates that do not fit its frames
(:func:`trackcli.run.checks.check_track_on_clip`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.io.truth import TRUTH_FILE_NAMES, GroundTruth, PathLike, Track, box_centres, load_track
from trackcli.run.truth import load_truth

log = logging.getLogger(__name__)

__all__ = [
    "SUCCESS_THRESHOLDS",
    "TRUTH_FILE_NAMES",
    "EvalResult",
    "FrameScores",
    "GroundTruth",
    "Track",
    "box_centres",
    "box_iou",
    "coverage_notes",
    "mismatch_notes",
    "polygon_iou",
    "evaluate",
    "format_table",
    "load_track",
    "load_truth",
    "score_frames",
    "success_rates",
    "summarise",
]

SUCCESS_THRESHOLDS: np.ndarray = np.linspace(0.0, 1.0, 21)
"""Overlap thresholds ``(21,)`` at which the success rate is taken for the AUC."""
SUCCESS_THRESHOLDS.setflags(write=False)



@dataclass(frozen=True)
class FrameScores:
    """Per-frame scores over the scoring window (see the module docstring).

    Attributes
    ----------
    frame : ndarray of int64, shape (K,)
        The scored frames: truth present, inside the scoring window.
    centre_error : ndarray of float64, shape (K,)
        Centre error in pixels; ``inf`` for missing frames.
    iou : ndarray of float64, shape (K,)
        Box overlap in [0, 1]; 0 for missing frames.
    missing : ndarray of bool, shape (K,)
        No usable estimate for the frame.
    lost : ndarray of bool, shape (K,)
        Frame counted as lost.
    frames_absent : int
        Truth frames inside the window that were left out because the target is absent.
    first_frame, last_frame, frame_step : int
        The scoring window.
    centre_kind : {"centroid", "box"}
        Which centres were compared.
    lost_threshold : float or None
        The centre-error limit used for ``lost``.
    outline_iou : ndarray of float64, shape (K,), or None
        Outline overlap in [0, 1] (0 for missing frames); None unless both sides have outlines.
    """

    frame: np.ndarray
    centre_error: np.ndarray
    iou: np.ndarray
    missing: np.ndarray
    lost: np.ndarray
    frames_absent: int
    first_frame: int
    last_frame: int
    frame_step: int
    centre_kind: str
    lost_threshold: float | None
    outline_iou: np.ndarray | None = None


@dataclass(frozen=True)
class EvalResult:
    """Summary scores of one prediction file against one ground truth.

    Attributes
    ----------
    frames_scored : int
        Truth frames with the target present inside the scoring window.
    frames_missing : int
        Scored frames with no usable estimate (error ``inf``, IoU 0).
    frames_lost : int
        Scored frames counted as lost (see the module docstring).
    frames_absent : int
        Truth frames inside the window without the target; not scored.
    centre_error_mean, centre_error_median, centre_error_max : float
        Centre error statistics in pixels over scored frames that have an estimate (NaN if
        none has).
    precision : float
        Fraction of scored frames with centre error ``<= threshold``.
    threshold : float
        Pixel threshold of ``precision``.
    success_auc : float
        Mean of ``success_rates``.
    success_rates : tuple of float, length 21
        Fraction of scored frames with ``IoU > t`` for ``t`` in :data:`SUCCESS_THRESHOLDS`.
    mean_iou : float
        Mean IoU over scored frames (missing frames count 0).
    lost_threshold : float or None
        Centre-error limit for ``lost``, if one was given.
    centre_kind : str
        ``"centroid"`` or ``"box"``: which centres were compared.
    first_frame, last_frame, frame_step : int
        The scoring window.
    outline_iou : float or None
        Mean outline IoU over scored frames (missing frames count 0); None when the track or
        the truth has no outlines.
    """

    frames_scored: int
    frames_missing: int
    frames_lost: int
    frames_absent: int
    centre_error_mean: float
    centre_error_median: float
    centre_error_max: float
    precision: float
    threshold: float
    success_auc: float
    success_rates: tuple[float, ...]
    mean_iou: float
    lost_threshold: float | None
    centre_kind: str
    first_frame: int
    last_frame: int
    frame_step: int
    outline_iou: float | None = None

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary: ints, floats, strings, lists; NaN becomes ``None``."""

        def plain(v):
            if isinstance(v, (bool, np.bool_)):
                return bool(v)
            if isinstance(v, (int, np.integer)):
                return int(v)
            if isinstance(v, (float, np.floating)):
                v = float(v)
                return v if math.isfinite(v) else None
            if isinstance(v, tuple):
                return [plain(x) for x in v]
            return v

        out = {name: plain(getattr(self, name)) for name in self.__dataclass_fields__}
        out["success_thresholds"] = [float(t) for t in SUCCESS_THRESHOLDS]
        return out


# ---------------------------------------------------------------------------------------------
# Geometry


def box_iou(a, b) -> np.ndarray:
    """Intersection over union of axis-aligned boxes, element by element.

    Parameters
    ----------
    a, b : array_like, shape (..., 4)
        Boxes ``(x, y, w, h)`` with ``w, h >= 0``; broadcast against each other.

    Returns
    -------
    ndarray, shape (...)
        Values in [0, 1]; 0 where the union has no area or a box has a NaN.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ix = np.minimum(a[..., 0] + a[..., 2], b[..., 0] + b[..., 2]) - np.maximum(a[..., 0], b[..., 0])
    iy = np.minimum(a[..., 1] + a[..., 3], b[..., 1] + b[..., 3]) - np.maximum(a[..., 1], b[..., 1])
    inter = np.clip(ix, 0.0, None) * np.clip(iy, 0.0, None)
    union = a[..., 2] * a[..., 3] + b[..., 2] * b[..., 3] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    iou = np.where(np.isfinite(iou), iou, 0.0)
    return np.clip(iou, 0.0, 1.0)


#: Raster cells per pixel (each way) on which outline overlaps are measured.
OUTLINE_RASTER = 4


def polygon_iou(a, b, *, raster: int = OUTLINE_RASTER) -> float:
    """Intersection over union of two closed outlines (simple or not: even-odd filling).

    Both polygons are filled on a common grid of ``raster`` cells per pixel covering their
    union's box, and the cells are counted; the error is a fraction of a cell along the
    outlines (an IoU good to about 0.01 for objects 20 px across at ``raster = 4``).

    Parameters
    ----------
    a, b : array_like, shape (P, 2) and (Q, 2)
        Vertices ``(x, y)`` in pixels, in order, the last joined to the first.

    Returns
    -------
    float
        In [0, 1]; 0 when either outline has a NaN or no area.
    """
    import cv2

    a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    if len(a) < 3 or len(b) < 3 or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return 0.0
    both = np.vstack([a, b])
    lo = np.floor(both.min(axis=0)) - 1.0
    hi = np.ceil(both.max(axis=0)) + 1.0
    w, h = (int(v) for v in (hi - lo) * raster)
    if w <= 0 or h <= 0 or w * h > 64_000_000:
        raise DataError(f"outline too large to rasterise ({w} x {h} cells)")
    shift = 4  # sub-cell vertex precision for fillPoly

    def mask(poly: np.ndarray) -> np.ndarray:
        m = np.zeros((h, w), dtype=np.uint8)
        pts = np.rint((poly - lo) * raster * (1 << shift) - 0.5 * (1 << shift)).astype(np.int32)
        cv2.fillPoly(m, [pts], 1, lineType=cv2.LINE_8, shift=shift)
        return m.astype(bool)

    ma, mb = mask(a), mask(b)
    union = np.count_nonzero(ma | mb)
    return float(np.count_nonzero(ma & mb) / union) if union else 0.0


def success_rates(iou, thresholds=SUCCESS_THRESHOLDS) -> np.ndarray:
    """Success rates: fraction of frames with ``IoU > t`` for each threshold ``t``.

    Parameters
    ----------
    iou : array_like, shape (K,)
        Per-frame overlaps, K >= 1.
    thresholds : array_like, shape (T,)

    Returns
    -------
    ndarray, shape (T,)
    """
    iou = np.asarray(iou, dtype=np.float64).reshape(-1)
    thresholds = np.asarray(thresholds, dtype=np.float64).reshape(-1)
    if iou.size == 0:
        raise DataError("success rates need at least one frame, got none")
    return (iou[:, None] > thresholds[None, :]).mean(axis=0)


# ---------------------------------------------------------------------------------------------
# Scoring


def _check_threshold(name: str, value, *, nullable: bool) -> float | None:
    if value is None and nullable:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not math.isfinite(v) or v < 0:
        valid = "a finite number >= 0" + (" or None" if nullable else "")
        raise ConfigError(f"{name}: expected {valid}, got {value!r}")
    return v


def score_frames(pred: Track, truth: GroundTruth, *, lost_threshold: float | None = None) -> FrameScores:
    """Match predictions to truth by frame index and score every frame in the window.

    Parameters
    ----------
    pred : Track
    truth : GroundTruth
    lost_threshold : float or None
        Centre error in pixels above which a frame counts as lost.

    Returns
    -------
    FrameScores

    Raises
    ------
    DataError
        No frame has both a prediction and the target present in the truth.
    """
    lost_threshold = _check_threshold("lost_threshold", lost_threshold, nullable=True)
    if pred.frame.size == 0:
        raise DataError(f"{pred.source}: no predicted frames to score")
    first, last = int(pred.frame[0]), int(pred.frame[-1])
    step = int(np.gcd.reduce(np.diff(pred.frame))) if pred.frame.size > 1 else 1

    in_window = (truth.frame >= first) & (truth.frame <= last) & ((truth.frame - first) % step == 0)
    scored = in_window & truth.present
    frames = truth.frame[scored]
    t_box = truth.box[scored]
    t_centre = truth.centre[scored]

    pos = np.clip(np.searchsorted(pred.frame, frames), 0, pred.frame.size - 1)
    has_row = pred.frame[pos] == frames if frames.size else np.zeros(0, dtype=bool)
    if not np.any(has_row):
        present = truth.frame[truth.present]
        span = f"frames {present[0]}-{present[-1]}" if present.size else "no frame"
        raise DataError(
            f"no frame has both a prediction and ground truth: {pred.source} covers frames "
            f"{first}-{last} (step {step}), {truth.source} has the target in {span}"
        )
    p_box = pred.box[pos]
    p_centre = pred.centre[pos] if truth.centre_kind == "centroid" else box_centres(p_box)
    usable = has_row & np.all(np.isfinite(p_box), axis=1) & np.all(np.isfinite(p_centre), axis=1)

    error = np.full(frames.shape, np.inf)
    error[usable] = np.hypot(*(p_centre[usable] - t_centre[usable]).T)
    iou = np.zeros(frames.shape)
    iou[usable] = box_iou(p_box[usable], t_box[usable])

    lost = ~usable | (iou == 0.0) | (has_row & pred.lost[pos])
    if lost_threshold is not None:
        lost |= error > lost_threshold

    outline_iou = None
    if pred.outline is not None and truth.outline is not None:
        t_outline = truth.outline[scored]
        outline_iou = np.zeros(frames.shape)
        for k in np.flatnonzero(usable):
            outline_iou[k] = polygon_iou(pred.outline[pos[k]], t_outline[k])

    return FrameScores(
        frame=frames,
        centre_error=error,
        iou=iou,
        missing=~usable,
        lost=lost,
        frames_absent=int(np.count_nonzero(in_window & ~truth.present)),
        first_frame=first,
        last_frame=last,
        frame_step=step,
        centre_kind=truth.centre_kind,
        lost_threshold=lost_threshold,
        outline_iou=outline_iou,
    )


def _span(frames: np.ndarray) -> str:
    if frames.size == 0:
        return "no frames"
    return f"frames {int(frames[0])}-{int(frames[-1])} ({frames.size} rows)"


def coverage_notes(pred: Track, truth: GroundTruth, scores: FrameScores | None = None) -> list[str]:
    """Plain-language notes when the track and the truth cover different frames.

    Empty when every truth frame has a row in the track and vice versa.  Otherwise the notes
    say what each file covers, what is left out of the scores and which frames were scored:
    truth frames outside the scoring window (a track that stops early or starts late), and
    predicted frames the truth has no entry for (a truth file shorter than the clip).

    Parameters
    ----------
    pred : Track
    truth : GroundTruth
    scores : FrameScores, optional
        The scores, to name the frames that were scored.
    """
    notes: list[str] = []
    pf, tf = pred.frame, truth.frame
    if pf.size == tf.size and np.array_equal(pf, tf):
        return notes
    first, last = (int(pf[0]), int(pf[-1])) if pf.size else (0, -1)
    outside = tf[(tf < first) | (tf > last)]
    unknown = np.setdiff1d(pf, tf)
    head = f"{pred.source} covers {_span(pf)}; {truth.source} covers {_span(tf)}"
    if outside.size:
        notes.append(f"{head}: {outside.size} truth frames outside the track's frames "
                     f"{first}-{last} are not scored")
        head = ""
    if unknown.size:
        notes.append((f"{head}: " if head else "") + f"{unknown.size} predicted frames "
                     f"({int(unknown[0])}-{int(unknown[-1])}) have no ground truth and are not scored")
        head = ""
    if not notes:
        notes.append(f"{head}: the scored frames are those in both")
    if scores is not None:
        scored = scores.frame
        what = (f"frames {int(scored[0])}-{int(scored[-1])}" + (f" step {scores.frame_step}" if scores.frame_step != 1 else "")
                if scored.size else "no frame")
        notes.append(f"scored {scored.size} frames: {what}")
    return notes


def mismatch_notes(pred: Track, truth: GroundTruth, scores: FrameScores, truth_path: PathLike | None = None) -> list[str]:
    """Notes (see the module docstring) when ``pred`` and the truth seem to be of different clips.

    Raises
    ------
    DataError
        The truth is a folder with the clip's frames and the track has frames past its last.
    """
    from pathlib import Path

    notes: list[str] = []
    folder = Path(truth_path) if truth_path is not None else None
    if folder is not None and folder.is_dir():
        from trackcli.errors import VideoError
        from trackcli.io.video import open_video
        from trackcli.run.checks import check_track_on_clip

        try:
            video = open_video(folder, fps=25.0)
        except VideoError:  # a folder with the truth only
            video = None
        if video is not None:
            with video:
                points = pred.outline if pred.outline is not None else pred.centre[:, None, :]
                notes += check_track_on_clip(pred.frame, points, width=video.width, height=video.height,
                                             n_frames=video.n_total, track=pred.source, clip=str(folder))
    if scores.frame.size > 1 and not np.any(scores.iou > 0):
        notes.append(f"{pred.source} meets the true box on none of the {scores.frame.size} frames scored: "
                     f"is {truth.source} the truth of another clip?")
    return notes


def summarise(scores: FrameScores, *, threshold: float = 20.0) -> EvalResult:
    """Summary metrics of per-frame scores (definitions in the module docstring).

    Parameters
    ----------
    scores : FrameScores
    threshold : float
        Pixel threshold for precision.

    Returns
    -------
    EvalResult
    """
    threshold = _check_threshold("threshold", threshold, nullable=False)
    n = scores.frame.size
    if n == 0:
        raise DataError("no scored frames")
    finite = scores.centre_error[~scores.missing]
    if finite.size:
        stats = float(finite.mean()), float(np.median(finite)), float(finite.max())
    else:
        stats = (math.nan,) * 3
    rates = success_rates(scores.iou)
    return EvalResult(
        frames_scored=int(n),
        frames_missing=int(np.count_nonzero(scores.missing)),
        frames_lost=int(np.count_nonzero(scores.lost)),
        frames_absent=int(scores.frames_absent),
        centre_error_mean=stats[0],
        centre_error_median=stats[1],
        centre_error_max=stats[2],
        precision=float(np.mean(scores.centre_error <= threshold)),
        threshold=threshold,
        success_auc=float(rates.mean()),
        success_rates=tuple(float(r) for r in rates),
        mean_iou=float(scores.iou.mean()),
        lost_threshold=scores.lost_threshold,
        centre_kind=scores.centre_kind,
        first_frame=scores.first_frame,
        last_frame=scores.last_frame,
        frame_step=scores.frame_step,
        outline_iou=None if scores.outline_iou is None else float(scores.outline_iou.mean()),
    )


def evaluate(
    pred: Track | PathLike,
    truth: GroundTruth | PathLike,
    *,
    threshold: float = 20.0,
    lost_threshold: float | None = None,
) -> EvalResult:
    """Score predictions against ground truth.

    Frames are matched by index.  Only truth frames with the target present and inside the
    predictions' scoring window are scored; a scored frame without a usable prediction has
    centre error ``inf`` and IoU 0, and counts as missing and lost.  A frame is lost if it is
    missing, if the prediction's ``lost`` column is 1, if its IoU is 0, or if its centre error
    exceeds ``lost_threshold`` when given.  Precision is the fraction of scored frames with
    centre error ``<= threshold``; the success AUC is the mean, over the 21 overlap thresholds
    ``t = np.linspace(0, 1, 21)``, of the fraction of scored frames with ``IoU > t``.  See the
    module docstring for the full definitions.

    Parameters
    ----------
    pred : Track or path
        Estimates, or the path of a track-format CSV (read with :func:`load_track`).
    truth : GroundTruth or path
        Ground truth, or a path read with :func:`load_truth` (object 0 of a truth CSV).
    threshold : float
        Centre-error threshold in pixels for precision.
    lost_threshold : float or None
        Centre error in pixels above which a frame counts as lost.

    Returns
    -------
    EvalResult

    Raises
    ------
    InputError
        A file is missing, unreadable or malformed.
    ConfigError
        A threshold is negative or not a number.
    DataError
        No frame has both a prediction and ground truth.
    """
    threshold = _check_threshold("threshold", threshold, nullable=False)
    if not isinstance(pred, Track):
        pred = load_track(pred)
    if not isinstance(truth, GroundTruth):
        truth = load_truth(truth)
    return summarise(score_frames(pred, truth, lost_threshold=lost_threshold), threshold=threshold)


def format_table(result: EvalResult) -> str:
    """Human-readable table of an :class:`EvalResult` (one metric per line)."""

    def px(v: float) -> str:
        return f"{v:.2f}" if math.isfinite(v) else "n/a"

    window = f"{result.first_frame}-{result.last_frame}"
    if result.frame_step != 1:
        window += f" step {result.frame_step}"
    lost_rule = "IoU 0, missing or flagged"
    if result.lost_threshold is not None:
        lost_rule += f", or error > {result.lost_threshold:g} px"
    rows = [
        ("frames scored", f"{result.frames_scored}  (window {window}; {result.frames_absent} with the target absent)"),
        ("frames missing", f"{result.frames_missing}"),
        ("frames lost", f"{result.frames_lost}  ({lost_rule})"),
        (
            f"centre error [px, {result.centre_kind}]",
            f"mean {px(result.centre_error_mean)}  median {px(result.centre_error_median)}  "
            f"max {px(result.centre_error_max)}",
        ),
        (f"precision @ {result.threshold:g} px", f"{result.precision:.3f}"),
        ("success AUC", f"{result.success_auc:.3f}"),
        ("mean IoU", f"{result.mean_iou:.3f}"),
    ]
    if result.outline_iou is not None:
        rows.append(("outline IoU", f"{result.outline_iou:.3f}"))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
