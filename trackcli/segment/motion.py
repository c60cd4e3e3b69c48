"""What moves unlike its surroundings: a motion cue for ``draw --box`` on a clip.

One frame cannot tell an object from a region beside it of the same colours (a wall behind a
dancer, the water under a flamingo); the frames that follow can, since the object moves and
the region moves with the scene.  :func:`motion_residual` measures, at every pixel, how far the
dense optical flow (DIS) from the drawn frame to each of the next few frames departs from the
scene's own motion (the smallest departure over those frames), a homography fitted by RANSAC
to the flow outside the box (it takes in a still camera, a pan, a zoom); :func:`moving` splits the box at Otsu's threshold of that
residual.  The scene's homography also stands for a far background behind a moving camera;
near objects outside the box that move otherwise only spoil the fit where they dominate it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: the frames after the drawn one whose flow is measured (the residual is the smallest of them)
MOTION_FRAMES = 3
#: the scale of the frames for the flow (DIS at half resolution)
MOTION_SCALE = 0.5
#: the scene's motion is fitted outside the box grown by this share of its size on every side
MOTION_MARGIN = 0.1
#: the flow's smoothing, in pixels at its scale: so far on each side of the moving part's edge
#: the agreement of a mask with what moves is not judged (half a patch: the medium preset's
#: patches are 8 px on a level of half the resolution it is given, 16 px of it)
MOTION_BAND = 8
#: the residual is in units of the median residual outside that box, or of this many pixels of
#: the frame when that is less (the flow's noise in a still scene)
MOTION_FLOOR = 0.5
#: a box whose moving part
#: (Otsu's split of the log residual) covers less than this share of it, or more than one minus
#: it, has no clear moving object ...
MOVING_LEAST = 0.05
#: ... nor one whose moving part departs from the scene's motion by less than this (its median;
#: in a still scene, at the floor, one pixel: DIS's noise on a flat region is most of that)
MOVING_RESIDUAL = 2.0


def _flow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    import cv2

    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(a, b, None)


def _grey(image_bgr: np.ndarray) -> np.ndarray:
    import cv2

    small = cv2.resize(image_bgr, None, fx=MOTION_SCALE, fy=MOTION_SCALE, interpolation=cv2.INTER_AREA)
    return small if small.ndim == 2 else cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)


def motion_residual(image_bgr: np.ndarray, later: Sequence[np.ndarray],
                    box: tuple[float, float, float, float]) -> np.ndarray | None:
    """How far each pixel's flow from ``image_bgr`` to each frame of ``later`` departs from the
    scene's homography (fitted outside ``box`` grown by :data:`MOTION_MARGIN`), the smallest
    over ``later`` (the object departs on every one of them; the background it covers or
    uncovers, whose flow takes the object's, only on the later ones), in units of the median departure outside that box (at least
    :data:`MOTION_FLOOR` pixels); float32 of the frame's size.  None without later frames, or when too little of the frame lies outside the box to
    fit the scene's motion."""
    import cv2

    if not later:
        return None
    h_img, w_img = image_bgr.shape[:2]
    g0 = _grey(image_bgr)
    h, w = g0.shape
    s = g0.shape[1] / w_img
    x, y, bw, bh = (v * s for v in box)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    outside = ~((xx >= x - MOTION_MARGIN * bw) & (xx < x + (1 + MOTION_MARGIN) * bw)
                & (yy >= y - MOTION_MARGIN * bh) & (yy < y + (1 + MOTION_MARGIN) * bh))
    if outside.sum() < 0.05 * h * w or outside.sum() < 200:
        return None
    step = max(1, int(outside.sum() // 20000))  # enough points for RANSAC, few enough to be quick
    src = np.stack([xx[outside], yy[outside]], 1)[::step]
    grid = np.dstack([xx, yy])
    least = np.full((h, w), np.inf, np.float32)
    for frame in later:
        if frame.shape[:2] != image_bgr.shape[:2]:
            return None
        flow = _flow(g0, _grey(frame))
        H, _ = cv2.findHomography(src, src + flow[outside][::step], cv2.RANSAC, 1.0)
        if H is None:
            return None
        moved = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), H).reshape(h, w, 2)
        least = np.minimum(least, np.linalg.norm(flow - (moved - grid), axis=2))
    least /= max(float(np.median(least[outside])), MOTION_FLOOR * MOTION_SCALE)
    return cv2.resize(least, (w_img, h_img), interpolation=cv2.INTER_LINEAR)


def moving(residual: np.ndarray, rect: tuple[int, int, int, int]) -> np.ndarray | None:
    """The pixels of ``rect = (x, y, w, h)`` that move unlike the scene: Otsu's split of the log
    of ``residual`` (:func:`motion_residual`) within it, as a boolean mask of the frame's size;
    None when there is no clear moving object: the moving part covers less than
    :data:`MOVING_LEAST` of the box or more than ``1 - MOVING_LEAST`` of it, or its median
    residual is below :data:`MOVING_RESIDUAL` (the flow's own noise, a still clip)."""
    import cv2

    x0, y0, w, h = rect
    inside = np.log(residual[y0:y0 + h, x0:x0 + w] + 1e-3)
    lo, hi = np.percentile(inside, (1, 99))
    if hi - lo < 1e-6:
        return None
    q = np.clip((inside - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
    t, split = cv2.threshold(q, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    share = float(np.count_nonzero(split)) / split.size
    if not MOVING_LEAST <= share <= 1.0 - MOVING_LEAST:
        return None
    if float(np.median(residual[y0:y0 + h, x0:x0 + w][split > 0])) < MOVING_RESIDUAL:
        return None
    out = np.zeros(residual.shape, bool)
    out[y0:y0 + h, x0:x0 + w] = split > 0
    return out


def agreement(mask: np.ndarray, moves: np.ndarray, rect: tuple[int, int, int, int]) -> float:
    """How well ``mask`` is what moves within ``rect``: the share of its pixels in the box that
    move (``moves``, :func:`moving`) less the share of the box's other pixels that do, in [-1, 1].
    Pixels within :data:`MOTION_BAND` of the moving part's edge are left out: the flow is
    smoothed over its patches, and there what moves spills onto what does not."""
    import cv2

    x0, y0, w, h = rect
    m, mv = mask[y0:y0 + h, x0:x0 + w] > 0, moves[y0:y0 + h, x0:x0 + w]
    r = int(round(MOTION_BAND / MOTION_SCALE))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    u8 = mv.astype(np.uint8)
    sure = (cv2.dilate(u8, kernel) == 0) | (cv2.erode(u8, kernel) > 0)
    m_in, m_out = m & sure, ~m & sure
    if not m_in.any() or not m_out.any():
        return 0.0
    return float(mv[m_in].mean() - mv[m_out].mean())
