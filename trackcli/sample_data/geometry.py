"""Outlines of the sample objects and the similarity that places them."""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.interpolate import CubicSpline

from trackcli.shapes.spline import polygon_area_centroid
from trackcli.errors import ConfigError
from trackcli.sample_data.common import N_OUTLINE_POINTS
from trackcli.sample_data.truth import Outline, load_outline


# =============================================================================================
# Geometry


def polygon_area(poly) -> float:
    """Signed shoelace area of a closed polygon ``(P, 2)``: positive when the vertices turn from
    ``+x`` towards ``+y`` (clockwise on the screen, where ``y`` points down), negative for the
    counter-clockwise outlines of this package (:func:`trackcli.shapes.spline.polygon_area_centroid`)."""
    return float(polygon_area_centroid(poly)[0])


def polygon_centroid(poly) -> np.ndarray:
    """Area centroid ``(2,)`` of a simple closed polygon ``(P, 2)``
    (:func:`trackcli.shapes.spline.polygon_area_centroid`)."""
    return polygon_area_centroid(poly)[1]


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


def place_outlines(json_path, rows) -> np.ndarray:
    """The true outline of every row of a truth CSV: the base outline of ``json_path`` (a
    ``<clip>.outline.json``, :func:`load_outline`) placed in each row's pose
    (:func:`true_outline`); shape ``(N, P, 2)``.  A row without a numeric pose raises
    ``ValueError``."""
    base = load_outline(json_path)
    return np.stack([true_outline(row, base) for row in rows])


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
