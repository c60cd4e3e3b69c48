"""DAVIS scores of a folder of masks, or of a track CSV's outlines, against a folder of true masks.

What ``trackcli eval PRED TRUTH`` does when TRUTH is a folder of mask images (DAVIS layout:
``SEQ/masks/00000.png`` ..., the i-th image in sorted order being frame i).  The measures are
those of DAVIS-2016 (Perazzi et al. 2016), computed by :mod:`trackcli.run.masks`:

- **J**, region similarity: the IoU of the predicted and the true mask;
- **F**, boundary accuracy: the F-measure of their boundary pixels, matched within
  ``ceil(0.008 x image diagonal)`` px.

Per sequence, for J and for F: the **mean** over the frames, the **recall** (the fraction of
frames scoring above 0.5) and the **decay** (the mean over the first quarter of the frames less
the mean over the last quarter: what is lost over time), with the first and the last frame left
out (the first is given; the last is not annotated in every release); ``J&F`` is the mean of
the two means.

The prediction is either a folder of masks (as ``trackcli track --masks`` writes them, or any
method's) or a track CSV, whose outline columns are filled on the true masks' frame size
(:func:`trackcli.run.masks.outline_mask`).  Masks of a folder are matched to the true ones by
file name when the names match, else in sorted order; a track's rows by frame index.

Inputs that do not belong together are refused or warned about in one line (see
:mod:`trackcli.run.checks`): masks of another size, a track with frames past the truth's last
or estimates that do not fit its frames, different frame counts (only the frames in both are
scored), and a prediction that meets the truth on no frame.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from trackcli.errors import DataError
from trackcli.run.masks import SequenceScores, boundary_f, mask_files, outline_mask, read_mask, region_similarity

#: Frames are split into this many parts in time for the decay (DAVIS: quarters).
DECAY_BINS = 4
#: A frame counts towards the recall when its score exceeds this.
RECALL_THRESHOLD = 0.5


def is_mask_folder(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a folder of mask PNGs: not a benchmark folder with a box file, and its
    first PNG has a few values (0 and 255, or a palette's indices), not a frame's hundreds."""
    p = Path(path)
    if not p.is_dir() or (p / "groundtruth_rect.txt").is_file() or (p / "groundtruth.txt").is_file():
        return False
    first = next((f for f in sorted(p.iterdir()) if f.suffix.lower() == ".png" and not f.name.startswith(".")), None)
    if first is None:
        return False
    import cv2

    img = cv2.imread(str(first), cv2.IMREAD_UNCHANGED)  # masks have a few values, frames hundreds
    return img is not None and len(np.unique(img.reshape(-1, img.shape[2] if img.ndim == 3 else 1), axis=0)) <= 16


def statistics(values: np.ndarray) -> tuple[float, float, float]:
    """DAVIS's ``(mean, recall, decay)`` of per-frame scores (the frames that count, in order)."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return math.nan, math.nan, math.nan
    ids = (np.round(np.linspace(1, v.size, DECAY_BINS + 1) + 1e-10) - 1).astype(int)
    bins = [v[ids[i]:ids[i + 1] + 1] for i in range(DECAY_BINS)]
    return float(v.mean()), float(np.mean(v > RECALL_THRESHOLD)), float(bins[0].mean() - bins[-1].mean())


@dataclass(frozen=True)
class MaskScores:
    """The DAVIS scores of one prediction against one folder of true masks.

    Attributes
    ----------
    pred, truth : str
        What was scored, and against what.
    scores : SequenceScores
        Per-frame J and F of the frames in both (their frame indices in ``scores.frames``).
    truth_frames, pred_frames : int
        How many frames each side has.
    notes : list of str
        Warnings about inputs that do not quite belong together.
    """

    pred: str
    truth: str
    scores: SequenceScores
    truth_frames: int
    pred_frames: int
    notes: tuple[str, ...] = ()

    def summary(self) -> dict[str, float | int]:
        s = self.scores
        jm, jr, jd = statistics(s.J[s.counted])
        fm, fr, fd = statistics(s.F[s.counted])
        return {"frames_scored": int(len(s.frames)), "frames_counted": int(np.count_nonzero(s.counted)),
                "J_mean": jm, "J_recall": jr, "J_decay": jd, "F_mean": fm, "F_recall": fr, "F_decay": fd,
                "JF_mean": 0.5 * (jm + fm)}

    def to_dict(self, *, per_frame: bool = True) -> dict:
        """JSON-able: the summary, and with ``per_frame`` the frames with their J and F (NaN as None)."""
        def plain(v):
            return v if not isinstance(v, float) or math.isfinite(v) else None

        d: dict = {"kind": "eval", "metric": "davis", "pred": self.pred, "truth": self.truth,
                   "truth_frames": self.truth_frames, "pred_frames": self.pred_frames,
                   **{k: plain(v) for k, v in self.summary().items()}}
        if per_frame:
            d["frames"] = [int(f) for f in self.scores.frames]
            d["J"] = [round(float(v), 6) for v in self.scores.J]
            d["F"] = [round(float(v), 6) for v in self.scores.F]
            d["counted"] = [bool(c) for c in self.scores.counted]
        d["warnings"] = list(self.notes)
        return d


def evaluate_masks(pred: str | os.PathLike[str], truth: str | os.PathLike[str], *,
                   progress: Callable[[int], None] | None = None) -> MaskScores:
    """Score ``pred`` (a folder of masks or a track CSV) against the folder of true masks ``truth``.

    Raises
    ------
    InputError
        A folder holds no masks, a mask or the CSV cannot be read.
    DataError
        Masks of different sizes; a track with frames past the truth's last; no frame in both.
    """
    from trackcli.run.checks import check_sizes, check_track_on_clip

    truth_files = mask_files(truth)
    first = read_mask(truth_files[0])
    shape = first.shape
    notes: list[str] = []
    p = Path(pred)
    if p.is_dir():
        pred_files = mask_files(p)
        check_sizes(read_mask(pred_files[0]).shape[::-1], shape[::-1], what_a=f"{p}/{pred_files[0].name}",
                    what_b=f"the truth {truth_files[0]}")
        names = {f.stem: k for k, f in enumerate(truth_files)}
        if all(f.stem in names for f in pred_files):
            pairs = [(names[f.stem], f) for f in pred_files]
        else:
            pairs = list(enumerate(pred_files[:len(truth_files)]))
            if len(pred_files) != len(truth_files):
                notes.append(f"{p} holds {len(pred_files)} masks named unlike the {len(truth_files)} of {truth}: "
                             f"matched in order, the first {len(pairs)}")

        def predicted(k: int, f: Path) -> np.ndarray:
            m = read_mask(f)
            if m.shape != shape:
                check_sizes(m.shape[::-1], shape[::-1], what_a=str(f), what_b=f"the truth {truth_files[k]}")
            return m
        n_pred = len(pred_files)
    else:
        from trackcli.io.tracks import read_outlines

        frames, outlines, _ = read_outlines(p)
        notes += check_track_on_clip(frames, outlines, width=shape[1], height=shape[0], n_frames=len(truth_files),
                                     track=str(p), clip=f"the truth {truth}")
        pairs = [(int(f), k) for k, f in enumerate(frames)]

        def predicted(k: int, row: int) -> np.ndarray:
            return outline_mask(outlines[row], shape)
        n_pred = len(frames)
    if not pairs:
        raise DataError(f"no frame of {pred} has a true mask in {truth}")
    if len(pairs) != len(truth_files):
        scored = [k for k, _ in pairs]
        notes.append(f"{pred} covers {n_pred} frames and {truth} {len(truth_files)}: scored the {len(pairs)} in both "
                     f"(frames {min(scored)}-{max(scored)})")
    J, F, idx = [], [], []
    for k, src in sorted(pairs, key=lambda kv: kv[0]):
        t = first if k == 0 else read_mask(truth_files[k])
        if t.shape != shape:
            check_sizes(t.shape[::-1], shape[::-1], what_a=str(truth_files[k]), what_b=str(truth_files[0]))
        m = predicted(k, src)
        J.append(region_similarity(m, t))
        F.append(boundary_f(m, t))
        idx.append(k)
        if progress is not None:
            progress(1)
    scores = SequenceScores(frames=np.asarray(idx), J=np.asarray(J), F=np.asarray(F))
    if len(J) > 1 and max(J) == 0.0:
        notes.append(f"no mask of {pred} meets the true object on any frame: is the truth of another clip?")
    return MaskScores(str(pred), str(truth), scores, len(truth_files), n_pred, tuple(notes))


def score_predictions(preds: list[str], truth: str, *, plot: str | None = None
                      ) -> Iterator[tuple[str | None, MaskScores]]:
    """``eval`` against a folder of true masks: each of ``preds`` (mask folders or track CSVs)
    scored in turn, with its label for tables and the plot (when there are several or a
    ``plot``, which must not replace an input)."""
    labels: list[str | None] = [None] * len(preds)
    if plot:
        from trackcli.io.outputs import refuse_overwriting_inputs

        refuse_overwriting_inputs({"--plot": plot}, {"TRUTH": truth, **{f"PRED {k + 1}": t for k, t in enumerate(preds)}})
    if plot or len(preds) > 1:
        from trackcli.run.plots import track_labels

        labels = list(track_labels(preds))
    for label, pred in zip(labels, preds):
        yield label, evaluate_masks(pred, truth)


def format_mask_table(result: MaskScores) -> str:
    """A human-readable table of :class:`MaskScores` (one measure per line)."""
    s = result.summary()
    fr = result.scores.frames

    def num(v: float) -> str:
        return f"{v:.3f}" if math.isfinite(v) else "n/a"

    rows = [
        ("frames scored", f"{s['frames_scored']}  (frames {int(fr[0])}-{int(fr[-1])}; {s['frames_counted']} counted, "
                          "the first and last left out)"),
        ("J (region IoU)", f"mean {num(s['J_mean'])}  recall {num(s['J_recall'])}  decay {num(s['J_decay'])}"),
        ("F (boundary)", f"mean {num(s['F_mean'])}  recall {num(s['F_recall'])}  decay {num(s['F_decay'])}"),
        ("J&F", num(s["JF_mean"])),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def draw_mask_plot(items: list[tuple[str, MaskScores]]) -> np.ndarray:
    """J and F per frame, side by side, one curve per labelled result (legend: label [mean]), as a BGR image."""
    import cv2

    from trackcli.run.plots import _COLOURS, _text, _vertical_text

    if not items:
        raise DataError("nothing to plot: give at least one prediction")
    last = max(int(r.scores.frames.max()) for _, r in items)
    w, h = 1000, 440
    img = np.full((h, w, 3), 255, dtype=np.uint8)
    for panel, key in enumerate(("J", "F")):
        x0 = panel * w // 2
        left, right, top, bottom = x0 + 62, x0 + w // 2 - 14, 34, h - 48
        pw, ph = right - left, bottom - top
        span = max(last, 1)
        for t in np.linspace(0.0, 1.0, 6):
            yy = int(round(bottom - t * ph))
            cv2.line(img, (left, yy), (right, yy), (225, 225, 225), 1)
            _text(img, f"{t:.1f}", (left - 8, yy + 5), 0.45, anchor="right")
        for t in np.unique(np.round(np.linspace(0, span, 6))):
            xx = int(round(left + t / span * pw))
            cv2.line(img, (xx, top), (xx, bottom), (225, 225, 225), 1)
            _text(img, f"{int(t)}", (xx, bottom + 18), 0.45, anchor="centre")
        cv2.rectangle(img, (left, top), (right, bottom), (90, 90, 90), 1)
        title = "J: region similarity (mask IoU)" if key == "J" else "F: boundary accuracy"
        _text(img, title + " per frame", (left + pw // 2, 22), 0.6, anchor="centre")
        _text(img, "frame", (left + pw // 2, bottom + 40), 0.5, anchor="centre")
        _vertical_text(img, key, (x0 + 14, top + ph // 2))
        legend = []
        for k, (label, r) in enumerate(items):
            colour = _COLOURS[k % len(_COLOURS)]
            f, v = r.scores.frames.astype(float), getattr(r.scores, key)
            pts = np.column_stack([left + f / span * pw, bottom - np.clip(v, 0, 1) * ph])
            # a gap in the frames is a gap in the curve
            for seg in np.split(pts, np.flatnonzero(np.diff(f) > 1) + 1):
                q = np.rint(seg * 16).astype(np.int32)
                if len(q) > 1:
                    cv2.polylines(img, [q], False, colour, 2, cv2.LINE_AA, 4)
                else:
                    cv2.circle(img, tuple(np.rint(seg[0]).astype(int)), 2, colour, -1)
            legend.append((f"{label} [{r.summary()[key + '_mean']:.3f}]", colour))
        lw = max(cv2.getTextSize(t, 0, 0.45, 1)[0][0] for t, _ in legend) + 44
        lx, ly = right - lw - 8, bottom - 20 * len(legend) - 18
        cv2.rectangle(img, (lx, ly), (lx + lw, ly + 20 * len(legend) + 10), (255, 255, 255), -1)
        cv2.rectangle(img, (lx, ly), (lx + lw, ly + 20 * len(legend) + 10), (160, 160, 160), 1)
        for k, (t, colour) in enumerate(legend):
            yy = ly + 18 + 20 * k
            cv2.line(img, (lx + 8, yy - 5), (lx + 32, yy - 5), colour, 2, cv2.LINE_AA)
            _text(img, t, (lx + 38, yy), 0.45)
    return img


def write_mask_plot(path: str | os.PathLike[str], items: list[tuple[str, MaskScores]]) -> Path:
    """:func:`draw_mask_plot` written as a PNG, atomically."""
    import cv2

    from trackcli.io.outputs import atomic_path

    path = Path(path)
    ok, buf = cv2.imencode(".png", draw_mask_plot(items))
    if not ok:
        raise DataError(f"{path}: PNG encoding failed")
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())
    return path


__all__ = ["MaskScores", "draw_mask_plot", "evaluate_masks", "format_mask_table", "is_mask_folder", "score_predictions",
           "statistics", "write_mask_plot"]
