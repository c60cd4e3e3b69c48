"""The object's region: pixel-wise foreground posteriors from colour, and the outline they draw.

CONDENSATION estimates the curve in a shape-space of few degrees of freedom, which keeps the
search robust but cannot follow a shape that changes (a dancer's arms, a dog turning).  After
each frame's estimate the outline is fitted again in the full image, with the estimate as the
prior (AC ch. 8's posterior fit, here pixel by pixel):

- every pixel's colour gives the log-ratio ``L_c = log p(c | object) - log p(c | background)``
  of two colour histograms (Bibby & Reid 2008's pixel-wise posteriors), the object's learned
  inside the template, the background's in a band about it;
- the estimate gives a prior log-odds that falls with the signed distance ``d`` from its
  outline, ``L_s = -d / sigma``, ``sigma`` a fraction of the object's size;
- a pixel is the object's where ``L_c + L_s > 0`` (both smoothed a little so the region's
  boundary does not follow single pixels), in the connected parts that overlap the estimate.

The refined outline is the boundary of that region.  Where colour does not tell object from
background the prior alone decides and the outline is the estimate's.

Its place in a run: a stage after each tracker step (:func:`trackcli.trackers.base.run_tracker`),
which draws the outline (the CSV's outline columns, the recording's ``video/outline``) and
changes nothing of the estimate, its weights or the next frame's prediction.  The terms that
weigh the tracker's hypotheses are the observation model's (:mod:`trackcli.observe.terms`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: histogram bins per colour channel (of 256 levels)
BINS = 16
#: limit of the colour log-ratio, so that one bin cannot outvote the prior by itself
L_MAX = 4.0


def _bin_index(image_bgr: np.ndarray) -> np.ndarray:
    q = (image_bgr.astype(np.uint16) * BINS) >> 8
    return (q[..., 0] * BINS + q[..., 1]) * BINS + q[..., 2]


@dataclass
class ColourModel:
    """Object and background colour histograms (normalised, of ``BINS**3`` bins)."""

    fg: np.ndarray
    bg: np.ndarray

    @classmethod
    def learn(cls, image_bgr: np.ndarray, mask: np.ndarray, *, band: float = 0.5) -> "ColourModel":
        """From an image and the object's mask: the inside, and a band of ``band`` x its size about it."""
        import cv2

        m = mask.astype(bool)
        idx = _bin_index(image_bgr)
        size = math.sqrt(max(np.count_nonzero(m), 1))
        r = max(3, int(round(band * size)))
        ring = cv2.dilate(m.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
        ring = ring.astype(bool) & ~m
        return cls(_hist(idx[m]), _hist(idx[ring]))

    def log_ratio(self, image_bgr: np.ndarray) -> np.ndarray:
        """``L_c`` of every pixel, float32 in [-L_MAX, L_MAX]."""
        lut = np.clip(np.log(self.fg + 1e-4) - np.log(self.bg + 1e-4), -L_MAX, L_MAX).astype(np.float32)
        return lut[_bin_index(image_bgr)]

    def blend(self, other: "ColourModel", rate: float) -> None:
        """Move toward ``other`` by ``rate`` (a slow update from a frame held with confidence)."""
        self.fg = (1 - rate) * self.fg + rate * other.fg
        self.bg = (1 - rate) * self.bg + rate * other.bg


def _hist(idx: np.ndarray) -> np.ndarray:
    h = np.bincount(idx.ravel(), minlength=BINS ** 3).astype(np.float64)
    return h / max(h.sum(), 1.0)


def polygon_fill(points: np.ndarray, shape: tuple[int, int], offset=(0, 0)) -> np.ndarray:
    import cv2

    m = np.zeros(shape, np.uint8)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2) - np.asarray(offset, dtype=float)
    if len(p) >= 3 and np.all(np.isfinite(p)):
        cv2.fillPoly(m, [np.rint(p * 16).astype(np.int32)], 1, lineType=cv2.LINE_8, shift=4)
    return m


@dataclass(frozen=True)
class RegionFit:
    mask: np.ndarray           # bool, the ROI's
    origin: tuple[int, int]    # (x0, y0) of the ROI in the frame
    outline: np.ndarray | None  # (P, 2) frame coordinates, None when the estimate stands
    agreement: float           # IoU of the region with the estimate's fill


def refine(image_bgr: np.ndarray, estimate: np.ndarray, model: ColourModel, *, sigma: float = 0.25,
           margin: float = 0.5, smooth: float = 1.5, others: tuple = ()) -> RegionFit:
    """The region the colour posterior and the estimate's prior agree on (module docstring).

    ``others``: more priors ``(outline, weight)``, their log-odds added to the estimate's."""
    import cv2

    h, w = image_bgr.shape[:2]
    est = np.asarray(estimate, dtype=float)
    allp = np.vstack([est] + [np.asarray(o, dtype=float) for o, _ in others])
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    size = math.sqrt(max((hi - lo).prod(), 1.0))
    pad = margin * size + 4
    x0, y0 = int(max(0, math.floor(lo[0] - pad))), int(max(0, math.floor(lo[1] - pad)))
    x1, y1 = int(min(w, math.ceil(hi[0] + pad) + 1)), int(min(h, math.ceil(hi[1] + pad) + 1))
    if x1 - x0 < 4 or y1 - y0 < 4:
        return RegionFit(np.zeros((0, 0), bool), (x0, y0), None, 0.0)
    roi = image_bgr[y0:y1, x0:x1]
    inside = polygon_fill(est, (y1 - y0, x1 - x0), (x0, y0))
    area = float(np.count_nonzero(inside))
    if area < 9:
        return RegionFit(inside.astype(bool), (x0, y0), None, 0.0)
    obj = math.sqrt(area)
    d_out = cv2.distanceTransform(1 - inside, cv2.DIST_L2, 3)
    d_in = cv2.distanceTransform(inside, cv2.DIST_L2, 3)
    signed = d_out - d_in
    L = model.log_ratio(roi)
    if smooth > 0:
        L = cv2.GaussianBlur(L, (0, 0), smooth)
    post = L - signed / (sigma * obj)
    for o, wt in others:
        ins = polygon_fill(o, inside.shape, (x0, y0))
        sd = cv2.distanceTransform(1 - ins, cv2.DIST_L2, 3) - cv2.distanceTransform(ins, cv2.DIST_L2, 3)
        post = post - wt * sd / (sigma * obj)
    region = (post > 0).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(region, connectivity=8)
    keep = np.zeros(n, bool)
    if n > 1:
        overlap = np.bincount(lab[inside.astype(bool)], minlength=n)
        keep[1:] = overlap[1:] > 0.02 * area
    region = keep[lab]
    if not region.any():
        return RegionFit(region, (x0, y0), None, 0.0)
    u = region.astype(np.uint8)
    contours, _ = cv2.findContours(u, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    c = max(contours, key=cv2.contourArea)[:, 0, :].astype(float) + (x0, y0)
    inter = np.count_nonzero(region & inside.astype(bool))
    agree = inter / max(np.count_nonzero(region | inside.astype(bool)), 1)
    return RegionFit(region, (x0, y0), c, float(agree))


#: the frames' scale for the optical flow (DIS at half resolution: 1.6 ms a frame of 854x480)
FLOW_SCALE = 0.5


class FlowPrior:
    """Moves the last frame's outline by the dense optical flow between the frames (DIS).

    The flow is a prior for the refined outline that follows what the shape-space cannot: a
    limb that swings, a body that turns.  Its errors add up from frame to frame, so it is
    used together with the tracker's estimate, never alone (:class:`OutlineRefiner`).
    """

    def __init__(self) -> None:
        import cv2

        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
        self._prev: np.ndarray | None = None
        self._flow: np.ndarray | None = None

    def push(self, image_bgr: np.ndarray) -> None:
        """The next frame: the flow from the last one to it."""
        import cv2

        small = cv2.resize(image_bgr, None, fx=FLOW_SCALE, fy=FLOW_SCALE, interpolation=cv2.INTER_AREA)
        grey = small if small.ndim == 2 else cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)
        self._flow = None if self._prev is None or self._prev.shape != grey.shape else self._dis.calc(self._prev, grey, None)
        self._prev = grey

    def move(self, points: np.ndarray) -> np.ndarray | None:
        """``points`` (P, 2) of the last frame carried to this one; None before a flow exists."""
        import cv2

        if self._flow is None:
            return None
        h, w = self._flow.shape[:2]
        p = np.clip(np.asarray(points, dtype=np.float64) * FLOW_SCALE, 0, [w - 1, h - 1]).astype(np.float32)
        d = cv2.remap(self._flow, p[:, :1], p[:, 1:], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[:, 0, :]
        return np.asarray(points, dtype=np.float64) + d.astype(np.float64) / FLOW_SCALE


def resample_closed(points: np.ndarray, n: int) -> np.ndarray:
    """``n`` points equally spaced along a closed polygon, clockwise on screen from its top."""
    p = np.asarray(points, dtype=float)
    x, y = p[:, 0], p[:, 1]
    if float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) < 0:
        p = p[::-1]
    p = np.roll(p, -int(np.argmin(p[:, 1])), axis=0)
    q = np.vstack([p, p[:1]])
    t = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(q, axis=0).T))])
    u = np.linspace(0.0, t[-1], n, endpoint=False)
    return np.column_stack([np.interp(u, t, q[:, 0]), np.interp(u, t, q[:, 1])])


class OutlineRefiner:
    """The outline of every frame fitted again from the tracker's estimate (module docstring).

    The first frame's estimate (the template) teaches the colour model, learned again from
    the refined first-frame region; each later frame's prior is the estimate and, with
    ``flow``, the last refined outline moved by the optical flow, their log-odds added.
    """

    def __init__(self, settings) -> None:
        self.settings = settings
        self.model: ColourModel | None = None
        self.flow = FlowPrior() if settings.flow else None
        self.last: np.ndarray | None = None

    def __call__(self, image_bgr: np.ndarray, estimate: np.ndarray) -> RegionFit | None:
        s = self.settings
        image = image_bgr if image_bgr.ndim == 3 else np.repeat(image_bgr[..., None], 3, axis=2)
        if self.flow is not None:
            self.flow.push(image)
        est = np.asarray(estimate, dtype=float)
        if not np.all(np.isfinite(est)) or len(est) < 3:
            return None
        if self.model is None:
            m = polygon_fill(est, image.shape[:2]).astype(bool)
            if not m.any():
                return None
            self.model = ColourModel.learn(image, m)
            fit = refine(image, est, self.model, sigma=s.prior_width)
            if fit.outline is not None:  # the colours again, from the region the template refined to
                m2 = polygon_fill(fit.outline, image.shape[:2]).astype(bool)
                if m2.any():
                    self.model = ColourModel.learn(image, m2)
        others = ()
        if self.flow is not None and self.last is not None:
            moved = self.flow.move(self.last)
            if moved is not None:
                others = ((moved, 1.0),)
        fit = refine(image, est, self.model, sigma=s.prior_width, others=others)
        self.last = fit.outline if fit.outline is not None else est
        return fit


def outline_refiner(settings, space) -> OutlineRefiner | None:
    """The run's :class:`OutlineRefiner` (``outline.refine``), or None: refinement off, no
    outline columns to draw (``output.outline_points`` 0), or an open curve."""
    if settings.outline.refine and settings.output.outline_points and space.basis.closed:
        return OutlineRefiner(settings.outline)
    return None
