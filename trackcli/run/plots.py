"""Precision and success plots of tracks against one ground truth, drawn with OpenCV.

The two plots tracking benchmarks (OTB and its successors) show side by side:

- **precision plot**: for each location-error threshold ``d`` from 0 to 50 px, the fraction of
  scored frames whose centre error is at most ``d``; the legend gives the precision at the
  threshold of ``trackcli eval`` (20 px by default);
- **success plot**: for each overlap threshold ``t`` from 0 to 1, the fraction of scored frames
  whose box IoU exceeds ``t``; the legend gives the success AUC (the mean over the 21
  thresholds ``0, 0.05, …, 1``, so that a perfect track scores 20/21 ≈ 0.952, since no IoU
  exceeds 1).

One curve per track, with a legend, as tracking papers show them.  Drawing with OpenCV keeps
the package free of a plotting library; the figure is a PNG written atomically.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from trackcli.errors import DataError
from trackcli.run.evaluate import SUCCESS_THRESHOLDS, FrameScores
from trackcli.io.outputs import atomic_path

#: Location-error thresholds (px) of the precision plot.
PRECISION_THRESHOLDS = np.arange(0.0, 50.5, 0.5)
#: Overlap thresholds of the success plot (drawn finely; the AUC uses SUCCESS_THRESHOLDS).
SUCCESS_CURVE_THRESHOLDS = np.linspace(0.0, 1.0, 101)

# Curve colours (BGR), chosen to stay apart for colour-blind readers.
_COLOURS = [(178, 114, 0), (0, 94, 213), (115, 158, 0), (167, 121, 204), (0, 159, 230), (233, 180, 86),
            (66, 228, 240), (0, 0, 0)]
_FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX


@dataclass(frozen=True)
class Curve:
    """One track's curves.

    Attributes
    ----------
    label : str
        Legend name.
    precision : ndarray of shape (len(PRECISION_THRESHOLDS),)
    success : ndarray of shape (len(SUCCESS_CURVE_THRESHOLDS),)
    precision_at : float
        Precision at the eval threshold (legend).
    auc : float
        Success AUC (legend).
    """

    label: str
    precision: np.ndarray
    success: np.ndarray
    precision_at: float
    auc: float


def curves(label: str, scores: FrameScores, threshold: float = 20.0) -> Curve:
    """Precision and success curves of one track's per-frame scores."""
    if scores.frame.size == 0:
        raise DataError(f"{label}: no scored frames to plot")
    err = scores.centre_error
    iou = scores.iou
    precision = (err[:, None] <= PRECISION_THRESHOLDS[None, :]).mean(axis=0)
    success = (iou[:, None] > SUCCESS_CURVE_THRESHOLDS[None, :]).mean(axis=0)
    auc = float((iou[:, None] > SUCCESS_THRESHOLDS[None, :]).mean())
    return Curve(label, precision, success, float(np.mean(err <= threshold)), auc)


def track_labels(paths: Sequence[str | Path]) -> list[str]:
    """Legend names for track files: ``CLIP.TRACKER.csv`` gives ``TRACKER`` when all share the clip.

    Falls back to the file names without ``.csv`` when the clips differ or names repeat.
    """
    stems = [Path(p).name.removesuffix(".csv") for p in paths]
    heads = {s.split(".", 1)[0] for s in stems}
    if len(heads) == 1 and all("." in s for s in stems):
        short = [s.split(".", 1)[1] for s in stems]
        if len(set(short)) == len(short):
            return short
    if len(set(stems)) == len(stems):
        return stems
    return [str(p) for p in paths]


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.5, colour=(40, 40, 40),
          thickness: int = 1, anchor: str = "left") -> None:
    import cv2

    (w, h), _ = cv2.getTextSize(text, _FONT, scale, thickness)
    x, y = org
    if anchor == "centre":
        x -= w // 2
    elif anchor == "right":
        x -= w
    cv2.putText(img, text, (x, y), _FONT, scale, colour, thickness, cv2.LINE_AA)


def _vertical_text(img: np.ndarray, text: str, centre: tuple[int, int], scale: float = 0.5) -> None:
    import cv2

    (w, h), base = cv2.getTextSize(text, _FONT, scale, 1)
    patch = np.full((h + base + 4, w + 4, 3), 255, dtype=np.uint8)
    cv2.putText(patch, text, (2, h + 2), _FONT, scale, (40, 40, 40), 1, cv2.LINE_AA)
    patch = cv2.rotate(patch, cv2.ROTATE_90_COUNTERCLOCKWISE)
    ph, pw = patch.shape[:2]
    x0, y0 = centre[0] - pw // 2, centre[1] - ph // 2
    region = img[y0:y0 + ph, x0:x0 + pw]
    np.minimum(region, patch[: region.shape[0], : region.shape[1]], out=region)


def _panel(img: np.ndarray, box: tuple[int, int, int, int], xs: np.ndarray, series: list[tuple[np.ndarray, str]],
           *, title: str, xlabel: str, ylabel: str, xticks: Sequence[float], xfmt: str,
           legend_loc: str) -> None:
    """Draw one plot into ``img`` inside ``box = (x, y, w, h)``: axes 0..1 up, ``xs`` across."""
    import cv2

    x0, y0, w, h = box
    left, right, top, bottom = x0 + 62, x0 + w - 14, y0 + 34, y0 + h - 48
    pw, ph = right - left, bottom - top
    xmin, xmax = float(xs[0]), float(xs[-1])

    def px(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        u = left + (np.asarray(x) - xmin) / (xmax - xmin) * pw
        v = bottom - np.asarray(y) * ph
        return np.column_stack([u, v])

    grid = (225, 225, 225)
    for t in np.linspace(0.0, 1.0, 6):
        yy = int(round(bottom - t * ph))
        cv2.line(img, (left, yy), (right, yy), grid, 1)
        _text(img, f"{t:.1f}", (left - 8, yy + 5), 0.45, anchor="right")
    for t in xticks:
        xx = int(round(left + (t - xmin) / (xmax - xmin) * pw))
        cv2.line(img, (xx, top), (xx, bottom), grid, 1)
        _text(img, format(t, xfmt), (xx, bottom + 18), 0.45, anchor="centre")
    cv2.rectangle(img, (left, top), (right, bottom), (90, 90, 90), 1)
    _text(img, title, (left + pw // 2, y0 + 22), 0.6, thickness=1, anchor="centre")
    _text(img, xlabel, (left + pw // 2, bottom + 40), 0.5, anchor="centre")
    _vertical_text(img, ylabel, (x0 + 14, top + ph // 2))

    shift = 4
    for k, (ys, _) in enumerate(series):
        pts = np.rint(px(xs, ys) * (1 << shift)).astype(np.int32)
        cv2.polylines(img, [pts], False, _COLOURS[k % len(_COLOURS)], 2, cv2.LINE_AA, shift)

    # legend
    lines = [name for _, name in series]
    sizes = [cv2.getTextSize(s, _FONT, 0.45, 1)[0] for s in lines]
    lw = max(s[0] for s in sizes) + 44
    lh = 20 * len(lines) + 10
    lx = right - lw - 8 if legend_loc.endswith("right") else left + 8
    ly = bottom - lh - 8 if legend_loc.startswith("lower") else top + 8
    cv2.rectangle(img, (lx, ly), (lx + lw, ly + lh), (255, 255, 255), -1)
    cv2.rectangle(img, (lx, ly), (lx + lw, ly + lh), (160, 160, 160), 1)
    for k, name in enumerate(lines):
        yy = ly + 18 + 20 * k
        cv2.line(img, (lx + 8, yy - 5), (lx + 32, yy - 5), _COLOURS[k % len(_COLOURS)], 2, cv2.LINE_AA)
        _text(img, name, (lx + 38, yy), 0.45)


def draw_plots(items: Sequence[Curve], *, threshold: float = 20.0, title: str | None = None) -> np.ndarray:
    """The precision and success plots side by side, as a BGR image ``(H, W, 3)``.

    Curves are ordered in the legends by their score, best first, as in tracking papers.
    """
    if not items:
        raise DataError("nothing to plot: give at least one track")
    w, h = 1000, 440
    top = 30 if title else 0
    img = np.full((h + top, w, 3), 255, dtype=np.uint8)
    if title:
        _text(img, title, (w // 2, 24), 0.6, anchor="centre")
    by_p = sorted(items, key=lambda c: -c.precision_at)
    by_s = sorted(items, key=lambda c: -c.auc)
    _panel(img, (0, top, w // 2, h), PRECISION_THRESHOLDS,
           [(c.precision, f"{c.label} [{c.precision_at:.3f}]") for c in by_p],
           title=f"Precision plot (legend: precision at {threshold:g} px)", xlabel="location error threshold (px)",
           ylabel="precision", xticks=range(0, 51, 10), xfmt="d", legend_loc="lower right")
    _panel(img, (w // 2, top, w // 2, h), SUCCESS_CURVE_THRESHOLDS,
           [(c.success, f"{c.label} [{c.auc:.3f}]") for c in by_s],
           title="Success plot (legend: AUC)", xlabel="overlap threshold (IoU)", ylabel="success rate",
           xticks=np.linspace(0, 1, 6), xfmt=".1f", legend_loc="lower left")
    return img


def write_plots(path: str | Path, items: Sequence[Curve], *, threshold: float = 20.0,
                title: str | None = None) -> Path:
    """Draw :func:`draw_plots` and write it as a PNG, atomically."""
    import cv2

    path = Path(path)
    img = draw_plots(items, threshold=threshold, title=title)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise DataError(f"{path}: PNG encoding failed")
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
    return path


__all__ = ["Curve", "PRECISION_THRESHOLDS", "SUCCESS_CURVE_THRESHOLDS", "curves", "draw_plots", "track_labels",
           "write_plots"]
