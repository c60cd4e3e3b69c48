"""The bouncing-ball experiment (Blake et al. 1998 §8, Fig 16): scores and figure.

A single AR(2) model of free flight overshoots at every bounce; a mixed-state model with a
bounce event follows it, and its label posterior marks the bounces.  This module measures
both on a clip with ground truth:

- the true bounces are the frames where the ball is lowest (a local maximum of the true
  centroid's ``y``, image ``y`` down, followed by a rise);
- the centre error of each track over the frames within ``radius`` of a bounce;
- the bounces the label posterior detected: its local peaks above ``threshold``, matched to
  true bounces within ``tolerance`` frames (one detection per bounce; the rest are false);

and draws the figure: the vertical position over time (truth and both tracks) above the
posterior of the bounce label.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from trackcli.errors import DataError
from trackcli.io.outputs import atomic_path


def true_bounces(cy: np.ndarray, min_drop: float = 1.0) -> np.ndarray:
    """Frames where the true ``cy`` has a local maximum (lowest point) followed by a rise of
    at least ``min_drop`` px over the next two frames (a ball resting on the floor is not a bounce)."""
    y = np.asarray(cy, dtype=float)
    out = []
    for k in range(1, len(y) - 1):
        if y[k] >= y[k - 1] and y[k] > y[k + 1] and y[k] - y[min(k + 2, len(y) - 1)] >= min_drop:
            out.append(k)
    return np.asarray(out, dtype=np.int64)


def detections(p: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    """Frames where ``p`` has a local peak at or above ``threshold`` (a plateau counts once, at its start)."""
    p = np.nan_to_num(np.asarray(p, dtype=float), nan=0.0)
    out = []
    for k in range(len(p)):
        left = p[k - 1] if k > 0 else -np.inf
        right = p[k + 1] if k + 1 < len(p) else -np.inf
        if p[k] >= threshold and p[k] > left and p[k] >= right:
            out.append(k)
    return np.asarray(out, dtype=np.int64)


def match(truth: Sequence[int], found: Sequence[int], tolerance: int = 1) -> tuple[int, int, list[int]]:
    """``(hits, false, offsets)``: true bounces with a detection within ``tolerance`` frames
    (each detection used once, nearest first), detections left over, and each hit's offset."""
    free = sorted(int(f) for f in found)
    hits, offsets = 0, []
    for t in truth:
        near = [f for f in free if abs(f - int(t)) <= tolerance]
        if near:
            best = min(near, key=lambda f: abs(f - int(t)))
            free.remove(best)
            hits += 1
            offsets.append(best - int(t))
    return hits, len(free), offsets


def around(frames: Sequence[int], n: int, radius: int) -> np.ndarray:
    """Boolean mask of the ``n`` frames within ``radius`` of any of ``frames``."""
    mask = np.zeros(n, dtype=bool)
    for f in frames:
        mask[max(int(f) - radius, 0): min(int(f) + radius + 1, n)] = True
    return mask


@dataclass(frozen=True)
class BounceScores:
    """Scores of one track over the frames around the true bounces."""

    mean_error: float
    max_error: float
    frames: int

    def line(self, name: str) -> str:
        return f"{name:8s} centre error over {self.frames} frames around bounces: mean {self.mean_error:.2f} px, " \
               f"max {self.max_error:.2f} px"


def score_around(error: np.ndarray, mask: np.ndarray) -> BounceScores:
    """Mean and max of ``error`` over ``mask`` (a missing estimate, NaN, counts as infinite)."""
    e = np.asarray(error, dtype=float)[mask]
    if e.size == 0:
        raise DataError("no frames around a bounce to score")
    e = np.where(np.isfinite(e), e, np.inf)
    return BounceScores(float(e.mean()), float(e.max()), int(e.size))


def figure(png: str | Path, frames: np.ndarray, truth_y: np.ndarray | None, tracks: dict[str, np.ndarray],
           p_bounce: np.ndarray, bounces: Sequence[int] = (), *, width: int = 960, title: str = "") -> Path:
    """PNG: the vertical position over time (truth grey, each track a colour) above the bounce
    label's posterior (bars), true bounces as vertical lines.  ``y`` is drawn down, as in the image."""
    import cv2

    f = np.asarray(frames, dtype=float)
    if f.size < 2:
        raise DataError("the figure needs at least two frames")
    H1, H2, left, right, top, gap, bottom = 300, 120, 60, 20, 34, 30, 36
    height = top + H1 + gap + H2 + bottom
    img = np.full((height, width, 3), 255, np.uint8)
    x0, x1 = left, width - right
    fx = lambda v: x0 + (np.asarray(v, float) - f[0]) / (f[-1] - f[0]) * (x1 - x0)  # noqa: E731
    ys = [np.asarray(v, float) for v in tracks.values()] + ([np.asarray(truth_y, float)] if truth_y is not None else [])
    allv = np.concatenate([v[np.isfinite(v)] for v in ys])
    lo, hi = float(allv.min()), float(allv.max())
    pad = 0.05 * max(hi - lo, 1.0)
    lo, hi = lo - pad, hi + pad
    fy = lambda v: top + (np.asarray(v, float) - lo) / (hi - lo) * H1  # noqa: E731  (y down, as in the image)
    p_top = top + H1 + gap
    fp = lambda v: p_top + H2 - np.clip(np.asarray(v, float), 0, 1) * H2  # noqa: E731
    font, black, grey = cv2.FONT_HERSHEY_SIMPLEX, (0, 0, 0), (170, 170, 170)
    for b in bounces:
        x = int(round(float(fx(b))))
        for y in range(top, p_top + H2, 8):
            cv2.line(img, (x, y), (x, min(y + 4, p_top + H2)), (200, 200, 255), 1)
    cv2.rectangle(img, (x0, top), (x1, top + H1), black, 1)
    cv2.rectangle(img, (x0, p_top), (x1, p_top + H2), black, 1)

    def curve(v: np.ndarray, colour: tuple[int, int, int], thick: int) -> None:
        ok = np.isfinite(v)
        pts = np.column_stack([fx(f), fy(v)])
        start = 0
        for k in range(len(v) + 1):
            if k == len(v) or not ok[k]:
                seg = pts[start:k]
                if len(seg) > 1:
                    cv2.polylines(img, [np.round(seg * 4).astype(np.int32).reshape(-1, 1, 2)], False, colour, thick,
                                  cv2.LINE_AA, shift=2)
                start = k + 1

    colours = [(40, 40, 220), (200, 110, 0), (0, 150, 0)]
    if truth_y is not None:
        curve(np.asarray(truth_y, float), grey, 5)
    for (name, v), col in zip(tracks.items(), colours):
        curve(np.clip(np.asarray(v, float), lo, hi), col, 2)
    p = np.nan_to_num(np.asarray(p_bounce, float), nan=0.0)
    bar = max(int((x1 - x0) / len(f)) - 1, 1)
    for k, v in enumerate(p):
        x = int(round(float(fx(f[k]))))
        cv2.rectangle(img, (x - bar // 2, int(fp(v))), (x + bar // 2, p_top + H2), (200, 110, 0), -1)
    cv2.line(img, (x0, int(fp(0.5))), (x1, int(fp(0.5))), grey, 1)
    # labels
    cv2.putText(img, title or "centroid y (px, down)", (x0, 22), font, 0.55,
                black, 1, cv2.LINE_AA)
    cv2.putText(img, f"{hi:.0f}", (5, top + H1), font, 0.45, black, 1, cv2.LINE_AA)
    cv2.putText(img, f"{lo:.0f}", (5, top + 12), font, 0.45, black, 1, cv2.LINE_AA)
    cv2.putText(img, "P(bounce)", (5, p_top - 8), font, 0.45, black, 1, cv2.LINE_AA)
    cv2.putText(img, "1", (x0 - 14, p_top + 10), font, 0.45, black, 1, cv2.LINE_AA)
    cv2.putText(img, "0", (x0 - 14, p_top + H2), font, 0.45, black, 1, cv2.LINE_AA)
    for t in np.linspace(f[0], f[-1], 6):
        x = int(round(float(fx(t))))
        cv2.putText(img, f"{t:.0f}", (x - 10, p_top + H2 + 18), font, 0.45, black, 1, cv2.LINE_AA)
    cv2.putText(img, "frame", (x1 - 50, height - 4), font, 0.45, black, 1, cv2.LINE_AA)
    legend = ([("truth", grey)] if truth_y is not None else []) + [(n, c) for n, c in zip(tracks, colours)]
    lx = x1 - 10 - 140 * len(legend)
    for name, col in legend:
        cv2.line(img, (lx, 16), (lx + 24, 16), col, 3, cv2.LINE_AA)
        cv2.putText(img, name, (lx + 30, 21), font, 0.5, black, 1, cv2.LINE_AA)
        lx += 140
    ok, buf = cv2.imencode(".png", img)
    path = Path(png)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
    return path


@dataclass(frozen=True)
class Experiment:
    """The bouncing-ball experiment on one clip: both tracks scored against the truth."""

    bounces: np.ndarray
    single: BounceScores
    mixed: BounceScores
    detected: np.ndarray
    hits: int
    false: int
    offsets: list[int]

    def lines(self) -> list[str]:
        return [f"true bounces at frames {', '.join(map(str, self.bounces))}",
                self.single.line("single"), self.mixed.line("mixed"),
                f"bounce label posterior > 0.5 peaks at frames {', '.join(map(str, self.detected)) or 'none'}: "
                f"{self.hits} of {len(self.bounces)} bounces detected within 1 frame "
                f"(offsets {self.offsets}), {self.false} false"]


def run_experiment(single_csv: str | Path, mixed_csv: str | Path, truth_path: str | Path, *,
                   label: str = "bounce", radius: int = 3, png: str | Path | None = None) -> Experiment:
    """Score the single-model and the mixed-state track of one clip against its truth
    (centre error within ``radius`` frames of each true bounce; detections of the ``label``
    posterior), and draw :func:`figure` into ``png`` when given."""
    from trackcli.io.tracks import read_columns
    from trackcli.io.truth import load_truth

    truth = load_truth(truth_path)
    s = read_columns(single_csv, ["frame", "cx", "cy"])
    m = read_columns(mixed_csv, ["frame", "cx", "cy", f"p_{label}"])
    frames = m["frame"].astype(np.int64)
    if not np.array_equal(frames, s["frame"].astype(np.int64)):
        raise DataError(f"{single_csv} and {mixed_csv} cover different frames")
    pos = {int(f): i for i, f in enumerate(truth.frame)}
    idx = np.array([pos.get(int(f), -1) for f in frames])
    if (idx < 0).any():
        raise DataError(f"{truth_path}: no truth for frame(s) {frames[idx < 0][:5].tolist()}")
    true_c = truth.centre[idx]
    bounces_at = true_bounces(true_c[:, 1])
    mask = around(bounces_at, len(frames), radius)
    err = {name: np.hypot(t["cx"] - true_c[:, 0], t["cy"] - true_c[:, 1]) for name, t in (("single", s), ("mixed", m))}
    found = detections(m[f"p_{label}"])
    hits, false, offsets = match(bounces_at, found)
    if png is not None:
        figure(png, frames, true_c[:, 1], {"single model": s["cy"], "mixed state": m["cy"]}, m[f"p_{label}"],
               frames[bounces_at])
    return Experiment(frames[bounces_at], score_around(err["single"], mask), score_around(err["mixed"], mask),
                      frames[found], hits, false, offsets)
