"""What the object looks like, learned from the template on its first frame.

:func:`learn_appearance` learns the :class:`Appearance` the contour discriminant
(:mod:`trackcli.observe.discriminant`) reads along its normals: the edge polarity of each
normal, the density of features inside the object, and a colour model.

Colour: foreground against background
-------------------------------------
A histogram of the pixels inside the template (foreground) and one of the background (an even
mixture of a ring around the template and the rest of the frame), in HSV with 8 hue × 8
saturation × 4 value bins (hue and saturation carry most of the information and change little
with lighting; the coarse value bins separate dark from light greys, whose hue is
meaningless; 256 bins in all, so that mapping a frame is a byte lookup), give the log-ratio
``L(c) = log p_fg(c) / p_bg(c)``, clipped to ``[-3, 3]``.  On grey footage hue and saturation
carry nothing; the bins are then 32 grey levels × 8 levels of local texture (the standard
deviation of the grey level over a Gaussian window of 2 px), so that a smooth face or ball is
told from a wall or pavement of its own grey level.  Every frame is mapped to ``L`` once (a
back-projection, :meth:`Appearance.colour_map`, or :class:`LazyColourMap` where it is read);
the discriminant averages it along each normal.  The models are kept as learned on the first
frame (no update), so they cannot drift onto the background.

The frame's picture and light
-----------------------------
Letterbox or pillarbox bars (:func:`picture_area`) hold no evidence: the feature image repeats
the picture's border over them (:func:`without_bars`) and the colour map is 0 there
(:func:`clear_bars`).  A frame whose light changed over the whole scene is read in the first
frame's exposure (:func:`in_first_light`, with the exposure :class:`trackcli.observe.scene.StillScene`
measures), so that the colour bins learned on the first frame still hold.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from trackcli.errors import DataError
from trackcli.observe.kernels import colour_lookup, count_line_features
from trackcli.observe.measure import _as_image, _as_normals, _remap_rows, _scan_chunks

#: HSV histogram bins (hue, saturation, value).
HIST_BINS = (8, 8, 4)
#: Grey-level bins of the histogram that replaces the HSV one on grey footage ...
GREY_BINS = 32
#: ... times bins of the local texture: the standard deviation of the grey level over a
#: Gaussian window of sigma :data:`TEXTURE_SIGMA` px, cut at :data:`TEXTURE_EDGES` grey levels
#: (a smooth face or ball against a textured wall or pavement of the same grey)
TEXTURE_SIGMA = 2.0
TEXTURE_EDGES = (2, 4, 7, 11, 16, 23, 32)
TEXTURE_BINS = len(TEXTURE_EDGES) + 1
#: A frame is grey (a monochrome clip, e.g. a grey JPEG sequence read as BGR) when fewer than
#: :data:`GREY_SHARE` of its pixels have channels more than :data:`GREY_SPREAD` grey levels apart.
GREY_SPREAD = 8
GREY_SHARE = 0.01
#: Letterbox and pillarbox bars: at least :data:`BAR_MIN` rows (columns) at the frame's edge,
#: 90 % of whose pixels are no brighter than :data:`BAR_LEVEL` grey levels, with a picture of at
#: least half the frame's height (width) between them.
BAR_LEVEL = 24
BAR_MIN = 4
#: rows (columns) of the picture next to a bar whose border the feature image repeats over the
#: bar: the smoothing spreads the bar's edge over a few pixels of the picture
BAR_MARGIN = 6
#: Clip of the colour log-ratio.
COLOUR_CLIP = 3.0
#: Smallest clutter density used, features per pixel (a clean background has almost none).
MIN_DENSITY = 0.002
# Offsets of the colour samples along a normal, as fractions of the object's size.
_COLOUR_FRACTIONS = (0.04, 0.08, 0.13, 0.2)

@dataclass(frozen=True, eq=False)
class Appearance:
    """What the object looks like, learned from the template on its first frame.

    Attributes
    ----------
    polarity : ndarray of shape (M,), int8
        Per normal: +1 dark-to-light along the outward normal, -1 light-to-dark, 0 unclear.
    lambda_in : float
        Density of features inside the object, per pixel of normal (any sign).
    lut : ndarray of shape (prod(HIST_BINS),), float32
        The colour log-ratio ``L`` of every HSV bin.
    size : float
        The object's size, the square root of the template's area, px.
    colour_offsets : ndarray of shape (K,), float32
        Positive offsets (px) of the colour samples along each normal.
    grey : bool
        The template's frame is grey: the bins are :data:`GREY_BINS` grey levels times the bins
        of the local texture (:func:`grey_texture`, :data:`TEXTURE_EDGES`) instead of the HSV
        bins of :data:`HIST_BINS`, whose hue and saturation carry nothing there.
    """

    polarity: np.ndarray
    lambda_in: float
    lut: np.ndarray
    size: float
    colour_offsets: np.ndarray
    grey: bool = False

    def colour_map(self, frame_bgr: np.ndarray) -> np.ndarray:
        """The colour log-ratio ``L`` of every pixel of a frame: float32 (H, W) in [-3, 3].

        The same as ``cv2.LUT(hsv_bins(frame, grey=self.grey), lut)``, in one compiled pass
        after the HSV conversion (on grey footage, after :func:`grey_texture`).
        """
        hsv = grey_texture(frame_bgr) if self.grey else cv2.cvtColor(_bgr(frame_bgr), cv2.COLOR_BGR2HSV)
        out = np.empty(hsv.shape[:2], np.float32)
        shares = _GREY_SHARES if self.grey else _BIN_SHARES
        colour_lookup(hsv, shares, np.ascontiguousarray(self.lut, dtype=np.float32).reshape(-1), out)
        return out

class LazyColourMap:
    """A frame's colour map (:meth:`Appearance.colour_map`) made only where it is read.

    The tracker reads the colour map along the normals of its samples, a few times the
    object's area; a whole 1280×720 frame costs 4.5 ms on one core (the HSV conversion and
    the look-up of the bins).  :meth:`ensure` makes the blocks of :data:`BLOCK` × BLOCK
    pixels a rectangle touches that are not made yet; the conversion and the look-up work
    pixel by pixel, so the values are those of the whole-frame map to the bit.  ``array``
    holds the map, 0 where not made yet; read it only where :meth:`ensure` (or
    :meth:`whole`) was called.  Scoring threads may call :meth:`ensure` at once: blocks are
    made under a lock, and marked made only after their values are written.  Colour frames
    only (the grey model's texture is not pixel by pixel).  With ``exposure``, the map of the
    frame brought back to the first frame's exposure
    (:func:`in_first_light`, pixel by pixel too).
    """

    BLOCK = 32

    def __init__(self, app: Appearance, frame_bgr: np.ndarray,
                 exposure: tuple[np.ndarray, np.ndarray] | None = None):
        if app.grey:
            raise DataError("a lazily made colour map is for colour frames only")
        self._app = app
        self._frame = _bgr(frame_bgr)
        self._undo = first_light_matrix(exposure, 3)
        h, w = self._frame.shape[:2]
        self.array = np.zeros((h, w), np.float32)
        b = self.BLOCK
        self._made = np.zeros(((h + b - 1) // b, (w + b - 1) // b), bool)
        self._area: tuple[int, int, int, int] | None = None
        self._lock = threading.Lock()

    @property
    def shape(self) -> tuple[int, int]:
        return self.array.shape

    def set_area(self, area: tuple[int, int, int, int]) -> None:
        """The picture between letterbox bars: the map is 0 outside it (:func:`clear_bars`)."""
        self._area = area
        clear_bars(self.array, area)

    def ensure(self, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
        """Make the map over pixels ``x0 <= x < x1, y0 <= y < y1`` (clipped to the frame); the map."""
        h, w = self.array.shape
        b = self.BLOCK
        bx0, by0 = max(0, int(math.floor(x0)) // b), max(0, int(math.floor(y0)) // b)
        bx1 = min(self._made.shape[1], (min(int(math.ceil(x1)), w) + b - 1) // b)
        by1 = min(self._made.shape[0], (min(int(math.ceil(y1)), h) + b - 1) // b)
        if bx1 <= bx0 or by1 <= by0 or self._made[by0:by1, bx0:bx1].all():
            return self.array
        with self._lock:  # one thread makes a block; another waits for it, then finds it made
            if not self._made[by0:by1, bx0:bx1].all():
                self._make(bx0, by0, bx1, by1)
        return self.array

    def _make(self, bx0: int, by0: int, bx1: int, by1: int) -> None:
        h, w = self.array.shape
        b = self.BLOCK
        X0, Y0, X1, Y1 = bx0 * b, by0 * b, min(bx1 * b, w), min(by1 * b, h)
        block = self._frame[Y0:Y1, X0:X1]
        out = self._app.colour_map(block if self._undo is None else cv2.transform(block, self._undo))
        if self._area is not None:  # the bars, in the block's coordinates
            ax0, ay0, ax1, ay1 = self._area
            clear_bars(out, (max(0, ax0 - X0), max(0, ay0 - Y0), max(0, ax1 - X0), max(0, ay1 - Y0)))
        self.array[Y0:Y1, X0:X1] = out
        self._made[by0:by1, bx0:bx1] = True

    def whole(self) -> np.ndarray:
        """The map of the whole frame."""
        h, w = self.array.shape
        return self.ensure(0, 0, w, h)

def colour_array(cmap: np.ndarray | LazyColourMap, points: np.ndarray | None = None,
                 reach: float = 0.0) -> np.ndarray:
    """The colour map as an array, made (if lazy) wherever it is read within ``reach`` px of
    ``points`` (n, 2), or over the whole frame when ``points`` is None."""
    if not isinstance(cmap, LazyColourMap):
        return cmap
    if points is None:
        return cmap.whole()
    if points.size == 0:
        return cmap.array
    x, y = points[:, 0], points[:, 1]  # by column: numpy's min over axis 0 of (n, 2) is 20 times slower
    return cmap.ensure(float(x.min()) - reach, float(y.min()) - reach, float(x.max()) + reach + 1.0,
                       float(y.max()) + reach + 1.0)

# One table for the three 8-bit HSV channels (hue 0-179): each channel's share of the flat bin
# index of HIST_BINS, which fits a byte (prod(HIST_BINS) == 256), so that the whole mapping is
# two cv2.LUT calls and one cv2.transform per frame.
_BIN_TABLE = np.zeros((1, 256, 3), np.uint8)
_BIN_TABLE[0, :, 0] = ((np.arange(256) * HIST_BINS[0]) // 180).clip(max=HIST_BINS[0] - 1) * (HIST_BINS[1] * HIST_BINS[2])
_BIN_TABLE[0, :, 1] = ((np.arange(256) * HIST_BINS[1]) // 256) * HIST_BINS[2]
_BIN_TABLE[0, :, 2] = (np.arange(256) * HIST_BINS[2]) // 256
_SUM_CHANNELS = np.ones((1, 3), np.float32)
_BIN_SHARES = np.ascontiguousarray(_BIN_TABLE[0])  # (256, 3): the same table for the compiled look-up
# On grey frames the grey level (in the third channel of grey_texture) counts in GREY_BINS
# bins and its local standard deviation (the second) in TEXTURE_BINS bins; the flat
# bin, grey level + GREY_BINS x texture, fits a byte (32 x 8 = 256).
_GREY_TABLE = np.zeros((1, 256, 3), np.uint8)
_GREY_TABLE[0, :, 1] = np.searchsorted(TEXTURE_EDGES, np.arange(256), side="right") * GREY_BINS
_GREY_TABLE[0, :, 2] = (np.arange(256) * GREY_BINS) // 256
_GREY_SHARES = np.ascontiguousarray(_GREY_TABLE[0])
def is_grey(frame_bgr: np.ndarray, region: np.ndarray | None = None) -> bool:
    """Whether a frame carries no colour: fewer than :data:`GREY_SHARE` of its pixels have
    channels more than :data:`GREY_SPREAD` grey levels apart (a 2-D frame is grey), and, with
    ``region`` (a boolean mask, e.g. the object), fewer than that share of the region's pixels
    too: a small coloured object in a colourless scene keeps its colour."""
    f = np.asarray(frame_bgr)
    if f.ndim == 2:
        return True
    img = _bgr(f)
    coloured = cv2.subtract(img.max(axis=2), img.min(axis=2)) > GREY_SPREAD
    if float(np.count_nonzero(coloured)) >= GREY_SHARE * coloured.size:
        return False
    if region is not None:
        inside = np.asarray(region, dtype=bool)
        if inside.any() and float(np.count_nonzero(coloured[inside])) >= GREY_SHARE * np.count_nonzero(inside):
            return False
    return True


def local_mean_deviation(grey: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The local mean and standard deviation of a grey image over a Gaussian window of
    ``sigma`` px: float32 ``(mean, sd)``, each the image's shape."""
    g = np.asarray(grey, dtype=np.float32)
    mean = cv2.GaussianBlur(g, (0, 0), sigma)
    var = cv2.GaussianBlur(g * g, (0, 0), sigma) - mean * mean
    return mean, np.sqrt(np.maximum(var, 0.0), out=var)


def grey_texture(frame_bgr: np.ndarray) -> np.ndarray:
    """A grey frame as three uint8 channels: 0, the local standard deviation of the grey level
    (Gaussian window of sigma :data:`TEXTURE_SIGMA`), the grey level."""
    f = np.asarray(frame_bgr)
    g = f if f.ndim == 2 else cv2.cvtColor(_bgr(f), cv2.COLOR_BGR2GRAY)
    _, sd = local_mean_deviation(g, TEXTURE_SIGMA)
    out = np.zeros(g.shape + (3,), np.uint8)
    out[..., 1] = np.minimum(sd + 0.5, 255.0)
    out[..., 2] = g
    return out


def hsv_bins(frame_bgr: np.ndarray, *, grey: bool = False) -> np.ndarray:
    """Flat HSV histogram bin of every pixel: uint8 (H, W) in ``[0, prod(HIST_BINS))``; with
    ``grey``, the bin of grey level and texture (:func:`grey_texture`) in
    ``[0, GREY_BINS * TEXTURE_BINS)``."""
    hsv = grey_texture(frame_bgr) if grey else cv2.cvtColor(_bgr(frame_bgr), cv2.COLOR_BGR2HSV)
    return cv2.transform(cv2.LUT(hsv, _GREY_TABLE if grey else _BIN_TABLE), _SUM_CHANNELS)


def _bgr(frame: np.ndarray) -> np.ndarray:
    f = np.asarray(frame)
    if f.ndim == 2:
        f = cv2.cvtColor(f.astype(np.uint8, copy=False), cv2.COLOR_GRAY2BGR)
    if f.ndim != 3 or f.shape[2] != 3:
        raise DataError(f"frame: expected an (H, W, 3) BGR image, got shape {f.shape}")
    return f if f.dtype == np.uint8 else np.clip(f, 0, 255).astype(np.uint8)

def feature_density(fimg: np.ndarray, centre: np.ndarray, size: float, threshold: float, *, stride: int = 3) -> float:
    """Features per pixel along rows and columns of ``fimg`` near ``centre``.

    A feature is counted as the scanner of :mod:`trackcli.observe.measure` finds one: a local maximum
    of ``|D|`` (the difference of neighbouring pixels of the smoothed image) at least
    ``threshold``.  Every ``stride``-th row and column of a window of ``5 size`` around
    ``centre`` (clipped to the image) is scanned.
    """
    img = _as_image(fimg)
    h, w = img.shape
    half = 2.5 * size
    cx, cy = float(centre[0]), float(centre[1])
    if not (math.isfinite(cx) and math.isfinite(cy)):
        cx, cy = w / 2, h / 2
    x0, x1 = int(max(0, cx - half)), int(min(w, cx + half))
    y0, y1 = int(max(0, cy - half)), int(min(h, cy + half))
    if x1 - x0 < 8 or y1 - y0 < 8:
        x0, x1, y0, y1 = 0, w, 0, h
    count, length = count_line_features(img, y0, y1, x0, x1, int(stride), np.float32(threshold))
    return max(count / max(length, 1), MIN_DENSITY)

def _colour_model(frame_bgr: np.ndarray, inside: np.ndarray, size: float, *, grey: bool = False) -> np.ndarray:
    """Colour log-ratio per HSV bin (per grey-level bin with ``grey``): the pixels of the
    object's mask ``inside`` (uint8 0/1) against the background."""
    img = _bgr(frame_bgr)
    bins = hsv_bins(img, grey=grey).reshape(-1)
    gap = max(2, int(round(0.05 * size)))
    ring_w = max(6, int(round(0.5 * size)))
    near = cv2.dilate(inside, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * gap + 1, 2 * gap + 1)))
    far = cv2.dilate(inside, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ring_w + 1, 2 * ring_w + 1)))
    core = cv2.erode(inside, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * gap + 1, 2 * gap + 1)))
    if core.sum() < 20:
        core = inside
    ring = far & (1 - near)
    rest = 1 - near
    n = int(np.prod(HIST_BINS))
    fg, bg_ring, bg_all = (np.bincount(bins[m.reshape(-1) > 0], minlength=n).astype(np.float64)
                           for m in (core, ring, rest))
    nbins = float(GREY_BINS * TEXTURE_BINS if grey else n)
    # add-a-half smoothing (a Dirichlet prior) keeps unseen colours neutral rather than infinite
    pf = (fg + 0.5) / (fg.sum() + 0.5 * nbins)
    # background: half the ring around the object (what it must be told from where it is),
    # half the rest of the frame (what it may meet later, e.g. letterbox bars, other regions)
    pb = 0.5 * (bg_ring + 0.5) / (bg_ring.sum() + 0.5 * nbins) + 0.5 * (bg_all + 0.5) / (bg_all.sum() + 0.5 * nbins)
    return np.clip(np.log(pf / pb), -COLOUR_CLIP, COLOUR_CLIP).astype(np.float32)

def polygon_mask(polygon: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The inside of a closed polygon (n, 2) as a uint8 0/1 mask of ``shape[:2]``."""
    inside = np.zeros(shape[:2], np.uint8)
    cv2.fillPoly(inside, [np.round(np.asarray(polygon, dtype=float)).astype(np.int32)], 1)
    return inside

def learn_appearance(frame_bgr: np.ndarray, fimg: np.ndarray, points: np.ndarray, normals: np.ndarray,
                     polygon: np.ndarray, *, h: float, sigma: float, threshold: float) -> Appearance:
    """Learn polarity per normal, interior feature density and colour from the template.

    Parameters
    ----------
    frame_bgr : ndarray (H, W, 3)
        The frame the tracker starts on.
    fimg : ndarray (H, W)
        Its feature image.
    points, normals : ndarray of shape (M, 2)
        Measurement points and outward normals of the template on that frame.
    polygon : ndarray of shape (P, 2)
        Dense outline of the template (for the colour regions and the size).
    h, sigma, threshold : float
        Search half-width, boundary spread and contrast threshold of the discriminant.
    """
    img = _as_image(fimg)
    pts, nrm, lead = _as_normals(points, normals)
    m = pts.shape[0]
    area = abs(float(cv2.contourArea(np.asarray(polygon, dtype=np.float32))))
    size = max(math.sqrt(area), 4.0)
    # Polarity: the signed difference across the outline, the strongest within +-2 sigma.
    u = np.arange(-math.ceil(2 * sigma) - 0.5, math.ceil(2 * sigma) + 1.0, 1.0, dtype=np.float32)
    prof = _remap_rows(img, pts.astype(np.float32), nrm.astype(np.float32), u)
    d = prof[:, 1:] - prof[:, :-1]
    best = d[np.arange(m), np.argmax(np.abs(d), axis=1)]
    polarity = np.where(np.abs(best) >= threshold, np.sign(best), 0).astype(np.int8)
    # Interior density: features on [-h, -2 sigma] of the template's normals, shrunk towards
    # the clutter density around it by a prior worth 2 px per normal.
    inner = 0
    for _, _, _r, nu, _s in _scan_chunks(img, pts, nrm, float(h), threshold, 0):
        inner += int(np.count_nonzero(nu < -2 * sigma))
    length = m * max(h - 2 * sigma, 1.0)
    centre = np.asarray(polygon, dtype=float).mean(axis=0)
    lam = feature_density(img, centre, size, threshold)
    lambda_in = max((inner + lam * 2 * m) / (length + 2 * m), MIN_DENSITY)
    offsets = np.unique(np.maximum(1.5, np.round(np.array(_COLOUR_FRACTIONS) * size))).astype(np.float32)
    inside = polygon_mask(polygon, img.shape)
    grey = is_grey(frame_bgr, inside > 0)
    return Appearance(polarity=polarity, lambda_in=float(lambda_in),
                      lut=_colour_model(frame_bgr, inside, size, grey=grey), size=size, colour_offsets=offsets,
                      grey=grey)

def picture_area(frame: np.ndarray) -> tuple[int, int, int, int] | None:
    """The picture ``(x0, y0, x1, y1)`` between the black bars of a letterboxed or pillarboxed
    frame (see :data:`BAR_LEVEL`); None when the frame has no bars."""
    f = np.asarray(frame)
    grey = f if f.ndim == 2 else cv2.cvtColor(_bgr(f), cv2.COLOR_BGR2GRAY)
    h, w = grey.shape[:2]

    def bar(lines: np.ndarray) -> int:
        dark = np.percentile(lines, 90, axis=1) <= BAR_LEVEL
        n = int(np.argmin(dark)) if not dark.all() else len(dark)
        return n if n >= BAR_MIN else 0

    top, bottom = bar(grey), bar(grey[::-1])
    left, right = bar(grey.T), bar(grey.T[::-1])
    if h - top - bottom < h / 2:
        top = bottom = 0
    if w - left - right < w / 2:
        left = right = 0
    if not (top or bottom or left or right):
        return None
    return left, top, w - right, h - bottom


def without_bars(fimg: np.ndarray, area: tuple[int, int, int, int]) -> np.ndarray:
    """A copy of a feature image whose bars (outside the picture ``area``) read as the frame's
    edge does: the picture's border, :data:`BAR_MARGIN` pixels in, repeated over them, so the
    bar's own edge is no feature."""
    x0, y0, x1, y1 = area
    h, w = fimg.shape
    out = np.array(fimg, dtype=np.float32, copy=True)
    k = BAR_MARGIN
    if y0 > 0:
        out[:y0 + k] = out[min(y0 + k, h - 1)]
    if y1 < h:
        out[y1 - k:] = out[max(y1 - k - 1, 0)]
    if x0 > 0:
        out[:, :x0 + k] = out[:, min(x0 + k, w - 1)][:, None]
    if x1 < w:
        out[:, x1 - k:] = out[:, max(x1 - k - 1, 0)][:, None]
    return out


def clear_bars(cmap: np.ndarray | LazyColourMap, area: tuple[int, int, int, int]) -> None:
    """Zero a colour map outside the picture ``area`` (no evidence, as beyond the frame's edge); in place.
    A :class:`LazyColourMap` keeps the area for the blocks it makes later."""
    if isinstance(cmap, LazyColourMap):
        cmap.set_area(area)
        return
    x0, y0, x1, y1 = area
    cmap[:y0] = 0.0
    cmap[y1:] = 0.0
    cmap[:, :x0] = 0.0
    cmap[:, x1:] = 0.0


def first_light_matrix(exposure: tuple[np.ndarray, np.ndarray] | None, channels: int) -> np.ndarray | None:
    """The ``cv2.transform`` matrix (float32, ``(channels, channels + 1)``) that brings an image
    of ``channels`` channels back to the first frame's exposure, ``(image - offset) / gain`` per
    channel, for an ``exposure`` of :meth:`StillScene.measure` (a gain and offset per channel,
    or one for all); None when ``exposure`` is None or within a hundredth of gain and a level of
    offset of none.  Made once per frame, applied to each block of it that is read."""
    if exposure is None:
        return None
    gain, offset = (np.asarray(v, dtype=np.float64).reshape(-1) for v in exposure)
    if np.all(np.abs(gain - 1.0) < 0.01) and np.all(np.abs(offset) < 1.0):
        return None
    if channels != gain.size:  # a grey image, or one exposure for every channel
        gain, offset = np.full(channels, gain.mean()), np.full(channels, offset.mean())
    mat = np.zeros((channels, channels + 1), np.float32)
    mat[np.arange(channels), np.arange(channels)] = 1.0 / gain
    mat[:, channels] = -offset / gain
    return mat


def in_first_light(image: np.ndarray, exposure: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """``image`` (BGR or grey, uint8) brought back to the first frame's exposure
    (:func:`first_light_matrix`); the image itself when that changes nothing."""
    img = np.asarray(image)
    mat = first_light_matrix(exposure, 1 if img.ndim == 2 else img.shape[2])
    return image if mat is None else cv2.transform(img, mat).reshape(img.shape)


def colour_map(app: Appearance, image: np.ndarray, exposure: tuple[np.ndarray, np.ndarray] | None = None
               ) -> np.ndarray | LazyColourMap:
    """The colour map of ``image`` for the appearance ``app``, read in the first frame's
    exposure when ``exposure`` is given (:func:`in_first_light`): made where the tracker reads
    it on colour frames (:class:`LazyColourMap`), whole on grey ones."""
    if app.grey:
        return app.colour_map(in_first_light(image, exposure))
    return LazyColourMap(app, image, exposure)
