"""Binary masks of an object: reading them, their outline, their overlap.

A mask is a 2-D image, non-zero on the object.  ``draw --mask`` reads one
(:func:`load_mask`) and takes the outline of the object it shows, its pieces joined into one
region (:func:`object_outline`); ``draw --box`` makes one (:mod:`trackcli.segment.grabcut`),
always in one piece, and takes the outline of its largest region (:func:`mask_outline`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trackcli.errors import DataError, InputError

log = logging.getLogger(__name__)

#: radii (px) of the closings tried, in turn, to fill the gap between two pieces of a mask
JOIN_RADII = (1, 2, 3, 4, 6, 8, 11, 16, 22, 32, 45, 64, 90, 128)
#: pieces left out of a mask's object are warned about from this share of its area on (specks
#: of annotation are said at -v only)
LEFT_OUT_WARNING = 0.01


def mask_outline(mask: np.ndarray) -> np.ndarray:
    """Outline ``(P, 2)`` of the largest region of a binary mask, as an ordered polygon."""
    import cv2

    m = (np.asarray(mask) > 0).astype(np.uint8)
    if m.ndim != 2:
        raise InputError(f"mask must be a 2-D image, got shape {m.shape}")
    contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise DataError("the mask contains no object (no non-zero pixels)")
    c = max(contours, key=cv2.contourArea)
    if cv2.contourArea(c) < 9:
        raise DataError("the mask's largest region is too small to outline (under 9 px)")
    return c[:, 0, :].astype(float)


def load_mask(path: str | Path, frame_size: tuple[int, int] | None = None) -> np.ndarray:
    """Read a binary mask image (non-zero = object); check its size against the frame."""
    import cv2

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such mask file")
    m = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise InputError(f"{p}: not an image OpenCV can read")
    if frame_size is not None and (m.shape[1], m.shape[0]) != tuple(frame_size):
        raise InputError(f"{p}: mask is {m.shape[1]}x{m.shape[0]} but the frame is {frame_size[0]}x{frame_size[1]}")
    return m


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two binary masks."""
    a, b = np.asarray(a) > 0, np.asarray(b) > 0
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 0.0


@dataclass
class Joined:
    """What :func:`join_pieces` made of a mask: the ``region`` (bool, the mask's shape), the
    areas (px) of the pieces ``joined`` to the largest and of those ``left_out``, and the
    largest closing radius (px) a gap between two joined pieces needed."""

    region: np.ndarray
    largest: int
    joined: list[int] = field(default_factory=list)
    left_out: list[int] = field(default_factory=list)
    radius: int = 0

    @property
    def left_out_share(self) -> float:
        """The share of the mask's area in the pieces left out."""
        return sum(self.left_out) / max(1, self.largest + sum(self.joined) + sum(self.left_out))

    def describe(self) -> str:
        """One sentence for the log, or "" for a mask in one piece."""
        if not self.joined and not self.left_out:
            return ""
        parts = [f"the mask is in {1 + len(self.joined) + len(self.left_out)} pieces"]
        if self.joined:
            parts.append(f"{len(self.joined)} joined to the largest by filling the gaps between them "
                         f"(closings of radius up to {self.radius} px)")
        if self.left_out:
            parts.append(f"{len(self.left_out)} ({100.0 * self.left_out_share:.2g} % of its area) left out: "
                         "filling the gap to them would take in more than they add")
        return "; ".join(parts)


def _gap_fill(region: np.ndarray, piece: np.ndarray, gap: float, limit: int) -> tuple[np.ndarray, int] | None:
    """The pixels that join ``piece`` to ``region`` (bool masks of one shape, ``gap`` px apart):
    of the pixels a closing of the two adds, those in parts touching both, for the first
    radius of :data:`JOIN_RADII` at which such a part exists, from half the gap (no smaller
    closing spans it) up to the gap; ``(fill, radius)``, or None when there is none or it
    would have more than ``limit`` pixels."""
    import cv2

    both = region | piece
    ys, xs = np.nonzero(both)
    ring = np.ones((3, 3), np.uint8)
    for r in (r for r in JOIN_RADII if gap / 2.0 - 1.0 <= r <= max(gap, 1.0)):
        # the closing only reaches r px beyond the two: work in their box grown by r + 1
        y0, y1 = max(0, ys.min() - r - 1), min(both.shape[0], ys.max() + r + 2)
        x0, x1 = max(0, xs.min() - r - 1), min(both.shape[1], xs.max() + r + 2)
        win = both[y0:y1, x0:x1].astype(np.uint8)
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        added = (cv2.morphologyEx(win, cv2.MORPH_CLOSE, disc) > 0) & (win == 0)
        if not added.any():
            continue
        n, labels = cv2.connectedComponents(added.astype(np.uint8), connectivity=8)
        near_region = cv2.dilate(region[y0:y1, x0:x1].astype(np.uint8), ring) > 0
        near_piece = cv2.dilate(piece[y0:y1, x0:x1].astype(np.uint8), ring) > 0
        bridging = np.intersect1d(labels[near_region & added], labels[near_piece & added])
        if bridging.size:
            fill = np.zeros_like(both)
            fill[y0:y1, x0:x1] = np.isin(labels, bridging)
            return (fill, r) if np.count_nonzero(fill) <= limit else None
    return None


def join_pieces(mask: np.ndarray) -> Joined:
    """The object a mask in several pieces shows, as one region.

    A user's mask is one object, but an occluder (a fence, a pole) can cut it into pieces,
    and annotation leaves specks.  Starting from the largest piece, each other piece (the
    larger first) is joined when the gap between it and the region can be filled with fewer
    pixels than the piece has: the fill is what a morphological closing of the two adds in
    the parts touching both, at the smallest radius of :data:`JOIN_RADII` that makes one.
    Other concavities of the outline are left as they are.  A piece whose gap costs more
    than it brings (a distant speck, the two pieces of a rope hanging apart) is left out: the
    region's overlap with the mask is higher without it.  Pieces are tried again after each
    join, since a joined piece can bring another within reach.  (A gap ``d`` px wide needs a
    closing of radius at least ``d / 2`` and a fill of at least ``d - 1`` pixels; radii up to
    ``d`` are tried.)
    """
    import cv2

    m = np.asarray(mask) > 0
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m.astype(np.uint8), connectivity=8)
    if n <= 2:
        return Joined(m, int(np.count_nonzero(m)))
    order = 1 + np.argsort(-stats[1:, cv2.CC_STAT_AREA], kind="stable")
    out = Joined(labels == order[0], int(stats[order[0], cv2.CC_STAT_AREA]))
    waiting = list(order[1:])
    joined_one = True
    while joined_one and waiting:
        joined_one = False
        # every pixel's distance to the region as it is now: each piece's gap
        away = cv2.distanceTransform((~out.region).astype(np.uint8), cv2.DIST_L2, 5)
        for k in waiting:
            piece = labels == k
            area = int(stats[k, cv2.CC_STAT_AREA])
            gap = float(away[piece].min())
            if gap - 1.0 > area:  # even a one-pixel path across the gap has more pixels
                continue
            joint = _gap_fill(out.region, piece, gap, area)
            if joint is not None:
                out.region |= piece | joint[0]
                out.joined.append(area)
                out.radius = max(out.radius, joint[1])
                waiting.remove(k)
                joined_one = True
                break  # the region grew: the gaps are measured again
    out.left_out = [int(stats[k, cv2.CC_STAT_AREA]) for k in waiting]
    return out


def object_outline(mask: np.ndarray) -> np.ndarray:
    """Outline ``(P, 2)`` of the object a binary mask shows, as an ordered polygon: its pieces
    joined into one region (:func:`join_pieces`, said in the log), holes filled."""
    m = np.asarray(mask)
    if m.ndim != 2:
        raise InputError(f"mask must be a 2-D image, got shape {m.shape}")
    joined = join_pieces(m)
    note = joined.describe()
    if note:  # a warning when a part of the object that counts is left out, not for specks
        (log.warning if joined.left_out_share >= LEFT_OUT_WARNING else log.info)("%s", note)
    return mask_outline(joined.region)
