"""Outlines to draw templates from: parsed points, an ellipse, checks, polygon geometry.

Every route of ``trackcli draw`` ends the same way: an ordered outline polygon ``(P, 2)`` in
image ``(x, y)`` pixels, to which a B-spline is fitted (:mod:`trackcli.run.drawing`).  This
module holds the geometry of those outlines:

- ``--points``: the polygon is given (:func:`parse_points`).
- ``--ellipse cx,cy,a,b[,angle]``: the polygon is sampled from the ellipse (angle in degrees,
  clockwise on screen since ``y`` points down; :func:`ellipse_outline`).
- the checks every outline passes (:func:`check_outline_in_frame`), its canonical order
  (:func:`canonical_start`), resampling, rasterising (:func:`polygon_mask`) and how far a
  fitted curve lies from it (:func:`fit_error`).

Outlines of masks and of boxes (GrabCut) come from :mod:`trackcli.segment`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from trackcli.errors import ConfigError, DataError, InputError, short_repr

# ---------------------------------------------------------------------------------------------
# Parsing user input


def parse_numbers(text: str, count: int | tuple[int, int], what: str,
                  error: type[Exception] = ConfigError) -> list[float]:
    """Parse ``"a,b,c"`` into floats, checking how many there are.

    Raises ``error``: ConfigError (an invalid option value) by default, InputError for a
    line of an input file.
    """
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise error(f"{what}: expected comma-separated numbers, got {short_repr(text)}") from None
    lo, hi = (count, count) if isinstance(count, int) else count
    if not lo <= len(values) <= hi:
        n = str(lo) if lo == hi else f"{lo} to {hi}"
        raise error(f"{what}: expected {n} numbers, got {len(values)} in {short_repr(text)}")
    if not all(np.isfinite(values)):
        raise error(f"{what}: numbers must be finite, got {short_repr(text)}")
    return values


def parse_points(spec: str) -> np.ndarray:
    """Ordered points from ``"x1,y1 x2,y2 ..."`` (or ``x1,y1,x2,y2,...``) or from a file of them.

    A file holds one ``x,y`` (or ``x y``) pair per line; blank lines and lines starting with
    ``#`` are ignored.  Returns an array of shape ``(P, 2)``.
    """
    path = Path(spec)
    looks_numeric = re.fullmatch(r"[\d.,\s+\-eE]+", spec) is not None
    if not looks_numeric:
        if not path.is_file():
            raise ConfigError(f"--points: {short_repr(spec)} is neither x,y pairs nor an existing points file")
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise InputError(f"{path}: cannot read points file ({exc.strerror or exc})") from None
        rows = []
        for k, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if line and not line.startswith("#"):
                rows.append(parse_numbers(line, 2, f"{spec} line {k}", InputError))
        pts = np.asarray(rows, dtype=float).reshape(-1, 2)
        if len(pts) < 3:
            raise InputError(f"{spec}: need at least 3 points, got {len(pts)}")
    else:
        values = parse_numbers(spec, (0, 10**6), "--points")
        if len(values) % 2:
            raise ConfigError(f"--points: expected x,y pairs, got an odd count of numbers ({len(values)})")
        pts = np.asarray(values, dtype=float).reshape(-1, 2)
    if len(pts) < 3:
        raise ConfigError(f"--points: need at least 3 points, got {len(pts)}")
    return pts


# ---------------------------------------------------------------------------------------------
# Outlines

#: Smallest width and height (px) of the part of an outline inside the frame, and of a frame.
MIN_OUTLINE_SIDE = 8
#: a closed outline's least mean width, px (area over half its perimeter)
MIN_OUTLINE_WIDTH = 1.0


def check_frame_size(frame_size: tuple[int, int], clip: str) -> None:
    """Raise DataError if frames of ``frame_size = (w, h)`` are too small to draw on."""
    w, h = frame_size
    if w < MIN_OUTLINE_SIDE or h < MIN_OUTLINE_SIDE:
        raise DataError(f"{clip}: frames are {w}x{h} px, too small to draw a template on "
                        f"(at least {MIN_OUTLINE_SIDE}x{MIN_OUTLINE_SIDE})")


def check_outline_in_frame(outline: np.ndarray, frame_size: tuple[int, int], what: str, *,
                           closed: bool = True) -> None:
    """Raise ConfigError if the outline ``(P, 2)`` is tiny or lies (almost) outside the frame.

    The rule is the one ``--box`` follows: the outline's bounding box, cut to the frame
    ``(w, h)``, must be at least :data:`MIN_OUTLINE_SIDE` px wide and high (an open curve:
    wide or high).  A closed outline must also enclose an area: its mean width (area over
    half the perimeter) at least :data:`MIN_OUTLINE_WIDTH` px, which points on a line, or a
    path that doubles back on itself, do not have.
    """
    w, h = frame_size
    pts = np.asarray(outline, dtype=float)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = hi - lo
    if (size.min() if closed else size.max()) < MIN_OUTLINE_SIDE:
        raise ConfigError(f"{what}: the outline spans only {size[0]:.3g}x{size[1]:.3g} px (at least "
                          f"{MIN_OUTLINE_SIDE} px {'each way' if closed else 'one way'})")
    if closed:
        from trackcli.shapes.spline import polygon_area_centroid

        area = abs(float(polygon_area_centroid(pts)[0]))
        half_perimeter = 0.5 * float(np.hypot(*(np.roll(pts, -1, axis=0) - pts).T).sum())
        if area < MIN_OUTLINE_WIDTH * half_perimeter:
            raise ConfigError(f"{what}: the outline encloses almost no area ({area:.1f} px²; its points lie on "
                              "a line, or the path doubles back on itself): give points in order around the object")
    inside = np.minimum(hi, [w - 1.0, h - 1.0]) - np.maximum(lo, 0.0)
    if inside.min() < 0 or (inside.min() if closed else inside.max()) < MIN_OUTLINE_SIDE:
        raise ConfigError(f"{what}: the outline lies (almost) outside the {w}x{h} frame "
                          f"(at least {MIN_OUTLINE_SIDE}x{MIN_OUTLINE_SIDE} px of it must be inside)")


def ellipse_outline(cx: float, cy: float, a: float, b: float, angle_deg: float = 0.0, n: int = 256) -> np.ndarray:
    """Points ``(n, 2)`` on an ellipse with semi-axes ``a`` (along x before rotation) and ``b``."""
    if a <= 0 or b <= 0:
        raise ConfigError(f"--ellipse: semi-axes must be positive, got a={a:g}, b={b:g}")
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    x, y = a * np.cos(t), b * np.sin(t)
    return np.column_stack([cx + c * x - s * y, cy + s * x + c * y])


def polygon_mask(points: np.ndarray, frame_size: tuple[int, int]) -> np.ndarray:
    """Rasterise a closed polygon ``(P, 2)`` into a uint8 mask of ``frame_size = (w, h)``."""
    import cv2

    w, h = frame_size
    m = np.zeros((h, w), np.uint8)
    pts = np.round(np.asarray(points) * 16).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(m, [pts], 255, lineType=cv2.LINE_8, shift=4)
    return m


def fit_error(template, outline: np.ndarray) -> float:
    """Largest distance (px) from the template's curve to the closed polygon ``outline``."""
    import cv2

    from trackcli.shapes.spline import dense_polygon

    poly = dense_polygon(template.Q, template.basis())
    contour = np.asarray(outline, dtype=np.float32).reshape(-1, 1, 2)
    return max(abs(cv2.pointPolygonTest(contour, (float(x), float(y)), True)) for x, y in poly)


def canonical_start(outline: np.ndarray) -> np.ndarray:
    """Order a closed outline clockwise on screen, starting at its topmost point.

    Templates of the same object drawn on different frames then have control points in
    correspondence (control point 0 at the top), which models placed on a new clip rely on.
    """
    x, y = outline[:, 0], outline[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    if area2 < 0:  # counter-clockwise on screen (y down): reverse
        outline = outline[::-1]
    top = outline[:, 1].min()
    near_top = np.flatnonzero(outline[:, 1] <= top + 0.5)
    # among the topmost points take the middle one, so flat tops start at their centre
    cx = outline[near_top, 0].mean()
    start = near_top[np.argmin(np.abs(outline[near_top, 0] - cx))]
    return np.roll(outline, -int(start), axis=0)


def resample_polygon(points: np.ndarray, n: int, closed: bool) -> np.ndarray:
    """``n`` points equally spaced along a polygon ``(P, 2)`` (closed: the last joined to the first)."""
    pts = np.vstack([points, points[:1]]) if closed else points
    seg = np.hypot(*np.diff(pts, axis=0).T)
    t = np.concatenate([[0.0], np.cumsum(seg)])
    u = np.linspace(0.0, t[-1], n, endpoint=not closed)
    return np.column_stack([np.interp(u, t, pts[:, 0]), np.interp(u, t, pts[:, 1])])
