"""Binary masks of an object: reading them, their outline, their overlap.

A mask is a 2-D image, non-zero on the object.  ``draw --mask`` reads one
(:func:`load_mask`), and ``draw --box`` makes one (:mod:`trackcli.segment.grabcut`); the
template is fitted to its outline (:func:`mask_outline`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trackcli.errors import DataError, InputError

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
