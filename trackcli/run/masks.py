"""Masks: outlines filled to per-frame masks, and the DAVIS-2016 region and boundary scores.

Video-object-segmentation benchmarks exchange one mask per frame and compare methods by

- **J**, region similarity: the IoU of the predicted and true masks (1 when both are empty);
- **F**, boundary accuracy: the F-measure of the masks' boundary pixels, a boundary pixel
  counting as matched when a pixel of the other boundary lies within a disc of radius
  ``ceil(0.008 * image diagonal)`` px (Perazzi et al. 2016, DAVIS-2016).

A sequence's J and F are the means over its frames with the first and the last left out (the
first is given, the last is not annotated in every release); a data set's are the means over its
sequences.  The boundary of a mask is the set of pixels that differ from their right, lower or
lower-right neighbour (DAVIS's ``seg2bmap`` on masks of the image's own size).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from trackcli.errors import DataError, InputError

#: DAVIS's boundary tolerance, a fraction of the image diagonal.
BOUNDARY_TOLERANCE = 0.008

#: Sub-pixel bits for filling an outline (fillPoly's ``shift``).
_SHIFT = 4


def outline_mask(points, shape: tuple[int, int]) -> np.ndarray:
    """The closed outline ``points`` (P, 2) filled on an image of ``shape`` = (height, width).

    A pixel is inside when its centre is (pixel ``(i, j)`` has its centre at ``x = j, y = i``,
    the convention of the outline columns).  NaN or fewer than three points give an empty mask.
    """
    import cv2

    h, w = int(shape[0]), int(shape[1])
    m = np.zeros((h, w), dtype=np.uint8)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(p) < 3 or not np.all(np.isfinite(p)):
        return m.astype(bool)
    lim = 4.0 * max(h, w) + 16.0            # keep fillPoly's fixed-point coordinates in range
    pts = np.rint(np.clip(p, -lim, lim) * (1 << _SHIFT)).astype(np.int32)
    cv2.fillPoly(m, [pts], 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return m.astype(bool)


def boundary_map(mask: np.ndarray) -> np.ndarray:
    """Boundary pixels of a binary mask: those that differ from the right, lower or lower-right one."""
    m = np.asarray(mask, dtype=bool)
    e = np.zeros_like(m)
    s = np.zeros_like(m)
    se = np.zeros_like(m)
    e[:, :-1] = m[:, 1:]
    s[:-1, :] = m[1:, :]
    se[:-1, :-1] = m[1:, 1:]
    b = (m ^ e) | (m ^ s) | (m ^ se)
    b[-1, :] = m[-1, :] ^ e[-1, :]
    b[:, -1] = m[:, -1] ^ s[:, -1]
    b[-1, -1] = False
    return b


def _disc(radius: int) -> np.ndarray:
    r = int(radius)
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    return (x * x + y * y <= r * r).astype(np.uint8)


def boundary_tolerance(shape: tuple[int, int], fraction: float = BOUNDARY_TOLERANCE) -> int:
    """The boundary tolerance in pixels for an image of ``shape``: ceil(fraction x diagonal)."""
    return int(math.ceil(fraction * math.hypot(shape[0], shape[1])))


def region_similarity(pred: np.ndarray, truth: np.ndarray) -> float:
    """J: IoU of two binary masks of one size; 1 when both are empty."""
    p, t = np.asarray(pred, dtype=bool), np.asarray(truth, dtype=bool)
    if p.shape != t.shape:
        raise DataError(f"masks of different sizes: {p.shape[1]}x{p.shape[0]} and {t.shape[1]}x{t.shape[0]}")
    union = np.count_nonzero(p | t)
    return 1.0 if union == 0 else float(np.count_nonzero(p & t) / union)


def boundary_f(pred: np.ndarray, truth: np.ndarray, *, fraction: float = BOUNDARY_TOLERANCE) -> float:
    """F: the boundary F-measure of two binary masks of one size (DAVIS-2016)."""
    import cv2

    p, t = np.asarray(pred, dtype=bool), np.asarray(truth, dtype=bool)
    if p.shape != t.shape:
        raise DataError(f"masks of different sizes: {p.shape[1]}x{p.shape[0]} and {t.shape[1]}x{t.shape[0]}")
    bp, bt = boundary_map(p), boundary_map(t)
    n_p, n_t = int(np.count_nonzero(bp)), int(np.count_nonzero(bt))
    if n_p == 0 and n_t == 0:
        return 1.0
    if n_p == 0 or n_t == 0:
        return 0.0
    disc = _disc(boundary_tolerance(p.shape, fraction))
    near_p = cv2.dilate(bp.astype(np.uint8), disc).astype(bool)
    near_t = cv2.dilate(bt.astype(np.uint8), disc).astype(bool)
    precision = np.count_nonzero(bp & near_t) / n_p
    recall = np.count_nonzero(bt & near_p) / n_t
    return 0.0 if precision + recall == 0 else float(2 * precision * recall / (precision + recall))


@dataclass(frozen=True)
class SequenceScores:
    """Per-frame J and F of one sequence, and the DAVIS means (first and last frame left out)."""

    frames: np.ndarray      # frame indices scored, (T,)
    J: np.ndarray           # (T,)
    F: np.ndarray           # (T,)

    @property
    def counted(self) -> np.ndarray:
        """Which frames enter the means: all but the first and the last (all when fewer than 3)."""
        c = np.ones(len(self.frames), dtype=bool)
        if len(c) >= 3:
            c[0] = c[-1] = False
        return c

    @property
    def J_mean(self) -> float:
        return float(np.mean(self.J[self.counted])) if len(self.J) else math.nan

    @property
    def F_mean(self) -> float:
        return float(np.mean(self.F[self.counted])) if len(self.F) else math.nan

    @property
    def JF_mean(self) -> float:
        return 0.5 * (self.J_mean + self.F_mean)


def score_masks(pred: Sequence[np.ndarray], truth: Sequence[np.ndarray], frames: Sequence[int] | None = None,
                *, fraction: float = BOUNDARY_TOLERANCE) -> SequenceScores:
    """J and F of each pair of masks, in order (frames ``0..T-1`` unless given)."""
    if len(pred) != len(truth):
        raise DataError(f"{len(pred)} predicted masks for {len(truth)} true ones")
    J = np.array([region_similarity(p, t) for p, t in zip(pred, truth)], dtype=float)
    F = np.array([boundary_f(p, t, fraction=fraction) for p, t in zip(pred, truth)], dtype=float)
    fr = np.arange(len(J)) if frames is None else np.asarray(frames, dtype=int)
    return SequenceScores(frames=fr, J=J, F=F)


def read_mask(path: str | Path) -> np.ndarray:
    """A mask image as a boolean array (non-zero = object; a palette PNG by its indices)."""
    import cv2

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such mask file")
    m = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if m is None:
        raise InputError(f"{p}: not an image")
    if m.ndim == 3:
        m = m[..., :3].max(axis=2)
    return m > 0


MASK_SUFFIXES = (".png", ".bmp", ".tif", ".tiff", ".jpg", ".jpeg")


def mask_files(folder: str | Path) -> list[Path]:
    """The mask images of a folder, in sorted order (the i-th belongs to the i-th frame)."""
    d = Path(folder)
    if not d.is_dir():
        raise InputError(f"{d}: not a folder of masks")
    files = sorted(f for f in d.iterdir() if f.suffix.lower() in MASK_SUFFIXES and f.is_file())
    if not files:
        raise InputError(f"{d}: no mask images (.png, ...)")
    return files


#: The palette of DAVIS annotations: index 0 background (black), index 1 the object (dark red).
DAVIS_PALETTE = ((0, 0, 0), (128, 0, 0))


def encode_mask_png(mask: np.ndarray, *, palette: bool = False) -> bytes:
    """A binary mask (H, W) as PNG bytes: grey 0/255, or with ``palette`` an 8-bit palette image
    with the object at index 1, as the DAVIS annotations are (colours :data:`DAVIS_PALETTE`).

    Both read back with :func:`read_mask` (and with any image library) as the same mask.
    """
    import zlib

    m = np.asarray(mask, dtype=bool)
    if m.ndim != 2 or m.size == 0:
        raise DataError(f"a mask must be a non-empty 2-D array, got shape {m.shape}")
    if not palette:
        import cv2

        ok, buf = cv2.imencode(".png", m.astype(np.uint8) * 255)
        if not ok:
            raise DataError("PNG encoding of a mask failed")
        return buf.tobytes()
    # OpenCV writes no palette images: the PNG chunks by hand (IHDR, PLTE, IDAT, IEND)
    h, w = m.shape

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (len(data).to_bytes(4, "big") + kind + data
                + (zlib.crc32(kind + data) & 0xFFFFFFFF).to_bytes(4, "big"))

    rows = np.zeros((h, w + 1), dtype=np.uint8)  # filter byte 0 (none) before each row
    rows[:, 1:] = m
    header = w.to_bytes(4, "big") + h.to_bytes(4, "big") + bytes([8, 3, 0, 0, 0])  # 8-bit, palette
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"PLTE", bytes(v for rgb in DAVIS_PALETTE for v in rgb))
            + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6)) + chunk(b"IEND", b""))
