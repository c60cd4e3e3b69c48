"""The ``bouncing_ball`` clip: a ball in parabolic flight bouncing on a floor."""

from __future__ import annotations

import math

import cv2
import numpy as np
from trackcli.sample_data.common import FRAME_SIZE, _CLIP_KEYS, _DEFAULT_FRAMES
from trackcli.sample_data.geometry import circle_outline
from trackcli.sample_data.scene import _Item, _Scene, _Sprite, _flat_sprite, _gradient, _round_poses, _smooth_noise, _streams



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
