"""The ``train`` clip: one head moving gently over a clean background."""

from __future__ import annotations

import math

import numpy as np
from trackcli.sample_data.common import FPS, FRAME_SIZE, _CLIP_KEYS, _DEFAULT_FRAMES
from trackcli.sample_data.geometry import head_and_shoulders
from trackcli.sample_data.scene import _Item, _Scene, _ar2_coefficients, _ar2_path, _gradient, _object_sprite, _round_poses, _smooth_noise, _streams



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
