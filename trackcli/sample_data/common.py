"""Constants shared by the sample clips."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any




log = logging.getLogger(__name__)

DEFAULT_SEED = 1996
"""Seed of the committed ``sample_data/`` set."""

FPS = 25.0
"""Frame rate of every clip (frames per second)."""

FRAME_SIZE = (480, 360)
"""``(width, height)`` of every clip in pixels."""

N_OUTLINE_POINTS = 256
"""Number of vertices of each base outline."""

CLIP_NAMES: tuple[str, ...] = ("train", "test", "three_heads", "bouncing_ball")
"""The clips, in the order :func:`generate` writes them."""

TRUTH_COLUMNS: tuple[str, ...] = (
    "frame", "time", "object", "cx", "cy", "bbox_x", "bbox_y", "bbox_w", "bbox_h",
    "tx", "ty", "angle", "scale", "visible",
)  # fmt: skip
"""Columns of ``<clip>.truth.csv``, in order."""

_DEFAULT_FRAMES = {"train": 260, "test": 160, "three_heads": 110, "bouncing_ball": 125}
_CLIP_KEYS = {"train": 1, "test": 2, "three_heads": 3, "bouncing_ball": 4}
_OBJECT_KEY = 0  # stream for the look of the object shared by train and test

_SUPERSAMPLE = 8  # coverage of rendered polygons: 8×8 samples per pixel
_VIS_SUPERSAMPLE = 4  # visible fractions: 4×4 samples per pixel

_DECIMALS = {"time": 4, "cx": 4, "cy": 4, "bbox_x": 4, "bbox_y": 4, "bbox_w": 4, "bbox_h": 4,
             "tx": 4, "ty": 4, "angle": 6, "scale": 6, "visible": 4}  # fmt: skip

_COLUMN_TEXT = {
    "frame": "frame index, from 0",
    "time": "frame / fps, seconds",
    "object": "object index, from 0 (see clip.objects)",
    "cx": "x of the area centroid of the true outline, pixels",
    "cy": "y of the area centroid of the true outline, pixels",
    "bbox_x": "left of the tight box of the true outline (may be outside the image)",
    "bbox_y": "top of the tight box of the true outline (may be outside the image)",
    "bbox_w": "width of the tight box",
    "bbox_h": "height of the tight box",
    "tx": "translation x of the similarity, pixels",
    "ty": "translation y of the similarity, pixels",
    "angle": "rotation of the similarity, radians from +x towards +y (clockwise on screen)",
    "scale": "scale factor of the similarity",
    "visible": "fraction of the object's area inside the image and not occluded, 0..1",
}

Progress = Callable[[str, int, int], Any]
