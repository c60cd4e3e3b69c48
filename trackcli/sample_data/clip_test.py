"""The ``test`` clip: the same head moving agilely over heavy clutter, a pole passing in front."""

from __future__ import annotations

import math

import cv2
import numpy as np
from trackcli.sample_data.common import FPS, FRAME_SIZE, _CLIP_KEYS, _DEFAULT_FRAMES
from trackcli.sample_data.geometry import _rectangle, circle_outline, head_and_shoulders, similarity
from trackcli.sample_data.scene import _Item, _PALETTES, _Scene, _Sprite, _ar2_coefficients, _ar2_path, _composite, _flat_sprite, _gradient, _head_sprite, _object_sprite, _round_poses, _smooth_noise, _streams



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
