"""The ``three_heads`` clip: two people standing, a third walking in front of them."""

from __future__ import annotations

import math

import cv2
import numpy as np
from trackcli.sample_data.common import FPS, FRAME_SIZE, _CLIP_KEYS, _DEFAULT_FRAMES
from trackcli.sample_data.geometry import head_and_shoulders
from trackcli.sample_data.scene import _Item, _PALETTES, _Scene, _ar2_coefficients, _ar2_path, _gradient, _head_sprite, _round_poses, _smooth_noise, _streams



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
