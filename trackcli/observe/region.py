"""The object's region: pixel-wise foreground posteriors from colour, and the outline they draw.

CONDENSATION estimates the curve in a shape-space of few degrees of freedom, which keeps the
search robust but cannot follow a shape that changes (a dancer's arms, a dog turning).  After
each frame's estimate the outline is fitted again in the full image, with the estimate as the
prior (AC ch. 8's posterior fit, here pixel by pixel):

- every pixel's colour gives the log-ratio ``L_c = log p(c | object) - log p(c | background)``
  of two colour histograms (Bibby & Reid 2008's pixel-wise posteriors), the object's learned
  inside the template, the background's in a band about it;
- the estimate gives a prior log-odds that falls with the signed distance ``d`` from its
  outline, ``L_s = -d / sigma``, ``sigma`` a fraction of the object's size (the largest of its
  priors': an estimate that has shrunk onto a part of the object does not narrow it);
- a pixel is the object's where ``L_c + L_s > 0`` (both smoothed a little so the region's
  boundary does not follow single pixels), in the connected parts that overlap the estimate.

The refined outline is the boundary of that region, its pieces joined into one polygon.  Where
colour does not tell object from background the prior alone decides and the outline is the
estimate's.

:class:`OutlineRefiner` runs this over a clip: it learns the colours from the region the
template was drawn from, moves the last outline to each new frame by dense optical flow (a
second prior), lets the colours follow the object slowly on frames held with confidence, and
says when a frame's region is evidence enough that the object is held (:meth:`~OutlineRefiner.holds`,
the ``lost`` verdict's second opinion).

Its place in a run: a stage after each tracker step (:func:`trackcli.trackers.base.run_tracker`),
which draws the outline (the CSV's outline columns, the recording's ``video/outline``) and
changes nothing of the estimate, its weights or the next frame's prediction.  The terms that
weigh the tracker's hypotheses are the observation model's (:mod:`trackcli.observe.terms`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

#: histogram bins per colour channel (of 256 levels)
BINS = 16
#: limit of the colour log-ratio, so that one bin cannot outvote the prior by itself
L_MAX = 4.0



def _bin_index(image_bgr: np.ndarray) -> np.ndarray:
    if image_bgr.dtype == np.uint8:  # the same bins in fewer array passes
        q = image_bgr >> 4
        return (q[..., 0].astype(np.uint16) << 8) | ((q[..., 1] << 4) | q[..., 2])
    q = (image_bgr.astype(np.uint16) * BINS) >> 8
    return (q[..., 0] * BINS + q[..., 1]) * BINS + q[..., 2]


def _compiled(image_bgr: np.ndarray) -> bool:
    """Whether the compiled look-up (:func:`trackcli.observe.kernels.bgr_bin_lookup`) reads ``image_bgr``."""
    return image_bgr.dtype == np.uint8 and image_bgr.ndim == 3 and image_bgr.shape[2] == 3


@dataclass
class ColourModel:
    """Object and background colour histograms (normalised, of ``BINS**3`` bins)."""

    fg: np.ndarray
    bg: np.ndarray
    _lut: tuple = dataclasses.field(default=(None, None, None), init=False, repr=False, compare=False)

    def lut(self) -> np.ndarray:
        """``L_c`` of every bin, float32 (made again only when ``fg`` or ``bg`` is another array)."""
        fg, bg, lut = self._lut
        if fg is not self.fg or bg is not self.bg:
            lut = np.clip(np.log(self.fg + 1e-4) - np.log(self.bg + 1e-4), -L_MAX, L_MAX).astype(np.float32)
            self._lut = (self.fg, self.bg, lut)
        return lut

    @classmethod
    def learn(cls, image_bgr: np.ndarray, mask: np.ndarray, *, band: float = 0.5) -> "ColourModel":
        """From an image and the object's mask: the inside, and a band of ``band`` x its size about it."""
        m = mask.astype(bool)
        idx = _bin_index(image_bgr)
        size = math.sqrt(max(np.count_nonzero(m), 1))
        r = max(3, int(round(band * size)))
        ring = grow(m, r) & ~m
        return cls(_hist(idx[m]), _hist(idx[ring]))

    def log_ratio(self, image_bgr: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """``L_c`` of every pixel, float32 in [-L_MAX, L_MAX]; with ``mask`` (bool, the image's
        height and width) only at its pixels, in row order: ``log_ratio(image)[mask]``."""
        lut = self.lut()
        if not _compiled(image_bgr):
            L = lut[_bin_index(image_bgr)]
            return L if mask is None else L[mask]
        from trackcli.observe.kernels import bgr_bin_lookup, bgr_bin_lookup_masked

        if mask is None:
            out = np.empty(image_bgr.shape[:2], np.float32)
            bgr_bin_lookup(image_bgr, lut, out)
            return out
        mask = np.asarray(mask, dtype=bool)
        out = np.empty(np.count_nonzero(mask), np.float32)
        bgr_bin_lookup_masked(image_bgr, mask, lut, out)
        return out

    def blend(self, other: "ColourModel", rate: float) -> None:
        """Move toward ``other`` by ``rate`` (a slow update from a frame held with confidence)."""
        self.fg = (1 - rate) * self.fg + rate * other.fg
        self.bg = (1 - rate) * self.bg + rate * other.bg


def grow(mask: np.ndarray, r: float) -> np.ndarray:
    """``mask`` grown by ``r`` px (the pixels within ``r`` of it, Euclidean), bool: a dilation by a
    disc, whose time does not grow with the disc as a structuring element's does."""
    import cv2

    m = np.asarray(mask).astype(bool)
    return cv2.distanceTransform((~m).astype(np.uint8), cv2.DIST_L2, 3) <= r


def _hist(idx: np.ndarray) -> np.ndarray:
    h = np.bincount(idx.ravel(), minlength=BINS ** 3).astype(np.float64)
    return h / max(h.sum(), 1.0)


def mask_polygons(mask: np.ndarray, least: int = 9) -> list[np.ndarray]:
    """A binary mask as polygons ``(P, 2)`` of boundary pixels' centres (vertices on straight runs
    left out): the outer boundary of each piece of at least ``least`` px, largest first, then the
    boundaries of the holes in them of as many px; :func:`region_fill` fills them back."""
    import cv2

    m = (np.asarray(mask) > 0).astype(np.uint8)
    contours, hierarchy = cv2.findContours(m, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return []
    outer = [c for c, h in zip(contours, hierarchy[0]) if h[3] < 0 and len(c) >= 3 and cv2.contourArea(c) >= least]
    holes = [c for c, h in zip(contours, hierarchy[0]) if h[3] >= 0 and len(c) >= 3 and cv2.contourArea(c) >= least]
    outer.sort(key=cv2.contourArea, reverse=True)
    holes.sort(key=cv2.contourArea, reverse=True)
    return [c[:, 0, :].astype(float) for c in outer + holes] if outer else []


def region_fill(pieces, shape: tuple[int, int]) -> np.ndarray:
    """The polygons ``pieces`` (of :func:`mask_polygons`) filled on an image of ``shape``, bool: a
    pixel is the region's when it is inside an odd number of them (a hole's boundary inside a piece's)."""
    m = np.zeros(shape, bool)
    for piece in pieces:
        m ^= polygon_fill(piece, shape).astype(bool)
    return m


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
    contrast: float = math.nan  # how the outline's inside stands out in the object's colours (:func:`contrast`)
    scale: float = 1.0         # the ROI's pixels per frame pixel (refine's work_size)
    pieces: tuple = ()         # the outer boundaries of the region's pieces, frame coordinates, largest first
    covers: float = 0.0        # the share of the estimate's fill inside the region


def refine(image_bgr: np.ndarray, estimate: np.ndarray, model: ColourModel, *, sigma: float = 0.25,
           margin: float = 0.5, smooth: float = 1.5, others: tuple = (), work_size: float = math.inf) -> RegionFit:
    """The region the colour posterior and the estimate's prior agree on (module docstring).

    ``others``: more priors ``(pieces, weight)``, ``pieces`` a polygon ``(P, 2)`` or a list of
    them (a region in pieces), their log-odds added to the estimate's; every prior's width is
    ``sigma`` x the object's size, the square root of the largest of their areas.  The region's connected
    parts kept are those that overlap the estimate; the outline joins them (:func:`joined_outline`:
    a person's legs that a shadow or a pole cuts off are the person's).
    ``work_size``: an object larger than this (px, the square root of its priors' box) is
    refined on the image shrunk to this size (the region's mask is then of the shrunk image,
    ``RegionFit.scale`` the factor; the outline is in the frame's pixels)."""
    import cv2

    h, w = image_bgr.shape[:2]
    est = np.asarray(estimate, dtype=float)
    others = [([o] if isinstance(o, np.ndarray) and o.ndim == 2 else list(o), wt) for o, wt in others]
    allp = np.vstack([est] + [np.asarray(p, dtype=float) for o, _ in others for p in o])
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    size = math.sqrt(max((hi - lo).prod(), 1.0))
    pad = margin * size + 4
    x0, y0 = int(max(0, math.floor(lo[0] - pad))), int(max(0, math.floor(lo[1] - pad)))
    x1, y1 = int(min(w, math.ceil(hi[0] + pad) + 1)), int(min(h, math.ceil(hi[1] + pad) + 1))
    if x1 - x0 < 4 or y1 - y0 < 4:
        return RegionFit(np.zeros((0, 0), bool), (x0, y0), None, 0.0)
    roi = image_bgr[y0:y1, x0:x1]
    f = min(1.0, work_size / size)
    if f < 1.0:
        roi = cv2.resize(roi, (max(4, round((x1 - x0) * f)), max(4, round((y1 - y0) * f))), interpolation=cv2.INTER_AREA)
        f = roi.shape[1] / (x1 - x0)

    def shrink(p: np.ndarray) -> np.ndarray:  # frame pixels -> the ROI's (pixel centres kept)
        return (np.asarray(p, dtype=float) - (x0, y0) + 0.5) * f - 0.5

    def grow_back(p: np.ndarray) -> np.ndarray:  # the ROI's pixels -> the frame's
        return (np.asarray(p, dtype=float) + 0.5) / f - 0.5 + (x0, y0)

    inside = polygon_fill(shrink(est), roi.shape[:2])
    area = float(np.count_nonzero(inside))
    if area < 9:
        return RegionFit(inside.astype(bool), (x0, y0), None, 0.0, scale=f)
    obj = math.sqrt(area)
    d_out = cv2.distanceTransform(1 - inside, cv2.DIST_L2, 3)
    d_in = cv2.distanceTransform(inside, cv2.DIST_L2, 3)
    signed = d_out - d_in
    L = model.log_ratio(roi)
    if smooth > 0:
        L = cv2.GaussianBlur(L, (0, 0), max(0.5, smooth * f))
    fills = []
    for o, wt in others:
        ins = np.zeros(inside.shape, np.uint8)
        for piece in o:
            ins |= polygon_fill(shrink(piece), inside.shape)
        fills.append((ins, wt))
    if fills:  # the object's size: the largest of its priors' (an estimate shrunk onto a part
        # of the object, a car's wheel, would otherwise pull the outline after it)
        obj = math.sqrt(max([area] + [float(np.count_nonzero(i)) for i, _ in fills]))
    post = L - signed / (sigma * obj)
    for ins, wt in fills:
        sd = cv2.distanceTransform(1 - ins, cv2.DIST_L2, 3) - cv2.distanceTransform(ins, cv2.DIST_L2, 3)
        post = post - wt * sd / (sigma * obj)
    region = (post > 0).astype(np.uint8)
    n, lab = cv2.connectedComponents(region, connectivity=8)
    keep = np.zeros(n, bool)
    if n > 1:
        overlap = np.bincount(lab[inside.astype(bool)], minlength=n)
        keep[1:] = overlap[1:] > 0.02 * area
    region = keep[lab]
    if not region.any():
        return RegionFit(region, (x0, y0), None, 0.0, scale=f)
    pieces = outer_pieces(region, least=max(9.0, PIECE_LEAST * area))
    if not pieces:
        return RegionFit(region, (x0, y0), None, 0.0, scale=f)
    c = grow_back(joined_outline(pieces))
    inter = np.count_nonzero(region & inside.astype(bool))
    agree = inter / max(np.count_nonzero(region | inside.astype(bool)), 1)
    return RegionFit(region, (x0, y0), c, float(agree), scale=f, pieces=tuple(grow_back(p) for p in pieces),
                     covers=inter / area)


#: the least area of a piece of the region (a share of the estimate's) that the outline takes in
PIECE_LEAST = 0.02


def outer_pieces(mask: np.ndarray, least: float = 9.0) -> list[np.ndarray]:
    """The outer boundaries of a mask's pieces of at least ``least`` px, largest first (every
    boundary pixel, as :func:`cv2.findContours` gives them; holes left out)."""
    import cv2

    contours, _ = cv2.findContours(np.asarray(mask).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pieces = [c for c in contours if len(c) >= 3 and cv2.contourArea(c) >= least]
    pieces.sort(key=cv2.contourArea, reverse=True)
    return [c[:, 0, :].astype(float) for c in pieces]


def joined_outline(pieces: list[np.ndarray]) -> np.ndarray:
    """One closed polygon around several pieces (polygons), joined by the shortest bridges
    between them (a minimum spanning tree of their nearest points), each crossed there and back:
    its fill is the pieces' (and the bridges' lines).  One piece: itself."""
    if len(pieces) == 1:
        return pieces[0]
    k = len(pieces)
    sub = [p[:: max(1, len(p) // 200)] for p in pieces]  # nearest points, on at most 200 of each
    dist = np.full((k, k), np.inf)
    near: dict[tuple[int, int], tuple[int, int]] = {}
    for a in range(k):
        for b in range(a + 1, k):
            d = np.hypot(*(sub[a][:, None, :] - sub[b][None, :, :]).transpose(2, 0, 1))
            i, j = np.unravel_index(int(np.argmin(d)), d.shape)
            dist[a, b] = dist[b, a] = d[i, j]
            near[(a, b)] = (int(i) * max(1, len(pieces[a]) // 200), int(j) * max(1, len(pieces[b]) // 200))
            near[(b, a)] = near[(a, b)][::-1]
    # Prim's tree from the largest piece; then a walk around the tree: each piece's boundary
    # from where it is entered, with its children's walks spliced in at their bridges
    tree: dict[int, list[int]] = {a: [] for a in range(k)}
    inside, best, parent = {0}, dist[0].copy(), np.zeros(k, int)
    while len(inside) < k:
        b = min((i for i in range(k) if i not in inside), key=lambda i: best[i])
        inside.add(b)
        tree[int(parent[b])].append(b)
        for i in range(k):
            if i not in inside and dist[b, i] < best[i]:
                best[i], parent[i] = dist[b, i], b

    def walk(a: int, start: int) -> list[np.ndarray]:
        # the boundary from ``start`` round to it, in runs between the places a child is spliced
        # in: the run up to that place (it included), the child's walk, that place again
        p = np.roll(pieces[a], -start, axis=0)
        at: dict[int, list[int]] = {}
        for c in tree[a]:
            at.setdefault((near[(a, c)][0] - start) % len(p), []).append(c)
        out, done = [], 0
        for step in sorted(at):
            out.append(p[done:step + 1])
            for c in at[step]:
                out.extend(walk(c, near[(a, c)][1]))
                out.append(p[step:step + 1])
            done = step + 1
        out.append(p[done:])
        return out

    return np.concatenate(walk(0, 0))


#: the band about a region whose colours :func:`contrast` compares with its inside, in object sizes
CONTRAST_BAND = 0.25


def contrast(image_bgr: np.ndarray, outline: np.ndarray, model: ColourModel) -> float:
    """How the inside of ``outline`` stands out from its surroundings in ``model``'s colours: the
    mean colour log-ratio ``L_c`` inside less its mean in a band :data:`CONTRAST_BAND` x the
    region's size wide about it (NaN for an outline of no area).  An outline on the object is a
    blob of its colours in others (4-5 on held frames of the DAVIS train sequences); one on the
    background, or on part of the object and part of the background, stands out less."""
    h, w = image_bgr.shape[:2]
    p = np.asarray(outline, dtype=float)
    if len(p) < 3 or not np.all(np.isfinite(p)):
        return math.nan
    x, y = p[:, 0], p[:, 1]
    if abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))) < 2.0:  # no area
        return math.nan
    lo, hi = p.min(axis=0), p.max(axis=0)
    r = max(2, int(round(CONTRAST_BAND * math.sqrt(max(float(np.prod(hi - lo)), 1.0)))))
    x0, y0 = int(max(0, math.floor(lo[0]) - r - 1)), int(max(0, math.floor(lo[1]) - r - 1))
    x1, y1 = int(min(w, math.ceil(hi[0]) + r + 2)), int(min(h, math.ceil(hi[1]) + r + 2))
    if x1 - x0 < 2 or y1 - y0 < 2:
        return math.nan
    inside = polygon_fill(p, (y1 - y0, x1 - x0), (x0, y0))
    n_in = np.count_nonzero(inside)
    if n_in == 0:
        return math.nan
    r = max(2, int(round(CONTRAST_BAND * math.sqrt(n_in))))
    inside = inside.astype(bool)
    band = grow(inside, r) & ~inside
    if not band.any():
        return math.nan
    roi = image_bgr[y0:y1, x0:x1]
    return float(model.log_ratio(roi, inside).mean() - model.log_ratio(roi, band).mean())


def edge_strength(image_bgr: np.ndarray, outlines: list[np.ndarray], step: float = 2.0) -> list[float]:
    """How strong the image's edges are along each closed outline: the grey level's gradient
    magnitude (Sobel), the strongest within 2 px of the outline, averaged over points every
    ``step`` px along it (NaN for an outline of fewer than 3 finite points)."""
    import cv2

    h, w = image_bgr.shape[:2]
    ps = [np.asarray(p, dtype=float).reshape(-1, 2) for p in outlines]
    good = [len(p) >= 3 and bool(np.all(np.isfinite(p))) for p in ps]
    if not any(good):
        return [math.nan] * len(ps)
    allp = np.vstack([p for p, g in zip(ps, good) if g])
    x0, y0 = (int(max(0, math.floor(v) - 4)) for v in allp.min(axis=0))
    x1, y1 = int(min(w, math.ceil(allp[:, 0].max()) + 5)), int(min(h, math.ceil(allp[:, 1].max()) + 5))
    if x1 - x0 < 3 or y1 - y0 < 3:
        return [math.nan] * len(ps)
    roi = image_bgr[y0:y1, x0:x1]
    grey = (roi if roi.ndim == 2 else cv2.cvtColor(roi, cv2.COLOR_BGR2GRAY)).astype(np.float32)
    mag = cv2.magnitude(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1))
    mag = cv2.dilate(mag, np.ones((5, 5), np.uint8))
    out = []
    for p, g in zip(ps, good):
        if not g:
            out.append(math.nan)
            continue
        perimeter = float(np.hypot(*np.diff(np.vstack([p, p[:1]]), axis=0).T).sum())
        pts = resample_closed(p, max(3, math.ceil(perimeter / step))) - (x0, y0)
        pts = np.clip(pts, 0, [x1 - x0 - 1, y1 - y0 - 1]).astype(np.float32)
        v = cv2.remap(mag, pts[:, :1], pts[:, 1:], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out.append(float(np.mean(v)))
    return out


#: the frames' scale for the optical flow (DIS at half resolution: 1.6 ms a frame of 854x480)
FLOW_SCALE = 0.5
#: the fewest pixels (at the flow's scale) of a region whose motion :meth:`FlowPrior.shift` measures
SHIFT_LEAST = 9


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

    def frozen(self) -> "FlowPrior":
        """This frame's flow, kept as it is by later pushes: for a stage that runs a frame behind
        the one that pushes (the refinement's thread, sharing the tracker's flow)."""
        view = object.__new__(FlowPrior)
        view._dis, view._prev, view._flow = None, None, self._flow
        return view

    def move(self, points: np.ndarray) -> np.ndarray | None:
        """``points`` (P, 2) of the last frame carried to this one; None before a flow exists."""
        import cv2

        if self._flow is None:
            return None
        h, w = self._flow.shape[:2]
        p = np.clip(np.asarray(points, dtype=np.float64) * FLOW_SCALE, 0, [w - 1, h - 1]).astype(np.float32)
        d = cv2.remap(self._flow, p[:, :1], p[:, 1:], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[:, 0, :]
        return np.asarray(points, dtype=np.float64) + d.astype(np.float64) / FLOW_SCALE

    def _inside(self, outline: np.ndarray) -> np.ndarray | None:
        """The flow vectors (K, 2), at the flow's scale, of the pixels inside the closed polygon
        ``outline`` (P, 2) of the last frame; None before a flow exists or when fewer than
        :data:`SHIFT_LEAST` of them are in the frame."""
        import cv2

        if self._flow is None:
            return None
        p = np.asarray(outline, dtype=np.float64).reshape(-1, 2) * FLOW_SCALE
        if len(p) < 3 or not np.all(np.isfinite(p)):
            return None
        h, w = self._flow.shape[:2]
        lo = np.maximum(np.floor(p.min(axis=0)).astype(int), 0)
        hi = np.minimum(np.ceil(p.max(axis=0)).astype(int) + 1, [w, h])
        if np.any(hi - lo < 1):
            return None
        m = np.zeros((hi[1] - lo[1], hi[0] - lo[0]), np.uint8)
        cv2.fillPoly(m, [np.round(p - lo).astype(np.int32)], 1)
        inside = m.astype(bool)
        if np.count_nonzero(inside) < SHIFT_LEAST:
            return None
        return self._flow[lo[1]:hi[1], lo[0]:hi[0]][inside]

    def shift(self, outline: np.ndarray) -> np.ndarray | None:
        """How the region inside the closed polygon ``outline`` (P, 2) of the last frame moved to
        this one: the median flow over its pixels (2,), px; None before a flow exists or when
        fewer than :data:`SHIFT_LEAST` of its pixels (at the flow's scale) are in the frame.
        The median follows the part of the region that moves together, the object, when the
        polygon also takes in some background."""
        d = self._inside(outline)
        return None if d is None else np.median(d, axis=0).astype(np.float64) / FLOW_SCALE

    def shift_spread(self, outline: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`shift` and how much the flow over the region disagrees with it: the median
        absolute deviation of the flow from its median per axis, as a standard deviation (2,),
        px.  Large where the region holds more than one motion (an object and the background it
        moves against, a ball that has just turned back), small for one rigid move."""
        d = self._inside(outline)
        if d is None:
            return None
        m = np.median(d, axis=0).astype(np.float64) / FLOW_SCALE
        d = d.astype(np.float64) / FLOW_SCALE
        return m, 1.4826 * np.median(np.abs(d - m), axis=0)


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


#: the share of a template's region that must lie in the first estimate's fill (grown by a
#: tenth of the object's size) for the region to start the refinement
START_INSIDE = 0.5


def simplify_closed(points: np.ndarray, n: int) -> np.ndarray:
    """``n`` vertices of a closed polygon that keep its shape: the corners Douglas-Peucker keeps
    (the largest set of at most ``n``), then points added along the longest edges; clockwise on
    screen from its top, as :func:`resample_closed`.  Equal spacing along a boundary that follows
    single pixels spends its points on their steps and cuts the corners."""
    import cv2

    p = np.asarray(points, dtype=float)
    if len(p) <= 3 or n < 3:
        return resample_closed(p, n)
    c = p.astype(np.float32).reshape(-1, 1, 2)
    lo, hi = 0.0, float(np.ptp(p, axis=0).max()) + 1.0
    best = None
    for _ in range(20):  # the smallest tolerance that keeps at most n vertices
        eps = 0.5 * (lo + hi)
        v = cv2.approxPolyDP(c, eps, True)[:, 0, :].astype(float)
        if len(v) <= n:
            best, hi = v, eps
        else:
            lo = eps
        if hi - lo < 0.05:
            break
    if best is None or len(best) < 3:
        return resample_closed(p, n)
    x, y = best[:, 0], best[:, 1]
    if float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) < 0:
        best = best[::-1]
    best = np.roll(best, -int(np.argmin(best[:, 1])), axis=0)
    # the points still to place go along the longest edges, each edge cut into equal parts
    nxt = np.roll(best, -1, axis=0)
    length = np.hypot(*(nxt - best).T)
    parts = np.ones(len(best), int)
    for _ in range(n - len(best)):
        parts[int(np.argmax(length / parts))] += 1
    out = [best[k] + (nxt[k] - best[k]) * (j / parts[k]) for k in range(len(best)) for j in range(parts[k])]
    return np.asarray(out)


#: a frame's region updates the colour model only when the tracker's confidence is at least
#: this and the region agrees with the estimate (IoU) at least :data:`UPDATE_AGREEMENT`
UPDATE_CONFIDENCE = 0.7
UPDATE_AGREEMENT = 0.6
#: the least IoU of a region with the estimate for the region to vouch for its frame (holds)
HOLD_AGREEMENT = 0.2
#: ... or the least share of the estimate's fill inside the region (an estimate shrunk onto a
#: part of the object the region still covers whole)
HOLD_COVER = 0.5
#: on a frame held with confidence (the tracker's at least :data:`UPDATE_CONFIDENCE`), the
#: tracker's curve is the outline when the image's edges along it are at least this many times as
#: strong as along the region's boundary (:func:`edge_strength`): where colour leaks into
#: look-alike surroundings (a hull's reflection, a road of a car's grey) the region's boundary
#: runs through flat colour, the curve held by the tracker's edges does not
EDGE_PREFERENCE = 1.2
#: objects larger than this (px, the square root of the area of their priors' box) are refined
#: on the frame shrunk to it: the time of a frame no longer grows with the object's size
WORK_SIZE = 160.0


class OutlineRefiner:
    """The outline of every frame fitted again from the tracker's estimate (module docstring).

    The first frame teaches the colour model: from ``start``, the region the template was
    fitted to (:attr:`trackcli.shapes.template.Template.region`, polygons in the first frame's
    pixels), when it lies where the first estimate is; else from the estimate's fill, learned
    again from the region it refines to.  With ``start`` the first frame's outline is the
    region's (its pieces joined, :func:`joined_outline`).  Each later frame's prior is the
    estimate and, with ``flow``, the last refined region's pieces moved by the optical flow,
    their log-odds added.

    The colours follow the object's (light, turning) slowly: a frame held with confidence (the
    tracker's at least :data:`UPDATE_CONFIDENCE`, the region agreeing with the estimate at least
    :data:`UPDATE_AGREEMENT`) moves the model ``settings.colour_rate`` of the way toward its own
    region's colours.  The first frame's model stays as the reference :func:`contrast` is
    measured with, which a drifting model cannot move: the evidence of :meth:`holds`.
    """

    def __init__(self, settings, start=None, flow: "FlowPrior | None" = None) -> None:
        self.settings = settings
        self.model: ColourModel | None = None
        self.reference: ColourModel | None = None
        # a flow another stage pushes every frame before this one runs (the tracker's, whose
        # proposal uses it), so that the frames' flow is computed once; else its own
        self.flow = (flow if flow is not None else FlowPrior()) if settings.flow else None
        self.owns_flow = flow is None
        self.last: np.ndarray | None = None
        self.start = None if not start else [np.asarray(p, dtype=float) for p in start]

    def _begin(self, image: np.ndarray, est: np.ndarray) -> RegionFit | None:
        """The first frame from the template's region, or None when there is none where the estimate is."""
        if self.start is None:
            return None
        shape = image.shape[:2]
        region = region_fill(self.start, shape)
        inside = polygon_fill(est, shape)
        area = np.count_nonzero(region)
        if area < 9 or not inside.any():
            return None
        r = max(1, int(round(0.1 * math.sqrt(np.count_nonzero(inside)))))
        grown = grow(inside, r)
        if np.count_nonzero(region & grown) < START_INSIDE * area:
            return None
        self.model = ColourModel.learn(image, region)
        inside = inside.astype(bool)
        inter = np.count_nonzero(region & inside)
        agree = inter / max(np.count_nonzero(region | inside), 1)
        # every boundary pixel, so that the optical flow moves every part of the boundary
        pieces = outer_pieces(region, least=max(9.0, PIECE_LEAST * area))
        if not pieces:
            return None
        return RegionFit(region, (0, 0), joined_outline(pieces), float(agree), pieces=tuple(pieces),
                         covers=inter / max(np.count_nonzero(inside), 1))

    def __call__(self, image_bgr: np.ndarray, estimate: np.ndarray, confidence: float = math.nan,
                 flow: FlowPrior | None = None) -> RegionFit | None:
        """The refined outline of the frame ``image_bgr`` whose estimate is the closed polygon
        ``estimate`` (P, 2), held with the tracker's ``confidence`` (NaN: unknown, no update);
        ``flow``: the shared flow as it was at this frame (:meth:`FlowPrior.frozen`), when the
        tracker may already have pushed the next one."""
        import cv2

        s = self.settings
        image = image_bgr if image_bgr.ndim == 3 else np.repeat(image_bgr[..., None], 3, axis=2)
        if self.flow is not None and self.owns_flow:
            self.flow.push(image)
        est = np.asarray(estimate, dtype=float)
        if not np.all(np.isfinite(est)) or len(est) < 3:
            return None
        if self.model is None:
            fit = self._begin(image, est)
            if fit is not None:
                self.reference = ColourModel(self.model.fg.copy(), self.model.bg.copy())
                self.last = list(fit.pieces)
                return dataclasses.replace(fit, contrast=contrast(image, fit.outline, self.reference))
            m = polygon_fill(est, image.shape[:2]).astype(bool)
            if not m.any():
                return None
            self.model = ColourModel.learn(image, m)
            fit = refine(image, est, self.model, sigma=s.prior_width)
            if fit.outline is not None:  # the colours again, from the region the template refined to
                m2 = polygon_fill(fit.outline, image.shape[:2]).astype(bool)
                if m2.any():
                    self.model = ColourModel.learn(image, m2)
            self.reference = ColourModel(self.model.fg.copy(), self.model.bg.copy())
        others = ()
        if self.flow is not None and self.last is not None:
            moved = [(flow or self.flow).move(p) for p in self.last]
            if all(m is not None for m in moved):
                others = ((moved, 1.0),)
        fit = refine(image, est, self.model, sigma=s.prior_width, others=others, work_size=WORK_SIZE)
        self.last = list(fit.pieces) if fit.outline is not None else [est]
        if fit.outline is None:
            return fit
        if (s.colour_rate > 0 and confidence >= UPDATE_CONFIDENCE and fit.agreement >= UPDATE_AGREEMENT):
            x0, y0 = fit.origin
            h, w = fit.mask.shape
            x1, y1 = x0 + int(round(w / fit.scale)), y0 + int(round(h / fit.scale))
            roi = image[y0:y1, x0:x1]
            if roi.shape[:2] != (h, w):
                roi = cv2.resize(roi, (w, h), interpolation=cv2.INTER_AREA)
            self.model.blend(ColourModel.learn(roi, fit.mask), s.colour_rate)
        # the lost verdict's evidence is the region's; the outline drawn may be the curve's
        fit = dataclasses.replace(fit, contrast=contrast(image, fit.outline, self.reference))
        if confidence >= UPDATE_CONFIDENCE:
            on_curve, on_region = edge_strength(image, [est, fit.outline])
            if on_curve > EDGE_PREFERENCE * on_region:
                fit = dataclasses.replace(fit, outline=est)
        return fit

    def holds(self, fit: RegionFit | None) -> bool:
        """Whether a frame's refined region is evidence enough that the object is held whatever
        the tracker's confidence: its inside stands out from its surroundings in the first
        frame's colours by at least ``settings.lost_contrast`` (:func:`contrast`; 0: never), and
        it still agrees with the estimate (IoU at least :data:`HOLD_AGREEMENT`, or the estimate
        at least :data:`HOLD_COVER` inside it: an estimate shrunk onto a wheel of the car the
        region holds).  A region that has parted from the estimate vouches for neither: on a
        cluttered clip it is as often on a look-alike of the object's colours as on the object."""
        t = self.settings.lost_contrast
        return (fit is not None and t > 0 and math.isfinite(fit.contrast) and fit.contrast >= t
                and (fit.agreement >= HOLD_AGREEMENT or fit.covers >= HOLD_COVER))


def outline_refiner(settings, space, start=None, flow: FlowPrior | None = None) -> OutlineRefiner | None:
    """The run's :class:`OutlineRefiner` (``outline.refine``), or None: refinement off, no
    outline columns to draw (``output.outline_points`` 0), or an open curve.  ``start``: the
    region the template was fitted to (:attr:`trackcli.shapes.template.Template.region`);
    ``flow``: the tracker's :class:`FlowPrior`, pushed by the tracker before each step, to share."""
    if settings.outline.refine and settings.output.outline_points and space.basis.closed:
        return OutlineRefiner(settings.outline, start=start, flow=flow)
    return None
