"""Places where the frame still shows what the first frame showed there.

With a still camera, a look-alike that stands in the scene on the first frame (a copy of the
object printed on the wall, a second leaf on the same plant) is part of the background: where
a later frame shows the first frame's pixels, they are explained by the scene as it was, and
a curve there is not on the object, which was elsewhere when the first frame was taken.

:class:`StillScene` compares each frame with the first after matching their exposure (a gain
and an offset per channel, fitted over the frame), and marks the pixels that kept their
colour.  A curve is judged on the pixels just inside its outline, where the object would be:
its *stillness* is the share of them that kept the first frame's colour.  The pixels of the
object's own place on the first frame are left out (the object may stand still, or come
back).  With a moving camera, or when the light changes unevenly, few pixels keep their
colour and the test says nothing.

The same fit tells when the light changed over the whole scene (clouds, a camera's automatic
exposure): with a still camera most of a colour frame agrees with it.  The tracker then reads its
colour model, learned on the first frame, on the frame brought back to the first frame's
exposure (:func:`in_first_light`); a colour histogram's bins are fixed, and an object that
brightens by a fifth can cross into bins where the model has only background.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit

from trackcli.observe.appearance import is_grey

#: a pixel kept its colour when every channel is within this many levels of the first frame's
#: (after matching the exposure and a 3 x 3 mean)
KEPT_LEVELS = 12.0
#: the stillness of a curve counts from this share of kept pixels ...
STILL_FROM = 0.5
#: ... fully from this share
STILL_FULL = 0.85
#: a curve with fewer than this share of its points usable (in the frame, off the object's own
#: place) is not judged
USABLE_MIN = 0.4
#: how far inside the outline a curve's pixels are read, in object sizes (at least 2 px)
INSIDE = 0.06
#: the exposure is fitted on about this many pixels, spread evenly
FIT_PIXELS = 3000
#: frames are compared reduced to at most about this many pixels (640 x 360)
WORK_PIXELS = 640 * 360

#: the exposure fitted on a colour frame is taken as a change of the light over the whole scene
#: when at least this share of the pixels it was fitted on agree with it in every channel: with
#: a still camera most of the scene does (0.77-0.98 on the dev clips), with a moving one only
#: its uniform regions (at most 0.72).  On grey frames one channel agreeing says less: a moving
#: camera's grey frames agreed up to 0.88, and the grey level of a large object's reduced frame
#: up to 0.95, as much as still cameras' (0.94 and more), so they are never corrected ...
EXPOSURE_SHARE = 0.75
#: ... and every channel's gain is inside these bounds (the fit is held to [0.5, 2]; a gain at
#: its bounds is no fit)
EXPOSURE_GAINS = (0.55, 1.8)

#: bits of the map
_KEPT, _OWN = 1, 2


def _smooth(frame: np.ndarray, k: int) -> np.ndarray:
    """The frame reduced by ``k`` (a power of 2; area average) and averaged over 3 x 3 pixels,
    uint8 (h, w, c)."""
    img = np.asarray(frame)
    if img.dtype != np.uint8:
        img = np.clip(img, 0, 255).astype(np.uint8)
    h, w = img.shape[:2]
    while k > 1:  # halved (OpenCV's fast path for a factor of 2), an odd last row or column left out
        h, w = max(1, h // 2), max(1, w // 2)
        img = cv2.resize(img[: 2 * h, : 2 * w], (w, h), interpolation=cv2.INTER_AREA)
        k //= 2
    out = cv2.blur(img, (3, 3))
    return out if out.ndim == 3 else out[:, :, None]


@njit(cache=True, nogil=True)
def _exposure(now, first, step, levels):  # pragma: no cover - compiled
    """Gain and offset per channel that map ``first`` onto ``now`` (uint8, (h, w, c)) where
    most pixels agree: least squares on every ``step``-th pixel in each direction, then twice
    again on those whose every channel fits within ``levels``."""
    h, w, c = first.shape
    gain = np.ones(c)
    offset = np.zeros(c)
    for it in range(3):
        n = 0.0
        sx = np.zeros(c)
        sy = np.zeros(c)
        sxx = np.zeros(c)
        sxy = np.zeros(c)
        for y in range(0, h, step):
            for x in range(0, w, step):
                if it > 0:
                    fits = True
                    for ch in range(c):
                        if abs(now[y, x, ch] - (gain[ch] * first[y, x, ch] + offset[ch])) >= levels:
                            fits = False
                            break
                    if not fits:
                        continue
                n += 1.0
                for ch in range(c):
                    a = float(first[y, x, ch])
                    b = float(now[y, x, ch])
                    sx[ch] += a
                    sy[ch] += b
                    sxx[ch] += a * a
                    sxy[ch] += a * b
        if n < 16.0:
            return np.ones(c), np.zeros(c)
        for ch in range(c):
            mx = sx[ch] / n
            my = sy[ch] / n
            vx = sxx[ch] / n - mx * mx
            g = (sxy[ch] / n - mx * my) / vx if vx > 1e-3 else 1.0
            g = min(max(g, 0.5), 2.0)
            gain[ch] = g
            offset[ch] = my - g * mx
    return gain, offset


@njit(cache=True, nogil=True)
def _agreement(now, first, step, levels, gain, offset):  # pragma: no cover - compiled
    """The share of every ``step``-th pixel in each direction whose every channel of ``now`` is
    within ``levels`` of ``gain * first + offset`` (float32 arithmetic)."""
    h, w, c = first.shape
    g = gain.astype(np.float32)
    o = offset.astype(np.float32)
    lim = np.float32(levels)
    n = 0
    total = 0
    for y in range(0, h, step):
        for x in range(0, w, step):
            total += 1
            fits = True
            for ch in range(c):
                if abs(np.float32(now[y, x, ch]) - (np.float32(first[y, x, ch]) * g[ch] + o[ch])) >= lim:
                    fits = False
                    break
            if fits:
                n += 1
    return n / max(total, 1)


@njit(cache=True, nogil=True)
def _kept(still_map, pts, nrm, d, inv_k, m, kept, usable):  # pragma: no cover - compiled
    """For curves of ``m`` points (flattened ``pts``, ``nrm``: (n m, 2) float32): how many of
    the pixels ``d`` inside each outline kept their colour, and how many are usable."""
    h, w = still_map.shape
    for i in range(kept.shape[0]):
        nk = 0
        nu = 0
        for j in range(i * m, (i + 1) * m):
            x = (pts[j, 0] - d * nrm[j, 0]) * inv_k
            y = (pts[j, 1] - d * nrm[j, 1]) * inv_k
            if not (x > -0.5 and x < w - 0.5 and y > -0.5 and y < h - 0.5):
                continue
            v = still_map[int(y + 0.5), int(x + 0.5)]
            if v & _OWN:
                continue
            nu += 1
            if v & _KEPT:
                nk += 1
        kept[i] = nk
        usable[i] = nu


class StillScene:
    """The first frame, to compare later frames with.

    Parameters
    ----------
    first : ndarray (h, w) or (h, w, 3)
        The first frame.
    own : ndarray (h, w) of bool or 0/1
        The object's own place on the first frame (its mask): never judged.
    size : float
        The object's size (px).  Frames are compared reduced by a power of 2: to at most
        :data:`WORK_PIXELS` pixels, and so that a large object spans 32 to 64.
    area : (x0, y0, x1, y1), optional
        The picture between letterbox or pillarbox bars
        (:func:`~trackcli.observe.appearance.picture_area`): the bars are never judged either.
    """

    def __init__(self, first: np.ndarray, own: np.ndarray, size: float,
                 area: tuple[int, int, int, int] | None = None):
        h, w = np.asarray(first).shape[:2]
        k = max(1.0, size / 64, math.sqrt(h * w / WORK_PIXELS))
        self.k = 2 ** math.ceil(math.log2(k) - 1e-9)
        self.size = float(size)
        self.first = _smooth(first, self.k)
        self.grey = self.first.shape[2] == 1 or is_grey(first)  # one channel or three alike: no exposure
        h, w = self.first.shape[:2]
        own = np.asarray(own, dtype=np.uint8)
        own = cv2.resize(own, (w, h), interpolation=cv2.INTER_NEAREST) if own.shape != (h, w) else own
        grow = 2 * max(1, int(round(0.05 * size / self.k))) + 1
        own = cv2.dilate(own, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (grow, grow)))
        if area is not None:  # letterbox or pillarbox bars: black on every frame, and no evidence
            x0, y0, x1, y1 = (int(round(v / self.k)) for v in area)
            own[:y0] = 1
            own[y1:] = 1
            own[:, :x0] = 1
            own[:, x1:] = 1
        self.own_bits = np.where(own > 0, _OWN, 0).astype(np.uint8)

    def compare(self, frame: np.ndarray) -> np.ndarray | None:
        """The map of a later frame (the same size and channels as the first; else None): bit 0
        set where the pixel kept the first frame's colour, bit 1 on the object's own place.
        Reads only what the constructor made, so any thread may call it."""
        return self.measure(frame)[0]

    def measure(self, frame: np.ndarray) -> tuple[np.ndarray | None, tuple[np.ndarray, np.ndarray] | None]:
        """``(map, exposure)``: the map of :meth:`compare`, and the frame's exposure against the
        first frame's, ``(gain, offset)`` per channel (the frame is ``gain * first + offset``),
        when most of the scene agrees with it (:data:`EXPOSURE_SHARE`, :data:`EXPOSURE_GAINS`):
        a change of the light seen by a still camera; else (and on grey frames) None.  Any
        thread may call it."""
        now = _smooth(frame, self.k)
        if now.shape != self.first.shape:
            return None, None
        step = max(1, int(round(math.sqrt(now.shape[0] * now.shape[1] / FIT_PIXELS))))
        gain, offset = _exposure(now, self.first, step, 2.0 * KEPT_LEVELS)
        agree = _agreement(now, self.first, step, 2.0 * KEPT_LEVELS, gain, offset)
        trusted = (not self.grey and agree >= EXPOSURE_SHARE
                   and bool(np.all((gain > EXPOSURE_GAINS[0]) & (gain < EXPOSURE_GAINS[1]))))
        return self._map(now, gain, offset), ((gain, offset) if trusted else None)

    def _map(self, now: np.ndarray, gain: np.ndarray, offset: np.ndarray) -> np.ndarray:
        c = now.shape[2]
        if c == 1:  # the first frame in this frame's exposure
            expected = cv2.convertScaleAbs(self.first[:, :, 0], alpha=float(gain[0]), beta=float(offset[0]))
            now = now[:, :, 0]
        else:
            m = np.zeros((c, c + 1), np.float32)
            m[np.arange(c), np.arange(c)] = gain
            m[:, c] = offset
            expected = cv2.transform(self.first, m)
        lim = int(KEPT_LEVELS)
        kept = cv2.inRange(cv2.absdiff(now, expected), (0,) * c, (lim,) * c)  # 255 where every channel kept
        return cv2.bitwise_or(cv2.threshold(kept, 0, _KEPT, cv2.THRESH_BINARY)[1], self.own_bits)

    def kept_share(self, still_map: np.ndarray | None, points: np.ndarray,
                   normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(kept, usable)`` of curves (..., M, 2) on a frame's map (:meth:`compare`): the share
        of the pixels just inside each outline that kept the first frame's colour, among those
        usable (in the frame, off the object's own place), and the usable share of the M points."""
        pts = np.asarray(points, dtype=np.float32)
        lead, m = pts.shape[:-2], pts.shape[-2]
        if still_map is None:
            return np.zeros(lead), np.zeros(lead)
        flat = np.ascontiguousarray(pts.reshape(-1, 2))
        nrm = np.ascontiguousarray(np.asarray(normals, dtype=np.float32).reshape(-1, 2))
        count = flat.shape[0] // max(m, 1)
        kept, usable = np.empty(count, np.int64), np.empty(count, np.int64)
        _kept(still_map, flat, nrm, np.float32(max(2.0, INSIDE * self.size)), np.float32(1.0 / self.k), m,
              kept, usable)
        return (kept / np.maximum(usable, 1)).reshape(lead), (usable / m).reshape(lead)

    def stillness(self, still_map: np.ndarray | None, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """0 (the curve is on something that was not there on the first frame) to 1 (it lies on
        the first frame's scene), for curves (..., M, 2) with their unit normals, on a frame's
        map (:meth:`compare`)."""
        kept, usable = self.kept_share(still_map, points, normals)
        s = np.clip((kept - STILL_FROM) / (STILL_FULL - STILL_FROM), 0.0, 1.0)
        return np.where(usable >= USABLE_MIN, s, 0.0)
