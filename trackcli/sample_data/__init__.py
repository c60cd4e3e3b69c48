"""Synthetic clips with exact ground truth, for the demo and for tests that pin accuracy.

Four clips, each 480×360 at 25 fps, are rendered from a seed:

``train``
    One head-and-shoulders silhouette moving gently over a clean background (smooth
    gradient, light fixed-pattern noise).  Each pose parameter ``tx, ty, angle, scale`` is an
    independent second-order auto-regressive process -- a damped oscillator driven by white
    noise, AC eqs 9.24–9.25 -- rescaled to a few pixels per frame, ±8° and ±8 %, so AR(2)
    dynamics learned from the clip have a known answer (recorded in the outline file).
``test``
    The same object moving agilely (velocity switching every few frames, sudden reversals,
    peak speeds of 12–15 px/frame) over heavy clutter: lines at many angles, text-like
    strokes, texture and static look-alike silhouettes, some only partly drawn (none where
    the object stands in the first frame, on which a template is drawn); a pole passes in
    front of the object for about ten frames.
``three_heads``
    Three similar heads (paper 000 §5.1), of nearly the same size (scales 0.95, 0.97, 1):
    two stand roughly still, the third walks from the right to the left in front of them
    (drawn on top).  The person on the left stands against a plain wall, the one in the
    middle in front of a door frame; a picture and book shelves hang above head height on
    the right, so that the three outlines are about equally visible when apart.
``bouncing_ball``
    A ball in parabolic flight over a floor, losing energy at each bounce, where its
    vertical velocity reverses within one frame (paper 001 §8).

Ground truth
------------
Every clip has a *base outline*: a dense closed polygon ``(P, 2)`` in object coordinates,
centred on its area centroid, ordered counter-clockwise as seen on the screen (``y``
down), so its shoelace signed area in ``(x, y)`` is negative.  In frame ``k`` object ``j``
is exactly the region bounded by the base outline mapped by the similarity

    ``p_image = scale · R(angle) · p + (tx, ty)``,  ``R(a) = [[cos a, −sin a], [sin a, cos a]]``,

with ``angle`` in radians from ``+x`` towards ``+y`` (clockwise on the screen), as in
:mod:`trackcli.shapes.shape_space`.  Frames are rendered from that polygon with 8×8 supersampled
coverage, so the rendered edge lies within a few hundredths of a pixel of the truth.

``<clip>.truth.csv`` has one row per frame and object:

=========================  =================================================================
``frame``                  frame index, from 0
``time``                   ``frame / fps`` in seconds
``object``                 object index, from 0 (see the outline file for which is which)
``cx, cy``                 area centroid of the true outline (pixels)
``bbox_x … bbox_h``        tight box ``(x, y, w, h)`` of the true outline; it may extend
                           outside the image
``tx, ty, angle, scale``   the similarity above
``visible``                fraction of the object's area that is inside the image and not
                           hidden by anything drawn in front of it (0 to 1)
=========================  =================================================================

``<clip>.outline.json`` holds the base outline (``points``), ``format: 1``, the clip's frame
rate, size, frame count and seed, which object is which, and the parameters of the motion.

Determinism: the truth and outline files depend only on the seed and the frame count and
are byte-identical between runs; each clip draws from its own stream
``numpy.random.SeedSequence([seed, clip_key])``.  A clip shortened with ``n_frames`` is the
first ``n_frames`` frames of the full clip.  Videos are written with OpenCV's VP9 encoder
(``vp09`` in ``.mp4``); where that encoder is missing, Motion-JPEG in ``.avi`` is used instead.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import os
import secrets
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.interpolate import CubicSpline

from trackcli.errors import ConfigError, InputError, TrackcliError, VideoError

__all__ = [
    "CLIP_NAMES",
    "DEFAULT_SEED",
    "FPS",
    "FRAME_SIZE",
    "TRUTH_COLUMNS",
    "Outline",
    "Truth",
    "circle_outline",
    "clip_truth",
    "default_n_frames",
    "generate",
    "head_and_shoulders",
    "load_outline",
    "load_truth",
    "make_bouncing_ball",
    "make_test",
    "make_three_heads",
    "make_train",
    "polygon_area",
    "polygon_centroid",
    "render_frames",
    "similarity",
    "true_outline",
    "write_clip",
]

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


# =============================================================================================
# Geometry


def polygon_area(poly) -> float:
    """Signed shoelace area of a closed polygon.

    Parameters
    ----------
    poly : array_like of shape (P, 2)
        Vertices ``(x, y)``; the last joins the first.

    Returns
    -------
    float
        Positive when the vertices turn from ``+x`` towards ``+y`` (clockwise on the screen,
        where ``y`` points down); negative for the counter-clockwise outlines of this module.
    """
    p = np.asarray(poly, dtype=float)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def polygon_centroid(poly) -> np.ndarray:
    """Area centroid of a simple closed polygon.

    Parameters
    ----------
    poly : array_like of shape (P, 2)

    Returns
    -------
    ndarray of shape (2,)
    """
    p = np.asarray(poly, dtype=float)
    x, y = p[:, 0], p[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    a = 0.5 * cross.sum()
    if a == 0.0:
        raise ValueError("polygon has zero area; its centroid is undefined")
    return np.array([((x + x1) * cross).sum(), ((y + y1) * cross).sum()]) / (6.0 * a)


def similarity(points, tx: float, ty: float, angle: float, scale: float) -> np.ndarray:
    """Map points by ``p ↦ scale · R(angle) · p + (tx, ty)``.

    Parameters
    ----------
    points : array_like of shape (..., 2)
    tx, ty : float
        Translation in pixels.
    angle : float
        Rotation in radians from ``+x`` towards ``+y`` (clockwise on the screen).
    scale : float

    Returns
    -------
    ndarray of shape (..., 2)
    """
    p = np.asarray(points, dtype=float)
    c, s = scale * math.cos(angle), scale * math.sin(angle)
    out = np.empty_like(p)
    out[..., 0] = c * p[..., 0] - s * p[..., 1] + tx
    out[..., 1] = s * p[..., 0] + c * p[..., 1] + ty
    return out


def true_outline(truth_row, base) -> np.ndarray:
    """The true outline of one object in one frame.

    Parameters
    ----------
    truth_row : mapping
        Anything indexable by ``"tx", "ty", "angle", "scale"``: a dict from
        :meth:`Truth.row`, a ``csv.DictReader`` row, a pandas row.
    base : array_like of shape (P, 2) or Outline
        The base outline of the clip (:func:`load_outline`).

    Returns
    -------
    ndarray of shape (P, 2)
        The outline in image ``(x, y)`` pixels.
    """
    pts = base.points if isinstance(base, Outline) else np.asarray(base, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"base outline must have shape (P, 2), got {pts.shape}")
    try:
        tx, ty, angle, scale = (float(truth_row[k]) for k in ("tx", "ty", "angle", "scale"))
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise ValueError(f"truth row needs numeric tx, ty, angle and scale: {exc}") from None
    return similarity(pts, tx, ty, angle, scale)


def _resample_closed(dense: np.ndarray, n: int) -> np.ndarray:
    """``n`` points equally spaced in arc length along a closed polyline, from ``dense[0]``."""
    closed = np.vstack([dense, dense[:1]])
    seg = np.hypot(*np.diff(closed, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.arange(n) * (s[-1] / n)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


# Head-and-shoulders drawn in "raw" object coordinates (pixels at scale 1, y down, origin
# at the base of the neck); the published outline is shifted to its centroid.
_HEAD_CENTRE = (0.0, -38.0)
_HEAD_AXES = (21.0, 26.0)
_BOTTOM_Y = 62.0
# right half of the upper outline, from the top of the head down to the bottom corner
_HALF_PROFILE = np.array([
    (0.0, -64.0), (11.0, -60.5), (18.5, -51.0), (21.0, -38.0), (18.6, -26.5), (13.5, -18.0),
    (11.2, -11.0), (11.8, -4.5), (17.5, 0.5), (30.0, 5.0), (42.0, 9.5), (50.0, 15.5),
    (54.0, 25.0), (55.5, 40.0), (56.0, _BOTTOM_Y),
])  # fmt: skip


@functools.lru_cache(maxsize=1)
def _head_raw_dense() -> np.ndarray:
    """Dense closed raw outline, counter-clockwise on screen, starting at the top of the head."""
    right = _HALF_PROFILE  # top of the head .. bottom-right corner
    left = right[1:] * np.array([-1.0, 1.0])  # just left of the top .. bottom-left corner
    spline_pts = np.vstack([right[::-1], left])  # bottom-right corner, up, over, down to bottom-left
    d = np.hypot(*np.diff(spline_pts, axis=0).T)
    t = np.concatenate([[0.0], np.cumsum(d)])
    cs = CubicSpline(t, spline_pts, bc_type=((1, [0.0, -1.0]), (1, [0.0, 1.0])))
    arc = cs(np.linspace(0.0, t[-1], 4000))
    bottom = np.linspace(arc[-1], arc[0], 400)[1:-1]  # straight bottom edge, left to right
    closed = np.vstack([arc, bottom])
    if polygon_area(closed) > 0:
        closed = closed[::-1]  # make it counter-clockwise on the screen
    top = int(np.argmin(np.abs(closed[:, 0]) + 1e3 * (closed[:, 1] > -60)))
    return np.roll(closed, -top, axis=0)


def _head_outline_and_offset(n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """The centred outline and the raw position of its centroid (raw = outline + offset)."""
    dense = _head_raw_dense()
    offset = polygon_centroid(dense)
    poly = _resample_closed(dense - offset, n_points)
    residual = polygon_centroid(poly)  # resampling moves the centroid by ~1e-3 px
    return np.round(poly - residual, 4), offset + residual


def head_and_shoulders(n_points: int = N_OUTLINE_POINTS) -> np.ndarray:
    """The head-and-shoulders outline used by the clips (a bust: head, neck, shoulders).

    About 112 px wide and 126 px tall at scale 1, centred on its area centroid, starting at
    the top of the head and running counter-clockwise on the screen (down the left side
    first), vertices equally spaced in arc length and rounded to 1e-4 px.

    Parameters
    ----------
    n_points : int
        Number of vertices ``P`` (at least 8).

    Returns
    -------
    ndarray of shape (P, 2)
    """
    if isinstance(n_points, bool) or int(n_points) != n_points or n_points < 8:
        raise ConfigError(f"n_points must be an integer >= 8, got {n_points!r}")
    return _head_outline_and_offset(int(n_points))[0]


def circle_outline(radius: float, n_points: int = N_OUTLINE_POINTS) -> np.ndarray:
    """A circle of ``radius`` px about the origin, counter-clockwise on the screen from the top.

    Returns
    -------
    ndarray of shape (P, 2)
    """
    if not radius > 0:
        raise ConfigError(f"radius must be > 0, got {radius!r}")
    a = -0.5 * np.pi - 2.0 * np.pi * np.arange(int(n_points)) / int(n_points)
    return np.round(radius * np.stack([np.cos(a), np.sin(a)], axis=1), 4)


def _rectangle(w: float, h: float) -> np.ndarray:
    """Rectangle ``w × h`` about the origin, counter-clockwise on the screen, densified."""
    corners = np.array([(0.0, -h / 2), (-w / 2, -h / 2), (-w / 2, h / 2), (w / 2, h / 2),
                        (w / 2, -h / 2)])  # fmt: skip
    return _resample_closed(corners, 64)


# =============================================================================================
# Ground truth containers and files


@dataclass(frozen=True, eq=False)
class Truth:
    """Per-frame ground truth of a clip: one entry per (frame, object), frame-major.

    Every attribute is an array of shape ``(N,)`` named as the CSV column
    (:data:`TRUTH_COLUMNS`); ``frame`` and ``object`` are integers.
    """

    frame: np.ndarray
    time: np.ndarray
    object: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    bbox_x: np.ndarray
    bbox_y: np.ndarray
    bbox_w: np.ndarray
    bbox_h: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    angle: np.ndarray
    scale: np.ndarray
    visible: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    @property
    def objects(self) -> tuple[int, ...]:
        """The object indices present, ascending."""
        return tuple(int(o) for o in np.unique(self.object))

    @property
    def n_frames(self) -> int:
        """Number of distinct frames."""
        return int(np.unique(self.frame).size)

    def select(self, object_id: int) -> Truth:
        """The rows of one object, in frame order."""
        keep = self.object == object_id
        if not keep.any():
            raise ConfigError(f"no object {object_id!r} in this truth; objects are {self.objects}")
        return Truth(**{c: getattr(self, c)[keep] for c in TRUTH_COLUMNS})

    def row(self, i: int) -> dict[str, float | int]:
        """Row ``i`` as a dict of column name to value (usable by :func:`true_outline`)."""
        return {c: getattr(self, c)[i].item() for c in TRUTH_COLUMNS}

    def pose(self) -> np.ndarray:
        """``(tx, ty, angle, scale)`` of every row, shape ``(N, 4)``."""
        return np.stack([self.tx, self.ty, self.angle, self.scale], axis=1)

    def to_csv(self) -> str:
        """The CSV text, with fixed decimals per column (see ``_DECIMALS``)."""
        lines = [",".join(TRUTH_COLUMNS)]
        cols = [getattr(self, c) for c in TRUTH_COLUMNS]
        fmts = ["{:d}" if c in ("frame", "object") else f"{{:.{_DECIMALS[c]}f}}"
                for c in TRUTH_COLUMNS]  # fmt: skip
        for i in range(len(self)):
            lines.append(",".join(f.format(_plain(col[i])) for f, col in zip(fmts, cols)))
        return "\n".join(lines) + "\n"


def _plain(v):
    """A numpy scalar as a Python int/float, with ``-0.0`` made ``0.0`` for stable text."""
    v = v.item()
    return v + 0.0 if isinstance(v, float) else v


@dataclass(frozen=True, eq=False)
class Outline:
    """A clip's base outline and description, as stored in ``<clip>.outline.json``.

    Attributes
    ----------
    points : ndarray of shape (P, 2)
        Base outline in object coordinates, centred on its area centroid, counter-clockwise
        on the screen.
    clip : str
        Clip name (``"train"``, ...).
    video : str
        File name of the video beside the outline file.
    fps : float
    width, height : int
    n_frames : int
    seed : int
    objects : tuple of str
        What object ``j`` of the truth file is, by index.
    motion : dict
        Parameters of the simulated motion (clip-specific).
    """

    points: np.ndarray
    clip: str
    video: str
    fps: float
    width: int
    height: int
    n_frames: int
    seed: int
    objects: tuple[str, ...]
    motion: dict = field(default_factory=dict)


def load_truth(csv_path) -> Truth:
    """Read a ``<clip>.truth.csv`` written by this module.

    Parameters
    ----------
    csv_path : str or os.PathLike

    Returns
    -------
    Truth

    Raises
    ------
    InputError
        The file is missing, its header is not :data:`TRUTH_COLUMNS`, or a value is not a
        number.
    """
    path = Path(csv_path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot read truth file ({exc.strerror or exc})") from None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise InputError(f"{path}: empty truth file (expected header {','.join(TRUTH_COLUMNS)})")
    header = tuple(c.strip() for c in lines[0].split(","))
    if header != TRUTH_COLUMNS:
        raise InputError(
            f"{path}: truth header is {','.join(header)!r}; expected {','.join(TRUTH_COLUMNS)!r}"
        )
    if len(lines) == 1:
        raise InputError(f"{path}: truth file has a header but no rows")
    table = np.empty((len(lines) - 1, len(TRUTH_COLUMNS)))
    for i, line in enumerate(lines[1:]):
        cells = line.split(",")
        if len(cells) != len(TRUTH_COLUMNS):
            raise InputError(
                f"{path} line {i + 2}: expected {len(TRUTH_COLUMNS)} fields, got {len(cells)}"
            )
        try:
            table[i] = [float(c) for c in cells]
        except ValueError:
            raise InputError(f"{path} line {i + 2}: non-numeric field in {line!r}") from None
    cols = {c: table[:, j] for j, c in enumerate(TRUTH_COLUMNS)}
    for c in ("frame", "object"):
        if not np.all(cols[c] == np.round(cols[c])) or np.any(cols[c] < 0):
            raise InputError(f"{path}: column {c} must hold non-negative integers")
        cols[c] = cols[c].astype(np.int64)
    return Truth(**cols)


def load_outline(json_path) -> Outline:
    """Read a ``<clip>.outline.json`` written by this module.

    Raises
    ------
    InputError
        The file is missing, not JSON, of another ``format`` than 1, or lacks a field; or its
        ``points`` are not a finite ``(P, 2)`` list with ``P >= 3``.
    """
    path = Path(json_path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"{path}: cannot read outline file ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    if not isinstance(doc, dict) or doc.get("format") != 1:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{path}: outline format must be 1, got {got!r}")
    try:
        clip = doc["clip"]
        pts = np.asarray(doc["points"], dtype=float)
        out = Outline(
            points=pts,
            clip=str(clip["name"]),
            video=str(clip["video"]),
            fps=float(clip["fps"]),
            width=int(clip["width"]),
            height=int(clip["height"]),
            n_frames=int(clip["n_frames"]),
            seed=int(clip["seed"]),
            objects=tuple(str(o) for o in clip["objects"]),
            motion=dict(doc.get("motion", {})),
        )
    except KeyError as exc:
        raise InputError(f"{path}: outline file lacks field {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{path}: malformed outline file ({exc})") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3 or not np.all(np.isfinite(pts)):
        raise InputError(f"{path}: points must be a finite list of >= 3 [x, y] pairs, got shape {pts.shape}")
    return out


# =============================================================================================
# Scenes: what is drawn in each frame


@dataclass(frozen=True, eq=False)
class _Sprite:
    """Colour of a shape in its own coordinates: ``image`` (h, w, 3) float32 BGR, and the
    pixel ``origin`` (x, y) of the shape's coordinate origin."""

    image: np.ndarray
    origin: tuple[float, float]


@dataclass(frozen=True, eq=False)
class _Item:
    """One shape drawn in one frame: its base polygon mapped by ``pose`` and painted from
    ``sprite`` mapped the same way.  ``object`` is the truth index of a tracked object;
    opaque items hide whatever was drawn before them."""

    base: np.ndarray
    sprite: _Sprite
    pose: tuple[float, float, float, float]
    opacity: float = 1.0
    object: int | None = None

    @property
    def polygon(self) -> np.ndarray:
        return similarity(self.base, *self.pose)


@dataclass(frozen=True, eq=False)
class _Scene:
    """A clip before rendering: static background, per-frame draw lists, and the truth."""

    name: str
    seed: int
    n_frames: int
    base: np.ndarray  # (P, 2) base outline of the tracked objects
    poses: np.ndarray  # (n_objects, n_frames, 4) tx, ty, angle, scale
    background: np.ndarray  # (H, W, 3) float32 BGR
    items: Callable[[int], list[_Item]]  # draw list of frame k, back to front
    objects: tuple[str, ...]
    motion: dict


def _streams(seed: int, key: int, n: int) -> list[np.random.Generator]:
    return [np.random.default_rng(s) for s in np.random.SeedSequence([seed, key]).spawn(n)]


def _round_poses(poses: np.ndarray) -> np.ndarray:
    """Round poses to the decimals written in the truth file, so the file is exact."""
    out = poses.copy()
    out[..., :2] = np.round(out[..., :2], _DECIMALS["tx"])
    out[..., 2] = np.round(out[..., 2], _DECIMALS["angle"])
    out[..., 3] = np.round(out[..., 3], _DECIMALS["scale"])
    return out + 0.0


def _ar2_coefficients(f: float, beta: float, tau: float) -> tuple[float, float]:
    """Damped oscillator with frequency ``f`` (Hz) and damping ``beta`` (1/s): AC eq 9.25."""
    return 2.0 * math.exp(-beta * tau) * math.cos(2.0 * math.pi * f * tau), -math.exp(-2.0 * beta * tau)


def _ar2_path(rng: np.random.Generator, n: int, a1: float, a2: float, burn_in: int = 300) -> np.ndarray:
    """A zero-mean AR(2) path ``y_k = a1 y_{k-1} + a2 y_{k-2} + w_k``, ``w_k ~ N(0, 1)``, of length
    ``n``, started in (approximately) the stationary distribution by a burn-in."""
    w = rng.standard_normal(n + burn_in)
    y = np.zeros(n + burn_in)
    for k in range(2, n + burn_in):
        y[k] = a1 * y[k - 1] + a2 * y[k - 2] + w[k]
    return y[burn_in:]


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float) -> np.ndarray:
    """Gaussian-blurred white noise with unit standard deviation, shape ``(h, w)``."""
    z = rng.standard_normal(shape).astype(np.float32)
    if sigma > 0:
        z = cv2.GaussianBlur(z, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    return z / max(float(z.std()), 1e-6)


def _gradient(size: tuple[int, int], corners) -> np.ndarray:
    """Bilinear blend of four BGR corner colours (top-left, top-right, bottom-left,
    bottom-right) over an image of ``size = (width, height)``."""
    w, h = size
    c = np.asarray(corners, dtype=np.float32).reshape(2, 2, 3)
    u = np.linspace(0.0, 1.0, w, dtype=np.float32)[None, :, None]
    v = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None, None]
    top = c[0, 0] * (1 - u) + c[0, 1] * u
    bot = c[1, 0] * (1 - u) + c[1, 1] * u
    return top * (1 - v) + bot * v


# ---------------------------------------------------------------------------------------------
# Rasterising and compositing


def _hires_mask(poly: np.ndarray, origin: tuple[int, int], shape: tuple[int, int], factor: int) -> np.ndarray:
    """Supersampled mask of a polygon over the pixel block at ``origin = (x0, y0)`` of
    ``shape = (h, w)`` pixels: uint8 of shape ``(h·factor, w·factor)``, 255 inside.

    Sample ``(I, J)`` sits at pixel coordinates ``((J + ½)/factor − ½ + x0, (I + ½)/factor − ½ + y0)``,
    so every pixel (centre at integer coordinates) holds ``factor²`` evenly spread samples.
    OpenCV fills a polygon about half a sample beyond its edges; the polygon is moved inwards
    by that half sample along its vertex normals to cancel the bias.
    """
    h, w = shape
    p = factor * (poly - np.asarray(origin, dtype=float) + 0.5) - 0.5
    tangent = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    # (t_y, -t_x) points outwards when the signed area is positive, inwards otherwise
    inward = -1.0 if polygon_area(p) > 0 else 1.0
    p = p + 0.5 * inward * normal
    mask = np.zeros((h * factor, w * factor), np.uint8)
    shift = 8
    cv2.fillPoly(mask, [np.round(p * (1 << shift)).astype(np.int32)], 255, cv2.LINE_8, shift)
    return mask


def _composite(canvas: np.ndarray, item: _Item) -> None:
    """Paint ``item`` into ``canvas`` (H, W, 3) float32, in place, with exact-area coverage."""
    H, W = canvas.shape[:2]
    poly = item.polygon
    lo = np.floor(poly.min(axis=0)).astype(int) - 1
    hi = np.ceil(poly.max(axis=0)).astype(int) + 2
    x0, y0 = max(lo[0], 0), max(lo[1], 0)
    x1, y1 = min(hi[0], W), min(hi[1], H)
    if x1 <= x0 or y1 <= y0:
        return
    h, w = y1 - y0, x1 - x0
    mask = _hires_mask(poly, (x0, y0), (h, w), _SUPERSAMPLE)
    alpha = cv2.resize(mask, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32)
    alpha *= item.opacity / 255.0
    tx, ty, angle, scale = item.pose
    c, s = scale * math.cos(angle), scale * math.sin(angle)
    ox, oy = item.sprite.origin
    # sprite pixel q -> object point q - origin -> image point -> block pixel
    m = np.array([[c, -s, tx - x0 - (c * ox - s * oy)], [s, c, ty - y0 - (s * ox + c * oy)]])
    colour = cv2.warpAffine(item.sprite.image, m, (w, h), flags=cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_REPLICATE)  # fmt: skip
    block = canvas[y0:y1, x0:x1]
    block += alpha[..., None] * (colour - block)


def _visible_fraction(item: _Item, in_front: Sequence[_Item], size: tuple[int, int]) -> float:
    """Fraction of ``item``'s area inside the image and not covered by the opaque ``in_front``."""
    f = _VIS_SUPERSAMPLE
    W, H = size
    poly = item.polygon
    lo = np.floor(poly.min(axis=0)).astype(int) - 1
    hi = np.ceil(poly.max(axis=0)).astype(int) + 2
    shape = (int(hi[1] - lo[1]), int(hi[0] - lo[0]))
    obj = _hires_mask(poly, (lo[0], lo[1]), shape, f) > 0
    total = int(obj.sum())
    if total == 0:
        return 0.0
    xs = (np.arange(shape[1] * f) + 0.5) / f - 0.5 + lo[0]
    ys = (np.arange(shape[0] * f) + 0.5) / f - 0.5 + lo[1]
    seen = obj & ((ys >= -0.5) & (ys < H - 0.5))[:, None] & ((xs >= -0.5) & (xs < W - 0.5))[None, :]
    for other in in_front:
        if other.opacity >= 1.0:
            seen &= _hires_mask(other.polygon, (lo[0], lo[1]), shape, f) == 0
    return int(seen.sum()) / total


def _scene_truth(scene: _Scene) -> Truth:
    n_obj = scene.poses.shape[0]
    rows: dict[str, list] = {c: [] for c in TRUTH_COLUMNS}
    for k in range(scene.n_frames):
        items = scene.items(k)
        order = {it.object: i for i, it in enumerate(items) if it.object is not None}
        for j in range(n_obj):
            pose = scene.poses[j, k]
            poly = similarity(scene.base, *pose)
            cx, cy = polygon_centroid(poly)
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            i = order[j]
            vis = _visible_fraction(items[i], items[i + 1:], FRAME_SIZE)
            values = (k, k / FPS, j, cx, cy, lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1], *pose, vis)
            for c, v in zip(TRUTH_COLUMNS, values):
                rows[c].append(v)
    cols = {c: np.asarray(v, dtype=np.int64 if c in ("frame", "object") else float)
            for c, v in rows.items()}  # fmt: skip
    # store exactly what the file will hold, so in-memory and loaded truth agree
    for c, d in _DECIMALS.items():
        cols[c] = np.round(cols[c], d) + 0.0
    return Truth(**cols)


def _render(scene: _Scene, k: int) -> np.ndarray:
    canvas = scene.background.copy()
    for item in scene.items(k):
        _composite(canvas, item)
    return np.clip(np.rint(canvas), 0, 255).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# Appearance


_PALETTES = {
    # BGR colours: skin, hair, shirt, collar
    "object": dict(skin=(105, 132, 172), hair=(32, 36, 48), shirt=(112, 72, 48), collar=(205, 208, 212)),
    "left": dict(skin=(120, 150, 190), hair=(40, 60, 95), shirt=(60, 110, 70), collar=(180, 200, 200)),
    "middle": dict(skin=(92, 118, 150), hair=(25, 25, 30), shirt=(60, 60, 150), collar=(200, 200, 200)),
    "walker": dict(skin=(110, 140, 182), hair=(30, 45, 70), shirt=(140, 100, 60), collar=(215, 215, 220)),
}


def _head_sprite(rng: np.random.Generator, palette: Mapping[str, tuple]) -> _Sprite:
    """Head-and-shoulders colours: skin, hair, shirt with a collar, eyes, rim shading, texture."""
    base, c = _head_outline_and_offset(N_OUTLINE_POINTS)
    pad = 8
    lo = np.floor(base.min(axis=0)) - pad
    hi = np.ceil(base.max(axis=0)) + pad
    w, h = int(hi[0] - lo[0]), int(hi[1] - lo[1])
    origin = (float(-lo[0]), float(-lo[1]))
    # regions are painted at 3×3 samples per sprite pixel, then averaged (soft boundaries)
    sub = 3
    ys, xs = np.mgrid[0:h * sub, 0:w * sub].astype(np.float32)
    X = (xs + 0.5) / sub - 0.5 + float(lo[0] + c[0])  # raw coordinates of each sample
    Y = (ys + 0.5) / sub - 0.5 + float(lo[1] + c[1])
    hx, hy = _HEAD_CENTRE
    ax, ay = _HEAD_AXES
    head = ((X - hx) / (ax + 4)) ** 2 + ((Y - hy) / (ay + 4)) ** 2 <= 1
    neck = (np.abs(X) <= 16) & (Y >= -30)
    v_line = 16.0 - 1.15 * np.abs(X)  # the V of the neckline
    shirt = Y > np.maximum(1.0 + 0.012 * X**2, v_line)
    skin = (head | neck) & ~shirt
    hair = head & ((Y < -47.0 + 0.035 * X**2) | ((np.abs(X) > 16.5) & (Y < -30)))
    collar = shirt & (Y - v_line < 3.2) & (np.abs(X) < 13.5)
    eyes = ((np.abs(X) - 8.0) / 3.0) ** 2 + ((Y - hy + 1.0) / 1.8) ** 2 <= 1
    mouth = (np.abs(X) < 5) & (np.abs(Y + 23.5) < 0.9)
    fine = np.empty((h * sub, w * sub, 3), np.float32)
    fine[:] = palette["shirt"]
    fine[skin] = palette["skin"]
    fine[hair] = palette["hair"]
    fine[collar] = palette["collar"]
    fine[(eyes | mouth) & skin & ~hair] = (40, 40, 60)
    img = cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA)
    X = X[1::sub, 1::sub]
    Y = Y[1::sub, 1::sub]
    # rim shading (darker near the outline) and light from the upper left
    inside = _hires_mask(base, (int(lo[0]), int(lo[1])), (h, w), 1)
    dist = cv2.distanceTransform((inside > 0).astype(np.uint8), cv2.DIST_L2, 5)
    shade = 0.8 + 0.2 * np.clip(dist / 9.0, 0.0, 1.0)
    shade *= 1.0 + 0.1 * (-(X / 60.0) - (Y / 70.0)) / 2.0
    texture = 7.0 * _smooth_noise(rng, (h, w), 1.5) + 2.5 * _smooth_noise(rng, (h, w), 0.0)
    img = img * shade[..., None] + texture[..., None]
    return _Sprite(np.clip(img, 0, 255).astype(np.float32), origin)


def _flat_sprite(colour) -> _Sprite:
    return _Sprite(np.asarray(colour, np.float32).reshape(1, 1, 3), (0.0, 0.0))


def _object_sprite(seed: int) -> _Sprite:
    """The look of the object in ``train`` and ``test`` (same seed, same object)."""
    (rng,) = _streams(seed, _OBJECT_KEY, 1)
    return _head_sprite(rng, _PALETTES["object"])


# =============================================================================================
# The four clips


def _build_train(seed: int, n_frames: int) -> _Scene:
    motion_rng, look_rng = _streams(seed, _CLIP_KEYS["train"], 2)
    W, H = FRAME_SIZE
    L = max(n_frames, _DEFAULT_FRAMES["train"])
    tau = 1.0 / FPS
    names = ("tx", "ty", "angle", "scale")
    means = (W / 2, H / 2 + 8.0, 0.0, 1.0)
    limits = (60.0, 35.0, math.radians(8.0), 0.08)  # largest excursion from the mean
    params, paths = {}, []
    for name, mean, limit in zip(names, means, limits):
        f = float(motion_rng.uniform(0.15, 0.45))
        beta = float(motion_rng.uniform(0.6, 1.6))
        a1, a2 = _ar2_coefficients(f, beta, tau)
        y = _ar2_path(motion_rng, L, a1, a2)
        y *= limit / np.max(np.abs(y))
        paths.append(y)
        params[name] = {"f_hz": round(f, 6), "beta_per_s": round(beta, 6), "a1": round(a1, 6),
                        "a2": round(a2, 6), "mean": mean}  # fmt: skip
    paths = np.stack(paths, axis=1)
    speed = np.hypot(*np.diff(paths[:, :2], axis=0).T).max()
    vmax = 3.0
    if speed > vmax:  # "a few px/frame at most": shrink the translation (still AR(2))
        paths[:, :2] *= vmax / speed
    for j, name in enumerate(names):
        params[name]["excursion"] = round(float(np.max(np.abs(paths[:, j]))), 6)
    poses = _round_poses((paths + np.asarray(means))[None, :n_frames])

    bg = _gradient(FRAME_SIZE, [(222, 214, 200), (205, 206, 214), (196, 190, 178), (182, 186, 196)])
    bg += (3.0 * _smooth_noise(look_rng, (H, W), 12.0) + 2.0 * _smooth_noise(look_rng, (H, W), 0.0))[..., None]
    sprite = _object_sprite(seed)
    base = head_and_shoulders()

    def items(k: int) -> list[_Item]:
        return [_Item(base, sprite, tuple(poses[0, k]), object=0)]

    motion = {
        "model": "independent AR(2) per pose parameter (AC eqs 9.15, 9.25): "
        "p_k - mean = a1 (p_{k-1} - mean) + a2 (p_{k-2} - mean) + b w_k, rescaled so that the "
        "largest excursion from the mean is 'excursion'",
        "tau_s": tau,
        "parameters": params,
    }
    return _Scene("train", seed, n_frames, base, poses, bg, items,
                  ("the head-and-shoulders object",), motion)  # fmt: skip


def _agile_path(rng: np.random.Generator, n: int, box: np.ndarray, vmax: float) -> np.ndarray:
    """Translation with sudden changes of velocity, kept inside ``box = [[xmin, ymin], [xmax, ymax]]``.

    Every 5 to 16 frames a new target velocity is drawn (speed 4 to ``vmax`` px/frame; a third
    of the time a reversal of the current one; in the outer part of the box, a direction
    pointing outwards is flipped); the velocity closes 60 % of the gap to the target each
    frame.  At the box edges the path reflects.
    """
    pos = box.mean(axis=0) + rng.uniform(-0.25, 0.25, 2) * (box[1] - box[0])
    vel = np.zeros(2)
    target = np.zeros(2)
    switch = 0
    out = np.empty((n, 2))
    for k in range(n):
        if k == switch:
            speed = rng.uniform(4.0, vmax)
            if rng.random() < 1 / 3 and np.hypot(*vel) > 2.0:
                direction = -vel / np.hypot(*vel)
            else:
                a = rng.uniform(0.0, 2.0 * np.pi)
                direction = np.array([math.cos(a), math.sin(a)])
                centre, half = box.mean(axis=0), (box[1] - box[0]) / 2
                if np.any(np.abs(pos - centre) > 0.6 * half) and np.dot(direction, centre - pos) < 0:
                    direction = -direction  # near the edges, head back inwards
            target = speed * direction
            switch = k + int(rng.integers(5, 17))
        vel = vel + 0.6 * (target - vel)
        sp = np.hypot(*vel)
        if sp > vmax:
            vel *= vmax / sp
        pos = pos + vel
        for d in range(2):
            if pos[d] < box[0, d]:
                pos[d] = 2 * box[0, d] - pos[d]
                vel[d], target[d] = abs(vel[d]), abs(target[d])
            elif pos[d] > box[1, d]:
                pos[d] = 2 * box[1, d] - pos[d]
                vel[d], target[d] = -abs(vel[d]), -abs(target[d])
        out[k] = pos
    return out


def _clutter(rng: np.random.Generator, base: np.ndarray, sprite: _Sprite, clear_of: np.ndarray) -> np.ndarray:
    """The static background of ``test``: texture, hatched patches, look-alike silhouettes,
    lines at many angles and text-like strokes.  Returns (H, W, 3) float32 BGR.

    The look-alike silhouettes sit in 8 of the 12 cells of a 4 × 3 grid, chosen at random
    among the cells whose centre is at least :data:`_CLEAR_RADIUS` px from ``clear_of``
    (the object's position in the first frame, where the template is drawn): the object
    starts out clear of its doubles, and meets them as it moves."""
    W, H = FRAME_SIZE
    bg = _gradient(FRAME_SIZE, [(200, 196, 186), (170, 182, 196), (186, 180, 170), (196, 198, 204)])
    bg += (16.0 * _smooth_noise(rng, (H, W), 6.0))[..., None]
    bg += (10.0 * _smooth_noise(rng, (H, W), 2.0))[..., None] * np.float32([0.8, 1.0, 1.2])
    bg += (3.0 * _smooth_noise(rng, (H, W), 0.0))[..., None]

    # hatched patches (texture with strong oriented edges)
    img = np.clip(bg, 0, 255).astype(np.uint8)
    for _ in range(5):
        pw, ph = (int(v) for v in rng.integers(50, 140, 2))
        px, py = int(rng.integers(-20, W - 30)), int(rng.integers(-20, H - 30))
        layer = img.copy()
        a = rng.uniform(0, np.pi)
        d = np.array([math.cos(a), math.sin(a)])
        nrm = np.array([-d[1], d[0]])
        gap = rng.uniform(5, 11)
        colour = tuple(int(v) for v in rng.integers(40, 120, 3))
        for t in np.arange(-200, 200, gap):
            p0 = np.array([px + pw / 2, py + ph / 2]) + t * nrm
            cv2.line(layer, tuple(np.round(p0 - 300 * d).astype(int)), tuple(np.round(p0 + 300 * d).astype(int)),
                     colour, 2, cv2.LINE_AA)  # fmt: skip
        sl = np.s_[max(py, 0):min(py + ph, H), max(px, 0):min(px + pw, W)]
        img[sl] = layer[sl]

    # look-alike silhouettes: filled with the object's own colours, filled and then half
    # painted over, or only part of the outline drawn
    canvas = img.astype(np.float32)
    cells = [(gx, gy) for gy in range(3) for gx in range(4)]
    far = [math.hypot((gx + 0.5) * W / 4 - clear_of[0], (gy + 0.5) * H / 3 - clear_of[1]) >= _CLEAR_RADIUS
           for gx, gy in cells]  # fmt: skip
    order = [int(i) for i in rng.permutation(len(cells)) if far[i]][:8]
    strokes = []
    for n, ci in enumerate(order):
        gx, gy = cells[ci]
        cx = (gx + 0.5) * W / 4 + rng.uniform(-25, 25)
        cy = (gy + 0.5) * H / 3 + rng.uniform(-20, 20)
        scale = rng.uniform(0.55, 1.15)
        angle = rng.uniform(-0.6, 0.6)
        kind = n % 3
        if kind == 2:
            strokes.append((cx, cy, angle, scale))
            continue
        look = sprite if n % 2 == 0 else _head_sprite(rng, _PALETTES["middle"])
        _composite(canvas, _Item(base, look, (cx, cy, angle, scale)))
        if kind == 1:  # cover part of it with a background-coloured blob
            r = 40 * scale
            blob = similarity(circle_outline(1.0, 48) * [r * 1.6, r], cx + rng.uniform(-r, r), cy + r * 0.6,
                              rng.uniform(0, np.pi), 1.0)  # fmt: skip
            _composite(canvas, _Item(blob, _flat_sprite(bg[int(np.clip(cy, 0, H - 1)), int(np.clip(cx, 0, W - 1))]),
                                     (0.0, 0.0, 0.0, 1.0)))  # fmt: skip
    img = np.clip(np.rint(canvas), 0, 255).astype(np.uint8)
    for cx, cy, angle, scale in strokes:
        poly = similarity(base, cx, cy, angle, scale)
        start = int(rng.integers(0, len(poly)))
        length = int(rng.uniform(0.45, 0.85) * len(poly))
        part = np.roll(poly, -start, axis=0)[:length]
        colour = tuple(int(v) for v in rng.integers(25, 80, 3))
        cv2.polylines(img, [np.round(part * 16).astype(np.int32)], False, colour,
                      int(rng.integers(2, 4)), cv2.LINE_AA, 4)  # fmt: skip

    # straight lines at many angles, most of them dark like the object's edges
    for _ in range(26):
        p = rng.uniform([0, 0], [W, H])
        a = rng.uniform(0, np.pi)
        d = 800 * np.array([math.cos(a), math.sin(a)])
        dark = rng.random() < 0.7
        colour = tuple(int(v) for v in (rng.integers(20, 90, 3) if dark else rng.integers(225, 256, 3)))
        cv2.line(img, tuple(np.round((p - d) * 16).astype(int)), tuple(np.round((p + d) * 16).astype(int)),
                 colour, int(rng.integers(1, 4)), cv2.LINE_AA, 4)  # fmt: skip

    # text-like strokes
    fonts = [cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_COMPLEX,
             cv2.FONT_HERSHEY_TRIPLEX, cv2.FONT_HERSHEY_SCRIPT_SIMPLEX]  # fmt: skip
    letters = np.array(list("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"))
    for _ in range(14):
        word = "".join(rng.choice(letters, int(rng.integers(3, 10))))
        org = (int(rng.integers(-20, W - 40)), int(rng.integers(15, H)))
        colour = tuple(int(v) for v in rng.integers(15, 100, 3))
        cv2.putText(img, word, org, fonts[int(rng.integers(len(fonts)))], float(rng.uniform(0.5, 1.3)),
                    colour, int(rng.integers(1, 4)), cv2.LINE_AA)  # fmt: skip
    return img.astype(np.float32)


_CLEAR_RADIUS = 125.0
"""Look-alikes of ``test`` are centred at least this far (px, up to jitter) from the object's start."""


def _pole_sprite(length: float, width: float) -> _Sprite:
    """A vertical pole, rounded by shading across its width."""
    w, h = int(width) + 8, int(length) + 8
    u = (np.arange(w, dtype=np.float32) - w / 2) / (width / 2)
    shade = np.clip(1.0 - 0.45 * u**2, 0.4, 1.0)
    img = np.empty((h, w, 3), np.float32)
    img[:] = (np.float32([70, 105, 150]) * shade[:, None])[None, :, :]
    return _Sprite(img, (w / 2, h / 2))


def _build_test(seed: int, n_frames: int) -> _Scene:
    motion_rng, look_rng = _streams(seed, _CLIP_KEYS["test"], 2)
    W, H = FRAME_SIZE
    L = max(n_frames, _DEFAULT_FRAMES["test"])
    base = head_and_shoulders()
    lo, hi = base.min(axis=0), base.max(axis=0)
    # keep the centroid where at least ~80 % of the box stays inside the image
    box = np.array([[-lo[0] * 0.8, -lo[1] * 0.8], [W - 1 - hi[0] * 0.8, H - 1 - hi[1] * 0.8]])
    xy = _agile_path(motion_rng, L, box, vmax=14.5)
    tau = 1.0 / FPS
    extra = []
    for limit in (math.radians(10.0), 0.08):
        a1, a2 = _ar2_coefficients(float(motion_rng.uniform(0.5, 0.9)), 1.0, tau)
        y = _ar2_path(motion_rng, L, a1, a2)
        extra.append(y * limit / np.max(np.abs(y)))
    poses_full = _round_poses(np.column_stack([xy, extra[0], 1.0 + extra[1]])[None])

    # the pole: a tilted bar sweeping sideways at constant speed, across the object at
    # frame k0, at the speed (of a few tried) that keeps the object partly hidden for the
    # number of frames closest to 10
    k0 = int(round(0.55 * _DEFAULT_FRAMES["test"]))
    bar_w, bar_len, bar_angle = 24.0, 520.0, 0.22
    nrm = np.array([math.cos(bar_angle), math.sin(bar_angle)])
    proj = np.stack([similarity(base, *p) @ nrm for p in poses_full[0]])  # (L, P)
    centre0 = poses_full[0, k0, :2]
    vx_obj = poses_full[0, k0 + 1, 0] - poses_full[0, k0 - 1, 0]
    direction = -1.0 if vx_obj > 0 else 1.0
    best = None
    for speed in np.arange(6.0, 40.5, 0.5):
        c = centre0[None, :] + direction * speed * (np.arange(L) - k0)[:, None] * np.array([1.0, 0.0])
        d = proj - (c @ nrm)[:, None]
        overlap = (d.max(axis=1) > -bar_w / 2) & (d.min(axis=1) < bar_w / 2)
        count = int(overlap.sum())
        if best is None or abs(count - 10) < abs(best[1] - 10):
            best = (speed, count)
    bar_speed = float(best[0]) * direction
    bar_base = _rectangle(bar_w, bar_len)
    bar_sprite = _pole_sprite(bar_len, bar_w)
    poses = poses_full[:, :n_frames]

    sprite = _object_sprite(seed)
    background = _clutter(look_rng, base, sprite, poses[0, 0, :2])

    def items(k: int) -> list[_Item]:
        out = [_Item(base, sprite, tuple(poses[0, k]), object=0)]
        bx = centre0[0] + bar_speed * (k - k0)
        if -bar_len < bx < W + bar_len:
            out.append(_Item(bar_base, bar_sprite, (bx, centre0[1], bar_angle, 1.0)))
        return out

    motion = {
        "model": "translation: target velocity redrawn every 5-16 frames (speed 4-14.5 px/frame, "
        "a third of the time a reversal; near the box edges pointing inwards), approached by "
        "60 % per frame, reflected at the box; angle and scale: AR(2) damped oscillators",
        "box": np.round(box, 4).tolist(),
        "occluder": {
            "kind": "bar drawn in front of the object, long axis along R(angle) (0, 1)",
            "width": bar_w,
            "length": bar_len,
            "angle": bar_angle,
            "crosses_at_frame": k0,
            "centre_at_crossing": [float(v) for v in centre0],
            "velocity_px_per_frame": [bar_speed, 0.0],
        },
    }
    return _Scene("test", seed, n_frames, base, poses, background, items,
                  ("the head-and-shoulders object",), motion)  # fmt: skip


def _room(rng: np.random.Generator) -> np.ndarray:
    """Background of ``three_heads``: a plain wall on the left, a door frame, a picture and
    book shelves (above the heads' height) on the right."""
    W, H = FRAME_SIZE
    bg = _gradient(FRAME_SIZE, [(200, 210, 218), (190, 200, 212), (184, 194, 204), (172, 184, 198)])
    bg += (3.0 * _smooth_noise(rng, (H, W), 10.0) + 2.0 * _smooth_noise(rng, (H, W), 0.0))[..., None]
    img = np.clip(np.rint(bg), 0, 255).astype(np.uint8)
    # a door frame, a picture, shelves with books: right two thirds only; the shelves end
    # above head height, so the walker's outline is not cut up by books
    cv2.rectangle(img, (205, 40), (300, 365), (60, 90, 120), 5, cv2.LINE_AA)
    cv2.rectangle(img, (215, 50), (290, 365), (150, 170, 190), -1, cv2.LINE_AA)
    cv2.rectangle(img, (320, 60), (400, 130), (40, 50, 60), 3, cv2.LINE_AA)
    cv2.rectangle(img, (326, 66), (394, 124), (120, 150, 100), -1, cv2.LINE_AA)
    cv2.line(img, (330, 118), (360, 80), (60, 80, 60), 2, cv2.LINE_AA)
    cv2.line(img, (360, 80), (390, 110), (60, 80, 60), 2, cv2.LINE_AA)
    for shelf_y in (75, 135, 195):
        cv2.line(img, (395, shelf_y), (480, shelf_y), (50, 70, 90), 4, cv2.LINE_AA)
        x = 398
        while x < 478:
            bw = int(rng.integers(5, 12))
            bh = int(rng.integers(30, 52))
            colour = tuple(int(v) for v in rng.integers(30, 200, 3))
            cv2.rectangle(img, (x, shelf_y - bh), (min(x + bw, 478), shelf_y - 3), colour, -1)
            x += bw + 1
    cv2.line(img, (180, 0), (180, 360), (175, 185, 195), 1, cv2.LINE_AA)  # corner of the room
    return img.astype(np.float32)


def _build_three_heads(seed: int, n_frames: int) -> _Scene:
    motion_rng, look_rng = _streams(seed, _CLIP_KEYS["three_heads"], 2)
    L = max(n_frames, _DEFAULT_FRAMES["three_heads"])
    tau = 1.0 / FPS
    k = np.arange(L)
    poses = np.empty((3, L, 4))
    # two people standing roughly still: small AR(2) sway about a fixed pose; the three are
    # of nearly one size, so that one template fits them all about equally well
    for j, (x, y, s) in enumerate([(95.0, 268.0, 0.95), (235.0, 262.0, 0.97)]):
        sway = []
        for limit in (2.0, 1.2, math.radians(2.0), 0.01):
            a1, a2 = _ar2_coefficients(float(motion_rng.uniform(0.2, 0.5)), 1.0, tau)
            y_ = _ar2_path(motion_rng, L, a1, a2)
            sway.append(y_ * limit / np.max(np.abs(y_)))
        poses[j] = np.column_stack([x + sway[0], y + sway[1], sway[2], s + sway[3]])
    # the walker: right to left in front of them, bobbing with each step
    x0, x1 = 425.0, 45.0
    speed = (x0 - x1) / (_DEFAULT_FRAMES["three_heads"] - 1)
    step = 12.5  # frames per step (two steps per second)
    phase = float(motion_rng.uniform(0, 2 * np.pi))
    poses[2, :, 0] = x0 - speed * k
    poses[2, :, 1] = 282.0 - 4.0 * np.abs(np.sin(np.pi * k / step + phase))
    poses[2, :, 2] = math.radians(1.5) * np.sin(np.pi * k / step + phase)
    poses[2, :, 3] = 1.0
    poses = _round_poses(poses[:, :n_frames])

    base = head_and_shoulders()
    sprites = [_head_sprite(look_rng, _PALETTES[p]) for p in ("left", "middle", "walker")]
    background = _room(look_rng)

    def items(kf: int) -> list[_Item]:
        return [_Item(base, sprites[j], tuple(poses[j, kf]), object=j) for j in range(3)]

    motion = {
        "model": "objects 0 and 1: AR(2) sway of at most 2 px, 2 deg, 1 %; object 2 walks from "
        f"x = {x0:g} at {speed:.4f} px/frame to the left, bobbing 4 px per step of {step:g} frames",
        "walker_speed_px_per_frame": round(speed, 6),
    }
    objects = ("standing on the left, against a plain wall", "standing in the middle",
               "walking from right to left in front of the others (drawn on top)")  # fmt: skip
    return _Scene("three_heads", seed, n_frames, base, poses, background, items, objects, motion)


def _ball_path(n: int, *, x0: float, y0: float, vx: float, vy: float, g: float, floor: float,
               restitution: float, friction: float, xmin: float, xmax: float) -> np.ndarray:
    """Exact ballistic flight sampled at integer frames: ``(n, 3)`` of ``x, y, rolled angle``.

    Bounces happen at their true sub-frame instants: on the floor (``y = floor``) the vertical
    velocity reverses and shrinks by ``restitution`` and the horizontal one by ``friction``;
    walls at ``xmin``/``xmax`` reflect elastically.  A bounce slower than 0.5 px/frame leaves
    the ball rolling on the floor.
    """
    out = np.empty((n, 3))
    x, y, t = x0, y0, 0.0
    rolling = False
    travelled = 0.0
    for k in range(n):
        while t < k:
            dt = k - t
            # time to hit the floor within dt (y + vy s + g s^2 / 2 = floor, s > 0)
            s_hit = math.inf
            if not rolling:
                disc = vy * vy + 2.0 * g * (floor - y)
                s = (-vy + math.sqrt(max(disc, 0.0))) / g
                if 1e-9 < s <= dt:
                    s_hit = s
            s_wall = math.inf
            if vx > 0:
                s_wall = (xmax - x) / vx
            elif vx < 0:
                s_wall = (xmin - x) / vx
            s_wall = s_wall if 1e-9 < s_wall <= dt else math.inf
            s = min(dt, s_hit, s_wall)
            x += vx * s
            travelled += vx * s
            if not rolling:
                y += vy * s + 0.5 * g * s * s
                vy += g * s
            t += s
            if s == s_hit:
                y = floor
                vy = -restitution * vy
                vx *= friction
                if abs(vy) < 0.5:
                    rolling, vy = True, 0.0
            if s == s_wall:
                vx = -vx
        out[k] = (x, y, travelled)
    return out


def _build_bouncing_ball(seed: int, n_frames: int) -> _Scene:
    (look_rng,) = _streams(seed, _CLIP_KEYS["bouncing_ball"], 1)
    W, H = FRAME_SIZE
    L = max(n_frames, _DEFAULT_FRAMES["bouncing_ball"])
    radius = 16.0
    floor_y = 318.0
    physics = dict(x0=40.0, y0=70.0, vx=2.6, vy=0.0, g=0.9, floor=floor_y - radius,
                   restitution=0.85, friction=0.95, xmin=radius, xmax=W - 1 - radius)  # fmt: skip
    path = _ball_path(L, **physics)
    poses = np.column_stack([path[:, 0], path[:, 1], path[:, 2] / radius, np.ones(L)])
    poses = _round_poses(poses[None, :n_frames])

    base = circle_outline(radius)
    # ball: six coloured sectors, darker towards the rim
    size = int(2 * radius) + 8
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32) - size / 2
    sector = ((np.arctan2(ys, xs) + np.pi) / (np.pi / 3)).astype(int) % 2
    img = np.where(sector[..., None] == 0, np.float32([40, 60, 210]), np.float32([40, 200, 230]))
    rim = np.sqrt(xs**2 + ys**2) / radius
    img = img * (1.0 - 0.35 * np.clip(rim, 0, 1) ** 2)[..., None]
    ball = _Sprite(img.astype(np.float32), (size / 2, size / 2))
    shadow_base = circle_outline(1.0, 64)
    shadow = _flat_sprite((30, 40, 50))

    bg = _gradient(FRAME_SIZE, [(235, 215, 190), (230, 210, 185), (215, 200, 180), (210, 195, 178)])
    bg += (2.0 * _smooth_noise(look_rng, (H, W), 0.0))[..., None]
    wood = _gradient(FRAME_SIZE, [(60, 100, 150)] * 2 + [(40, 75, 120)] * 2)
    wood += (8.0 * _smooth_noise(look_rng, (H, W), 3.0))[..., None]
    fy = int(floor_y)
    bg[fy:] = wood[fy:]
    img_bg = np.clip(np.rint(bg), 0, 255).astype(np.uint8)
    for y in range(fy + 9, H, 11):
        cv2.line(img_bg, (0, y), (W, y), (35, 60, 95), 1, cv2.LINE_AA)
    cv2.line(img_bg, (0, fy), (W, fy), (30, 50, 80), 2, cv2.LINE_AA)

    def items(k: int) -> list[_Item]:
        x, y = poses[0, k, :2]
        height = max(floor_y - radius - y, 0.0)
        near = 1.0 - 0.6 * min(height / 250.0, 1.0)
        sh = (x, floor_y + 5.0, 0.0, 1.0)
        shadow_poly = shadow_base * np.array([radius * 1.2 * near, 4.0 * near])
        return [_Item(shadow_poly, shadow, sh, opacity=0.45 * near),
                _Item(base, ball, tuple(poses[0, k]), object=0)]  # fmt: skip

    motion = {
        "model": "ballistic flight under gravity, bounces at their exact sub-frame instants; "
        "angle = distance rolled / radius (sign of vx)",
        "radius": radius,
        "g_px_per_frame2": physics["g"],
        "restitution": physics["restitution"],
        "friction_per_bounce": physics["friction"],
        "floor_y": floor_y,
        "start": {"x": physics["x0"], "y": physics["y0"], "vx": physics["vx"], "vy": physics["vy"]},
    }
    return _Scene("bouncing_ball", seed, n_frames, base, poses, np.asarray(img_bg, np.float32), items,
                  ("the ball",), motion)  # fmt: skip


_BUILDERS: dict[str, Callable[[int, int], _Scene]] = {
    "train": _build_train,
    "test": _build_test,
    "three_heads": _build_three_heads,
    "bouncing_ball": _build_bouncing_ball,
}


# =============================================================================================
# Public entry points


def default_n_frames(clip: str) -> int:
    """Number of frames of the full-length ``clip``."""
    return _DEFAULT_FRAMES[_check_clip(clip)]


def _check_clip(clip: str) -> str:
    if clip not in _BUILDERS:
        raise ConfigError(f"unknown clip {clip!r}; valid clips are {', '.join(CLIP_NAMES)}")
    return clip


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_n_frames(n_frames, clip: str) -> int:
    if n_frames is None:
        return _DEFAULT_FRAMES[clip]
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise ConfigError(f"n_frames must be a positive integer or None, got {n_frames!r}")
    return int(n_frames)


def _scene(clip: str, seed: int, n_frames: int | None) -> _Scene:
    clip = _check_clip(clip)
    return _BUILDERS[clip](_check_seed(seed), _check_n_frames(n_frames, clip))


def clip_truth(clip: str, *, seed: int = DEFAULT_SEED, n_frames: int | None = None) -> Truth:
    """Ground truth of a clip without rendering it (as written to ``<clip>.truth.csv``)."""
    return _scene_truth(_scene(clip, seed, n_frames))


def render_frames(clip: str, *, seed: int = DEFAULT_SEED, n_frames: int | None = None) -> Iterator[np.ndarray]:
    """The frames of a clip, before video encoding.

    Yields
    ------
    ndarray of shape (360, 480, 3), uint8, BGR
    """
    scene = _scene(clip, seed, n_frames)
    for k in range(scene.n_frames):
        yield _render(scene, k)


def _outline_json(scene: _Scene, video_name: str) -> str:
    doc = {
        "format": 1,
        "description": (
            "Base outline of the objects of this clip, in object coordinates (pixels at scale 1, "
            "x right, y down), centred on its area centroid, counter-clockwise as seen on the "
            "screen (signed shoelace area in (x, y) is negative). In frame k, object j is bounded "
            "by p_image = scale * R(angle) @ p + (tx, ty), R(a) = [[cos a, -sin a], [sin a, cos a]], "
            "with tx, ty, angle, scale from the row of <clip>.truth.csv for frame k and object j."
        ),
        "clip": {
            "name": scene.name,
            "video": video_name,
            "truth": f"{scene.name}.truth.csv",
            "fps": FPS,
            "width": FRAME_SIZE[0],
            "height": FRAME_SIZE[1],
            "n_frames": scene.n_frames,
            "seed": scene.seed,
            "objects": list(scene.objects),
        },
        "columns": _COLUMN_TEXT,
        "motion": scene.motion,
        "n_points": int(scene.base.shape[0]),
        "points": [[float(x) + 0.0, float(y) + 0.0] for x, y in np.round(scene.base, 4)],
    }
    return json.dumps(doc, indent=1, ensure_ascii=False) + "\n"


def _temp_path(final: Path) -> Path:
    """An unused name in the folder of ``final``, ending like ``final`` (OpenCV picks the
    container from the extension)."""
    return final.with_name(f".{final.stem}.{secrets.token_hex(6)}.tmp{final.suffix}")


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = _temp_path(path)
    try:
        with open(tmp, "x", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


_CODECS = (("vp09", ".mp4"), ("MJPG", ".avi"))


def _write_video(scene: _Scene, outdir: Path, progress: Progress | None) -> Path:
    W, H = FRAME_SIZE
    for fourcc, ext in _CODECS:
        final = outdir / f"{scene.name}{ext}"
        tmp = _temp_path(final)
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), FPS, (W, H))
        if writer.isOpened():
            break
        writer.release()
        tmp.unlink(missing_ok=True)
        log.warning("OpenCV cannot write %s%s here; trying the next codec", fourcc, ext)
    else:
        raise VideoError(f"OpenCV can write none of {', '.join(f + e for f, e in _CODECS)} in {outdir}")
    try:
        for k in range(scene.n_frames):
            writer.write(_render(scene, k))
            if progress is not None:
                progress(scene.name, k, scene.n_frames)
        writer.release()
        _check_readback(tmp, scene.n_frames)
        os.replace(tmp, final)
    except BaseException:
        writer.release()
        tmp.unlink(missing_ok=True)
        raise
    return final


def _check_readback(path: Path, n_frames: int) -> None:
    cap = cv2.VideoCapture(str(path))
    try:
        count = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            if frame.shape[:2] != FRAME_SIZE[::-1]:
                raise VideoError(f"{path}: frame {count} reads back as {frame.shape}, expected {FRAME_SIZE[::-1]}")
            count += 1
    finally:
        cap.release()
    if count != n_frames:
        raise VideoError(f"{path}: wrote {n_frames} frames but {count} read back")


def write_clip(
    clip: str,
    outdir,
    *,
    seed: int = DEFAULT_SEED,
    n_frames: int | None = None,
    truth_only: bool = False,
    progress: Progress | None = None,
) -> list[Path]:
    """Write one clip, its truth CSV and its outline JSON into ``outdir``.

    Parameters
    ----------
    clip : str
        One of :data:`CLIP_NAMES`.
    outdir : str or os.PathLike
        Created if missing.  Each file is written to a temporary name in the folder and
        renamed into place.
    seed : int
        Non-negative seed; the same seed gives byte-identical truth and outline files.
    n_frames : int, optional
        Shorten (or lengthen) the clip; a shortened clip is the start of the full one.
    truth_only : bool
        Write only the truth and outline files (fast: nothing is rendered).
    progress : callable, optional
        Called as ``progress(clip, frame_index, n_frames)`` after each frame is written.

    Returns
    -------
    list of Path
        ``[video, truth, outline]`` (without the video when ``truth_only``).
    """
    scene = _scene(clip, seed, n_frames)
    out = Path(outdir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create output folder {out}: {exc.strerror or exc}") from None
    paths = []
    if truth_only:
        video_name = next((f"{clip}{e}" for _, e in _CODECS if (out / f"{clip}{e}").exists()), f"{clip}.mp4")
    else:
        video = _write_video(scene, out, progress)
        paths.append(video)
        video_name = video.name
    truth_path = out / f"{clip}.truth.csv"
    outline_path = out / f"{clip}.outline.json"
    _atomic_write_text(truth_path, _scene_truth(scene).to_csv())
    _atomic_write_text(outline_path, _outline_json(scene, video_name))
    return paths + [truth_path, outline_path]


def make_train(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
               progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``train``: gentle AR(2) motion over a clean background (see :func:`write_clip`)."""
    return write_clip("train", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only, progress=progress)


def make_test(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
              progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``test``: agile motion over heavy clutter, with an occluding pole (see :func:`write_clip`)."""
    return write_clip("test", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only, progress=progress)


def make_three_heads(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
                     progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``three_heads``: two still heads, one walking in front (see :func:`write_clip`)."""
    return write_clip("three_heads", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only,
                      progress=progress)  # fmt: skip


def make_bouncing_ball(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
                       progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``bouncing_ball``: ballistic flight with bounces (see :func:`write_clip`)."""
    return write_clip("bouncing_ball", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only,
                      progress=progress)  # fmt: skip


def generate(
    outdir,
    *,
    seed: int = DEFAULT_SEED,
    clips: Sequence[str] | None = None,
    progress: Progress | None = None,
    n_frames: int | None = None,
    truth_only: bool = False,
) -> list[Path]:
    """Write the sample clips with their ground truth into ``outdir``.

    Parameters
    ----------
    outdir : str or os.PathLike
    seed : int
        Seed of every clip (each clip uses its own stream derived from it).
    clips : sequence of str, optional
        Which of :data:`CLIP_NAMES` to write; all by default.
    progress : callable, optional
        ``progress(clip, frame_index, n_frames)``, called after each frame is written.
    n_frames : int, optional
        Frame count for every selected clip instead of its default length.
    truth_only : bool
        Write only the truth and outline files.

    Returns
    -------
    list of Path
        The files written, clip by clip.
    """
    if isinstance(clips, str):
        clips = [clips]
    names = list(CLIP_NAMES if clips is None else clips)
    for name in names:
        _check_clip(name)
    _check_seed(seed)
    paths: list[Path] = []
    for name in names:
        paths += write_clip(name, outdir, seed=seed, n_frames=n_frames, truth_only=truth_only,
                            progress=progress)  # fmt: skip
    return paths


def _main(argv: Sequence[str] | None = None) -> int:
    import argparse
    import sys

    parser = argparse.ArgumentParser(
        prog="python -m trackcli.sample_data",
        description="Write the synthetic sample clips and their ground truth.",
    )
    parser.add_argument("outdir", help="output folder (created if missing)")
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"seed (default {DEFAULT_SEED})")
    parser.add_argument("--clip", action="append", choices=CLIP_NAMES, help="only this clip (repeatable)")
    parser.add_argument("--frames", type=int, default=None, help="frames per clip instead of the defaults")
    parser.add_argument("--truth-only", action="store_true", help="write only truth and outline files")
    args = parser.parse_args(argv)

    def report(name: str, k: int, n: int) -> None:
        if k + 1 == n or (k + 1) % 25 == 0:
            print(f"\r{name}: {k + 1}/{n}", end="\n" if k + 1 == n else "", file=sys.stderr, flush=True)

    try:
        for p in generate(args.outdir, seed=args.seed, clips=args.clip, progress=report,
                          n_frames=args.frames, truth_only=args.truth_only):  # fmt: skip
            print(p)
    except TrackcliError as exc:
        print(f"Error: {exc}", file=sys.stderr)
        return exc.exit_code
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
