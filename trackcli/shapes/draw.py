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


# ---------------------------------------------------------------------------------------------
# A closed curve through an outline, its control points where the outline bends

#: share of a closed fit's parametrisation given by where the outline bends (the rest by arc
#: length): see :func:`outline_params`
BEND_SHARE = 0.5
#: rounds of :func:`fit_closed`: each moves every point's parameter to its closest place on
#: the curve (within half a span either way) and solves for the control points again
FIT_ROUNDS = 6
#: ... to the closest of the curve's points sampled this many times per span
FIT_SAMPLES = 64


def bend_vertices(points: np.ndarray, n: int) -> np.ndarray:
    """Indices (sorted, the first 0) of ``n`` vertices of a closed polygon ``(P, 2)`` that
    keep its shape: chosen top-down in the order of Douglas and Peucker, each next vertex the
    one farthest from the chord of the stretch between two chosen ones that holds it.
    Vertices gather where the outline bends (a leg, a beak) and are sparse along straight
    or gently curved runs."""
    import heapq

    p = np.asarray(points, dtype=float)
    P = len(p)
    n = min(int(n), P)

    def farthest(a: int, b: int) -> tuple[float, int]:
        idx = np.arange(a + 1, b if b > a else b + P) % P
        if idx.size == 0:
            return 0.0, -1
        chord = p[b] - p[a]
        q = p[idx] - p[a]
        length = float(np.hypot(*chord))
        dist = np.hypot(*q.T) if length < 1e-9 else np.abs(chord[0] * q[:, 1] - chord[1] * q[:, 0]) / length
        k = int(np.argmax(dist))
        return float(dist[k]), int(idx[k])

    chosen = [0, int(np.argmax(np.hypot(*(p - p[0]).T)))]
    heap: list[tuple[float, int, int, int]] = []
    for a, b in ((chosen[0], chosen[1]), (chosen[1], chosen[0])):
        d, k = farthest(a, b)
        if k >= 0:
            heapq.heappush(heap, (-d, a, b, k))
    while len(chosen) < n and heap:
        _, a, b, k = heapq.heappop(heap)
        chosen.append(k)
        for x, y in ((a, k), (k, b)):
            d, j = farthest(x, y)
            if j >= 0:
                heapq.heappush(heap, (-d, x, y, j))
    return np.sort(np.asarray(chosen, dtype=int))


def outline_params(points: np.ndarray, n_ctrl: int, bend_share: float = BEND_SHARE) -> np.ndarray:
    """Spline parameters ``s ∈ [0, n_ctrl)`` of the points of a closed polygon, the first at 0.

    A closed uniform B-spline gives each control point one span of the parameter, so where
    the parameter runs fast along the outline the control points are dense.  By arc length
    they are spread evenly; by :func:`bend_vertices` the ``k``-th of ``n_ctrl`` vertices
    chosen where the outline bends gets ``s = k`` (arc length between them), and control
    points gather at the bends.  The parameters returned are ``bend_share`` of the second
    and the rest of the first: both increase along the outline, and so does their mix.
    """
    p = np.asarray(points, dtype=float)
    P = len(p)
    seg = np.hypot(*np.diff(np.vstack([p, p[:1]]), axis=0).T)
    t = np.concatenate([[0.0], np.cumsum(seg)])
    total = max(float(t[-1]), 1e-12)
    by_arc = n_ctrl * t[:-1] / total
    if bend_share <= 0:
        return by_arc
    v = bend_vertices(p, n_ctrl)
    k = len(v)
    # for each point: the chosen vertex at or before it, and the share of the way to the next
    before = np.searchsorted(v, np.arange(P), side="right") - 1
    start, stop = t[v[before]], np.where(before + 1 < k, t[v[np.minimum(before + 1, k - 1)]], total)
    by_bends = (before + (t[:-1] - start) / np.maximum(stop - start, 1e-12)) * (n_ctrl / k)
    return bend_share * by_bends + (1.0 - bend_share) * by_arc


def fit_closed(points: np.ndarray, n_ctrl: int, *, degree: int = 2, bend_share: float | None = None,
               rounds: int = FIT_ROUNDS) -> np.ndarray:
    """A closed B-spline of ``n_ctrl`` control points through a closed polygon ``(P, 2)``
    (``P`` at least ``n_ctrl``); returns ``Q = (Qx; Qy)``.

    The points get parameters by :func:`outline_params`, and the control points solve the
    linear least-squares problem (with a vanishing second-difference term, so that a span
    without points is still determined).  Each of ``rounds`` rounds then moves every point's
    parameter to the closest place on the curve (sampled :data:`FIT_SAMPLES` times a span)
    within half a span either way of where it was, and solves again.  Parameters only move
    locally, so they keep their order along the outline: the curve cannot fold back or throw
    a loop to serve points elsewhere, which a fit that searches the whole curve for each
    point (:func:`trackcli.shapes.spline.fit`) can do with many control points on an outline
    with long thin parts.
    """
    from trackcli.shapes.spline import SplineBasis

    p = np.asarray(points, dtype=float)
    basis = SplineBasis(n_ctrl, degree, True)
    L = float(basis.L)
    s = np.mod(outline_params(p, n_ctrl, BEND_SHARE if bend_share is None else bend_share), L)
    D = np.roll(np.eye(n_ctrl), -1, axis=1) - 2.0 * np.eye(n_ctrl) + np.roll(np.eye(n_ctrl), 1, axis=1)
    smooth = D.T @ D

    def solve(s: np.ndarray) -> np.ndarray:
        B = basis.basis(s)
        A = B.T @ B
        return np.linalg.solve(A + 1e-6 * np.trace(A) / n_ctrl * smooth, B.T @ p)

    # the curve is sampled FIT_SAMPLES times per span; each round a point's parameter moves
    # to the closest sample within half a span either way
    grid = basis.basis(np.arange(int(L) * FIT_SAMPLES) / FIT_SAMPLES)
    reach = np.arange(-(FIT_SAMPLES // 2), FIT_SAMPLES // 2 + 1)
    X = solve(s)
    for _ in range(rounds):
        curve = grid @ X
        near = (np.rint(s * FIT_SAMPLES).astype(int)[:, None] + reach[None, :]) % len(curve)
        best = np.argmin(np.sum((curve[near] - p[:, None, :]) ** 2, axis=2), axis=1)
        s = near[np.arange(len(p)), best] / FIT_SAMPLES
        X = solve(s)
    return np.concatenate([X[:, 0], X[:, 1]])
