"""Scenes of sprites over a background, rendered with supersampled coverage; the objects' looks."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from trackcli.sample_data.common import FPS, FRAME_SIZE, N_OUTLINE_POINTS, TRUTH_COLUMNS, _DECIMALS, _OBJECT_KEY, _SUPERSAMPLE, _VIS_SUPERSAMPLE
from trackcli.sample_data.geometry import _HEAD_AXES, _HEAD_CENTRE, _head_outline_and_offset, polygon_area, polygon_centroid, similarity
from trackcli.sample_data.truth import Truth



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
