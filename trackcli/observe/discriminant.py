"""The default observation model: a contour discriminant with appearance learned on the first frame.

The clutter density of AC eq 12.2 scores a hypothesised curve by how many edges lie near it,
so a curve in dense texture scores as well as the object.  This module replaces it by a
likelihood *ratio* — "the object's boundary is here" against "there is only background here" —
in the spirit of the contour discriminant of MacCormick & Blake (001 §3), and adds two cues
learned from the template on the first frame, both read along the same normals.

Edges: the discriminant per normal
----------------------------------
Along normal ``i`` the features (:mod:`trackcli.observe.measure`) on the segment ``[-h, h]`` are
modelled, under the *background* hypothesis, as a Poisson process of density ``λ`` per pixel
(the clutter density, estimated on every frame from the image around the object) and, under
the *object* hypothesis, as: the boundary at offset ``ν ~ N(0, σ²)``, missed with probability
``q`` (occlusion, low contrast); Poisson features of density ``λ_in`` on the interior part
``[-h, 0)`` (learned from the object on the first frame); density ``λ`` on the exterior part.
The ratio of the two densities of the features observed is

    D_i = exp(h (λ - λ_in)) (λ_in / λ)^{n_in} [ q + (1 - q) Σ_m g(ν_m) / λ(ν_m) ],

``g`` the Gaussian density of the boundary's offset, ``n_in`` the number of interior features
and ``λ(ν) = λ_in`` inside, ``λ`` outside.  ``log D_i > 0`` means normal ``i`` looks more like
the object's boundary than like clutter; ``log D = Σ_i log D_i`` has that meaning for the whole
curve.  An edge inside a smooth object counts against a curve (the interior term), and a curve
placed in dense texture gains little, because every feature is divided by the density of
features there.

Polarity per normal: on the first frame, the sign of the intensity change across the
template's outline is measured at each normal (a head is darker than the wall on one side and
lighter on another).  Where it is clear, only features of that sign count on that normal, and
the clutter densities are halved accordingly (texture has both signs in equal measure); where
it is not, features of either sign count.

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
told from a wall or pavement of its own grey level.  Every frame is mapped to ``L`` once (a back-projection), and along
each normal ``L`` is averaged at a few offsets inside and outside the curve; the colour term of
normal ``i`` is ``c_i = (mean_inside L - mean_outside L) / 2``, in ``[-3, 3]``: positive when
the curve separates object-coloured from background-coloured pixels.  The models are kept as
learned on the first frame (no update), so they cannot drift onto the background.

The log-likelihood of a curve
-----------------------------
    log p(Z | X) = Σ_i [ log D_i + w_c c_i ]   (+ a constant),

``w_c`` = ``condensation.colour_weight``.  The *presence score* of a curve is the same sum
divided by the number of normals: the average evidence per normal that the object is there.
It does not vanish when every sample of a particle set is wrong — a curve on background has a
score near or below zero whatever the other samples see — and is what the trackers' confidence
and ``lost`` verdict are computed from (:func:`confidence`).

Re-acquisition
--------------
While the tracker is lost, :func:`colour_peaks` finds object-coloured regions of the object's
size in a window about where it was last held (growing with the time lost, up to the whole
frame) and :func:`reacquisition_proposal` draws a share of the samples there, with the
importance weights that keep the set a fair sample of the posterior (Isard & Blake's
ICONDENSATION).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any, Callable

import cv2
import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.observe.kernels import (IN_VIEW_LEAST, colour_lookup, count_line_features, discriminant_curves,
                                      discriminant_normals)
from trackcli.observe.measure import _as_image, _as_normals, _remap_rows, _scan_chunks
from trackcli.observe.scene import first_light_matrix

__all__ = ["Appearance", "FrameEvidence", "colour_peaks", "confidence", "evidence", "feature_density",
           "grey_texture", "hsv_bins", "learn_appearance", "local_mean_deviation", "normals_with_features",
           "per_normal", "per_normal_reference", "presence", "reacquisition_proposal", "score"]

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
    (:func:`trackcli.observe.scene.in_first_light`, pixel by pixel too).
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


@dataclass(frozen=True, eq=False)
class FrameEvidence:
    """One frame's images for the observation model."""

    fimg: np.ndarray
    """Feature image (:func:`trackcli.observe.measure.feature_image`)."""
    cmap: np.ndarray | LazyColourMap
    """Colour log-ratio of every pixel (:meth:`Appearance.colour_map`), or the same made
    where it is read (:class:`LazyColourMap`; :func:`colour_array` gives the array)."""
    density: float
    """Clutter density ``λ`` around the object, features (of any sign) per pixel."""
    area: tuple[int, int, int, int] | None = None
    """The picture ``(x0, y0, x1, y1)`` inside letterbox or pillarbox bars (:func:`picture_area`);
    None: the whole frame."""


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


def evidence(app: Appearance, frame_bgr: np.ndarray, fimg: np.ndarray, centre: np.ndarray, threshold: float, *,
             cmap: np.ndarray | None = None) -> FrameEvidence:
    """The per-frame images of the observation model (one back-projection, one density);
    ``cmap``: the frame's :meth:`Appearance.colour_map` when already made."""
    return FrameEvidence(fimg=_as_image(fimg), cmap=app.colour_map(frame_bgr) if cmap is None else cmap,
                         density=feature_density(fimg, centre, app.size, threshold))


def _colour_profile(app: Appearance) -> tuple[np.ndarray, np.ndarray]:
    """Offsets of the colour samples along a normal (inside, then outside) and their weights.

    ``c_i = (mean inside L - mean outside L) / 2`` is the weighted sum of the samples.
    """
    offs = app.colour_offsets
    nk = offs.size
    u = np.concatenate([-offs[::-1], offs]).astype(np.float32)
    weights = np.concatenate([np.full(nk, 0.5 / nk), np.full(nk, -0.5 / nk)]).astype(np.float32)
    return u, weights


def _normal_terms(app: Appearance, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, *, h: float,
                  sigma: float, miss: float) -> tuple[np.ndarray, np.ndarray, tuple[int, ...], tuple[np.ndarray, ...]]:
    """The normals flattened, ``(pts, nrm, lead, terms)``, with the discriminant's terms per
    normal of the curve (M,): ``h (λ - λ_in)``, ``log(λ_in / λ)`` and, as float32,
    ``(1 - q) / (√(2π) σ λ)`` inside and outside, for the densities of features of each
    normal's accepted polarity (halved where a polarity was learned)."""
    pts, nrm, lead = _as_normals(points, normals)
    m = app.polarity.size
    if not lead or lead[-1] != m:
        raise DataError(f"points: expected shape (..., {m}, 2) for {m} normals, got {lead + (2,)}")
    half = np.where(app.polarity != 0, 0.5, 1.0)
    lam_out = ev.density * half
    lam_in = app.lambda_in * half
    c = (1.0 - miss) / (math.sqrt(2.0 * math.pi) * sigma)
    terms = (h * (lam_out - lam_in), np.log(lam_in / lam_out), (c / lam_in).astype(np.float32),
             (c / lam_out).astype(np.float32))
    return pts, nrm, lead, terms


def _kernel_normals(pts: np.ndarray, nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat points and normals as the compiled kernels take them: float32, contiguous, finite."""
    pts = np.ascontiguousarray(pts, dtype=np.float32)
    nrm = np.ascontiguousarray(nrm, dtype=np.float32)
    if not (np.isfinite(pts).all() and np.isfinite(nrm).all()):
        raise DataError("points and normals must be finite (and within float32 range); got NaN or infinite coordinates")
    return pts, nrm


def _colour_reach(app: Appearance) -> float:
    """How far (px, along x or y, with the rounding to a pixel) from a normal's point its
    colour samples are read, at most: the largest offset (the normals are unit vectors)."""
    return (float(np.max(np.abs(app.colour_offsets))) if app.colour_offsets.size else 0.0) + 1.0


def _kernel_args(app: Appearance, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, *, h: float,
                 sigma: float, threshold: float, miss: float) -> tuple[tuple[int, ...], tuple[Any, ...]]:
    """``(lead, arguments)`` of the compiled kernels for these curves, checked."""
    pts, nrm, lead, terms = _normal_terms(app, ev, points, normals, h=h, sigma=sigma, miss=miss)
    pts, nrm = _kernel_normals(pts, nrm)
    base, log_ratio_in, inv_in, inv_out = terms
    u_colour, weights = _colour_profile(app)
    cmap = _as_image(colour_array(ev.cmap, pts, _colour_reach(app)))
    if cmap.shape != ev.fimg.shape:
        raise DataError(f"colour map: expected the feature image's shape {ev.fimg.shape}, got {cmap.shape}")
    return lead, (ev.fimg, cmap, pts, nrm, np.ascontiguousarray(app.polarity, np.int8), int(math.ceil(float(h))),
                  np.float32(h), np.float32(threshold), np.float32(-0.5 / sigma**2), inv_in, inv_out, base,
                  log_ratio_in, float(miss), u_colour, weights)


def per_normal(app: Appearance, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, *, h: float,
               sigma: float, threshold: float, miss: float) -> tuple[np.ndarray, np.ndarray]:
    """``(log D_i, c_i)`` of every normal of every curve, each of the leading shape (..., M).

    Computed by the compiled kernel :func:`trackcli.observe.kernels.discriminant_normals`
    (one pass per normal, the GIL released); :func:`per_normal_reference` is the same
    computation with numpy and ``cv2.remap``.
    """
    lead, args = _kernel_args(app, ev, points, normals, h=h, sigma=sigma, threshold=threshold, miss=miss)
    k_total = args[2].shape[0]
    log_d = np.empty(k_total)
    colour = np.empty(k_total, np.float32)
    discriminant_normals(*args, log_d, colour)
    return log_d.reshape(lead), colour.astype(np.float64).reshape(lead)


def normals_with_features(fimg: np.ndarray, points: np.ndarray, normals: np.ndarray, *, h: float, threshold: float,
                          sign: int = 0) -> int:
    """How many of the normals (M, 2) have a feature on ``[-h, h]``: a local maximum of the
    intensity difference along the normal (its magnitude for ``sign`` 0; of that sign for
    ``sign`` ±1) at least ``threshold``, inside the image.

    The compiled kernel of :func:`per_normal` in counting form (every feature scores 1), so
    it reads the image exactly as the discriminant does; it reports how many normals of an
    estimate found an edge, at a few microseconds a curve.
    """
    img = _as_image(fimg)
    pts, nrm, _ = _as_normals(points, normals)
    m = pts.shape[0]
    if m == 0:
        return 0
    pts, nrm = _kernel_normals(pts, nrm)
    ones32, zeros = np.ones(m, np.float32), np.zeros(m)
    none32 = np.zeros(0, np.float32)
    log_d = np.empty(m)
    # scale 0: every feature weighs exp(0) = 1; with q = 1/2 and no other terms,
    # log_d = log(1/2 + number of features), > 0 from one feature up
    discriminant_normals(img, img, pts, nrm, np.full(m, int(np.sign(sign)), np.int8), int(math.ceil(float(h))),
                         np.float32(h), np.float32(threshold), np.float32(0.0), ones32, ones32, zeros, zeros, 0.5,
                         none32, none32, log_d, np.empty(m, np.float32))
    return int(np.count_nonzero(log_d > 0.0))


def per_normal_reference(app: Appearance, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, *, h: float,
                         sigma: float, threshold: float, miss: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`per_normal` written with numpy and OpenCV (the reference the kernel is tested against)."""
    pts, nrm, lead, terms = _normal_terms(app, ev, points, normals, h=h, sigma=sigma, miss=miss)
    k_total = pts.shape[0]
    curves = k_total // app.polarity.size
    pol_all = np.tile(app.polarity, curves)
    base, log_ratio_in, inv_in, inv_out = (np.tile(t, curves) for t in terms)
    scale = np.float32(-0.5 / sigma**2)
    log_d = np.empty(k_total)
    for k0, k1, row, nu, _s, sgn in _scan_chunks(ev.fimg, pts, nrm, float(h), threshold, 0, with_sign=True):
        pol = pol_all[k0:k1][row]
        keep = (pol == 0) | (sgn == pol)  # on each normal, features of its polarity only
        row, nu = row[keep], nu[keep]
        inside = nu < 0
        g = np.exp(nu * nu * scale)
        g *= np.where(inside, inv_in[k0:k1][row], inv_out[k0:k1][row])
        total = np.bincount(row, weights=g, minlength=k1 - k0)
        n_in = np.bincount(row[inside], minlength=k1 - k0)
        log_d[k0:k1] = base[k0:k1] + n_in * log_ratio_in[k0:k1] + np.log(miss + total)
    # colour: the log-ratio map's nearest pixels inside (-offsets) and outside (+offsets) every
    # normal; beyond the frame's edge it reads 0 (no evidence either way): replicating the
    # border would let an outline that has left the frame score the colours of the frame's edge
    u, weights = _colour_profile(app)
    p32, n32 = pts.astype(np.float32), nrm.astype(np.float32)
    x = np.floor(n32[:, None, 0] * u + p32[:, None, 0] + np.float32(0.5)).astype(np.int64)
    y = np.floor(n32[:, None, 1] * u + p32[:, None, 1] + np.float32(0.5)).astype(np.int64)
    cmap = np.asarray(colour_array(ev.cmap, pts, _colour_reach(app)), dtype=np.float32)
    inside = (x >= 0) & (x < cmap.shape[1]) & (y >= 0) & (y < cmap.shape[0])
    values = np.where(inside, cmap[np.where(inside, y, 0), np.where(inside, x, 0)], np.float32(0.0))
    colour = values.astype(np.float64) @ weights
    return log_d.reshape(lead), colour.reshape(lead)


def score(app: Appearance, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, *, h: float, sigma: float,
          threshold: float, miss: float, colour_weight: float) -> np.ndarray:
    """``log p(Z | X)`` (up to a constant) of every curve: ``Σ_i log D_i + w_c c_i``, shape (...).

    The sum of :func:`per_normal`'s terms over the normals in view, computed by the compiled
    kernel :func:`trackcli.observe.kernels.discriminant_curves` without writing them out; a
    normal beyond the frame's edge counts as the mean of those in view when that is negative,
    and as 0 otherwise (see there).
    """
    lead, args = _kernel_args(app, ev, points, normals, h=h, sigma=sigma, threshold=threshold, miss=miss)
    out = np.empty(int(np.prod(lead[:-1], dtype=np.int64)))
    discriminant_curves(*args, float(colour_weight), out)
    return out.reshape(lead[:-1])


def presence(app: Appearance, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, *, h: float, sigma: float,
             threshold: float, miss: float, colour_weight: float) -> tuple[float, float, float]:
    """Evidence that one curve (M, 2) is on the object: ``(score, mean log D_i, mean c_i)``.

    ``score = mean_i (log D_i + w_c c_i)`` per normal; the other two are its edge and colour parts.
    The means are taken over the normals whose base point is in the picture (all of them
    when none is): beyond the frame's edge there are no data, and a normal there reads as a
    missed boundary, so an object the edge cuts would be judged on what it does not show.
    How much of the curve is in view is the confidence's own factor (:func:`confidence`).
    """
    log_d, colour = per_normal(app, ev, points, normals, h=h, sigma=sigma, threshold=threshold, miss=miss)
    seen = in_picture(np.asarray(points).reshape(-1, 2), ev.fimg.shape, ev.area)
    return presence_in_view(log_d, colour, seen, colour_weight)


def presence_in_view(log_d: np.ndarray, colour: np.ndarray, seen: np.ndarray,
                     colour_weight: float) -> tuple[float, float, float]:
    """:func:`presence` from one curve's terms per normal (:func:`per_normal`) and which of its
    normals are in the picture (:func:`in_picture`)."""
    if seen.any() and not seen.all():
        log_d, colour = log_d[seen], colour[seen]
    e, col = float(log_d.mean()), float(colour.mean())
    return e + colour_weight * col, e, col


#: the confidence is 1 while at least this share of the curve lies inside the frame (the trackers
#: give it as a share of the template's own on its first frame, :class:`~trackcli.observe.presence.Presence`) ...
VISIBLE_FULL = 0.8
#: ... and 0 at or below this share: half an outline beyond the frame's edge is scored by the half
#: in view alone, and a look-alike there can score like the object; such an estimate is not held
#: (the same share below which the curves' scores read the normals beyond the edge as missed)
VISIBLE_NONE = IN_VIEW_LEAST


def in_picture(points: np.ndarray, frame_shape: tuple[int, ...],
               area: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Which of the points ``(M, 2)`` lie inside a frame of ``frame_shape`` (h, w, ...), or inside
    its picture ``area = (x0, y0, x1, y1)`` when it has bars: bool (M,)."""
    h, w = frame_shape[:2]
    x0, y0, x1, y1 = area if area is not None else (0, 0, w, h)
    x, y = points[:, 0], points[:, 1]
    return (x >= x0) & (x <= x1 - 1) & (y >= y0) & (y <= y1 - 1)


def visible_share(points: np.ndarray, frame_shape: tuple[int, ...],
                  area: tuple[int, int, int, int] | None = None) -> float:
    """The share of a curve's points ``(M, 2)`` that lie inside the frame or its picture
    (:func:`in_picture`)."""
    return float(np.mean(in_picture(points, frame_shape, area)))


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


def confidence(presence_score: float, spread: float, *, reference: float, centre: float = 0.3,
               visible: float = 1.0) -> float:
    """A per-frame confidence in [0, 1] that the estimate is on the object.

    ``reference`` is the presence score of the template on the frame it starts on: what the
    object looks like when it is certainly there.  The confidence is a logistic function of
    the presence score, 0.5 at ``centre * reference`` (but at least 0.05: evidence barely
    above background is not enough), of width ``max(reference / 4, 0.1)``, times a factor
    for the spread of the estimate's position (``spread`` = RMS spread of the translation in
    units of the object's size): 1 while the spread is below 0.25 object sizes, falling to 0
    at 1 size (a sample set spread over the image has not located the object, whatever its
    mean scores), and times a factor for the share ``visible`` of the curve inside the frame:
    1 from :data:`VISIBLE_FULL` up, 0 at :data:`VISIBLE_NONE` and below.  Beyond the edge
    there are no data, so a curve that has slid mostly out of the frame keeps only the
    evidence of the few normals that reach back into it (on a street clip, a contour that
    had followed a car off the frame's edge was called held at confidence 0.9 for 40 frames
    on the edges of whatever came past).
    """
    if not math.isfinite(presence_score):
        return 0.0
    ref = max(float(reference), 0.0) if math.isfinite(reference) else 0.0
    c = max(centre * ref, 0.05)
    width = max(ref / 4.0, 0.1)
    z = (presence_score - c) / width
    p = 1.0 / (1.0 + math.exp(-z)) if z > -50 else 0.0
    if math.isfinite(spread):
        p *= min(1.0, max(0.0, (1.0 - spread) / 0.75))
    p *= min(1.0, max(0.0, (visible - VISIBLE_NONE) / (VISIBLE_FULL - VISIBLE_NONE)))
    return float(p)


# ---------------------------------------------------------------------------------------------
# Re-acquisition: a proposal from the colour map (ICONDENSATION, AC §12 notes)


def colour_peaks(cmap: np.ndarray | LazyColourMap, size: float, *, count: int = 5, floor: float = 0.25,
                 window: tuple[float, float, float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Where in the frame object-coloured regions of the object's size are: ``(centres (K, 2), strengths (K,))``.

    The colour log-ratio map is averaged over a box of the object's size (on a map shrunk so
    that the object spans about 8 pixels), and its ``count`` largest local maxima above
    ``floor`` are returned, strongest first, with strengths ``max(value, 0)``.  Beyond the
    frame's edge the average reads 0 (no evidence), as the colour term does: mirrored, a thin
    dark line along the border of a video passed for an object-sized region and took the
    strongest peaks (on a street clip, three of four), so the proposal kept sending samples there.
    With ``window = (x0, y0, x1, y1)`` only maxima whose centres lie inside it count.
    """
    img = _as_image(colour_array(cmap))
    h, w = img.shape
    f = max(1, int(size / 8))
    small = cv2.resize(img, (max(1, w // f), max(1, h // f)), interpolation=cv2.INTER_AREA) if f > 1 else img
    k = max(1, int(round(size / f)))
    mean = cv2.blur(small, (k, k), borderType=cv2.BORDER_CONSTANT)
    peaks = (mean >= cv2.dilate(mean, np.ones((3, 3), np.uint8))) & (mean > floor)
    ys, xs = np.nonzero(peaks)
    cx = (xs + 0.5) * f * (w / (small.shape[1] * f)) - 0.5
    cy = (ys + 0.5) * f * (h / (small.shape[0] * f)) - 0.5
    if window is not None:
        inside = (cx >= window[0]) & (cx <= window[2]) & (cy >= window[1]) & (cy <= window[3])
        ys, xs, cx, cy = ys[inside], xs[inside], cx[inside], cy[inside]
    if ys.size == 0:
        return np.zeros((0, 2)), np.zeros(0)
    vals = mean[ys, xs].astype(np.float64)
    order = np.argsort(vals)[::-1][:count]
    return np.column_stack([cx[order], cy[order]]), vals[order]


def _log_gauss2(d: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Log density of a 2-D Gaussian at offsets ``d`` (n, 2)."""
    inv = np.linalg.inv(cov)
    _, logdet = np.linalg.slogdet(cov)
    q = np.einsum("ni,ij,nj->n", d, inv, d)
    return -0.5 * q - 0.5 * logdet - math.log(2 * math.pi)


#: standard deviation (of log-scale) added to the spread of the predicted scales when a
#: Gaussian is fitted to them: a sample set that has collapsed onto one scale still has a density
SCALE_SPREAD = 0.02


@dataclass(frozen=True)
class ScaleSearch:
    """How :func:`reacquisition_proposal` redraws the scale of its samples.

    ``log_scale(X)`` is the log of each sample's scale relative to the template, (n,);
    ``rescale(X, factor)`` multiplies each sample's scale by ``factor`` (n,), keeping its
    position and rotation (:meth:`trackcli.shapes.shape_space.ShapeSpace.scaled`); new
    scales are drawn log-uniform within ``[1 / largest, largest]`` of the template's.
    """

    log_scale: Callable[[np.ndarray], np.ndarray]
    rescale: Callable[[np.ndarray, np.ndarray], np.ndarray]
    largest: float


def reacquisition_proposal(centres: np.ndarray, strengths: np.ndarray, origin: np.ndarray, size: float,
                           frame_size: tuple[int, int], *, fraction: float, reappear: float = 0.1,
                           scale: ScaleSearch | None = None, window: tuple[float, float, float, float] | None = None):
    """An importance-sampling step for CONDENSATION while the object is lost.

    A share ``fraction`` of the predicted samples has its translation redrawn from ``g``, a
    mixture of isotropic Gaussians (standard deviation 0.1 object sizes) at the colour peaks
    ``centres`` weighted by ``strengths``, at rest (its previous state set equal to the
    new one); the other components of those samples are kept.
    The target prior is the dynamics' prediction ``f`` mixed with a small probability
    ``reappear`` that the object is anywhere in the frame, or in ``window`` (uniform ``u``):
    while lost, the object may come back where the motion model does not expect it.  Every sample then
    carries the correction

        log [ (1 - reappear) f(t) + reappear u(t) ] - log [ (1 - fraction) f(t) + fraction g(t) ],

    with ``f`` approximated by a Gaussian fitted to the predicted translations, which keeps
    the weighted set a fair sample of that prior times the likelihood (the importance
    weights of Isard & Blake's ICONDENSATION).

    With ``scale``, the redrawn samples also get a new scale, log-uniform within
    ``[1 / scale.largest, scale.largest]`` of the template's (an object that comes back, or
    is found again, nearer or farther than it was lost); ``f`` then includes a Gaussian
    fitted to the predicted log-scales, and ``u`` and ``g`` the log-uniform density.

    With ``window = (x0, y0, x1, y1)`` (image coordinates) ``u`` is uniform over the part of
    the window inside the frame instead of the whole frame, and 0 outside it: an object lost
    a moment ago is near where it was last seen (the caller grows the window with the time
    lost, and gives only the peaks inside it).

    Returns ``propose(prev, predicted, rng) -> (prev, shapes, log_correction)`` for
    :func:`trackcli.trackers.condensation.step`, or None when there is no peak.
    """
    if centres.shape[0] == 0:
        return None
    w = np.asarray(strengths, dtype=np.float64)
    w = w / w.sum()
    sd = 0.1 * size
    means = np.asarray(centres, dtype=np.float64) - np.asarray(origin, dtype=np.float64)[:2]
    ox, oy = float(origin[0]), float(origin[1])
    if window is None:
        log_u = -math.log(frame_size[0] * frame_size[1])
    else:
        wx0, wy0 = max(window[0], -0.5), max(window[1], -0.5)
        wx1, wy1 = min(window[2], frame_size[0] - 0.5), min(window[3], frame_size[1] - 0.5)
        log_u = -math.log(max(wx1 - wx0, 1.0) * max(wy1 - wy0, 1.0))
    span = math.log(scale.largest) if scale is not None else 0.0
    if scale is not None and not span > 0:
        raise ConfigError(f"scale search: the largest scale must be above 1, got {scale.largest!r}")

    def propose(prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = new.shape[0]
        t = new[:, :2]
        mu = t.mean(axis=0)
        cov = np.cov(t.T) + np.eye(2) * (0.05 * size) ** 2
        k = int(round(fraction * n))
        out = new.copy()
        out_prev = prev.copy()
        if scale is not None:
            log_s = scale.log_scale(new)
            s_mu, s_var = float(log_s.mean()), float(log_s.var()) + SCALE_SPREAD**2
        if k > 0:
            idx = rng.choice(n, size=k, replace=False)
            comp = rng.choice(means.shape[0], size=k, p=w)
            out[idx, :2] = means[comp] + sd * rng.standard_normal((k, 2))
            # a sample found this way starts at rest: no velocity from where its parent was
            if scale is not None:
                target = rng.uniform(-span, span, k)
                out[idx] = scale.rescale(out[idx], np.exp(target - log_s[idx]))
                out_prev[idx] = out[idx]
            else:
                out_prev[idx, :2] = out[idx, :2]
        t = out[:, :2]
        log_f = _log_gauss2(t - mu, cov)
        diff = t[:, None, :] - means[None, :, :]
        comp_log = np.log(w)[None, :] - 0.5 * (diff * diff).sum(axis=2) / sd**2 - math.log(2 * math.pi * sd * sd)
        top = comp_log.max(axis=1)
        log_g = top + np.log(np.exp(comp_log - top[:, None]).sum(axis=1))
        log_u_all: float | np.ndarray = log_u
        if window is not None:
            x, y = t[:, 0] + ox, t[:, 1] + oy
            log_u_all = np.where((x >= wx0) & (x <= wx1) & (y >= wy0) & (y <= wy1), log_u, -np.inf)
        if scale is not None:
            ls = log_s.copy()  # the redrawn samples' scales as the space gives them back
            if k > 0:
                ls[idx] = scale.log_scale(out[idx])
            log_f = log_f - 0.5 * (ls - s_mu) ** 2 / s_var - 0.5 * math.log(2 * math.pi * s_var)
            log_us = np.where(np.abs(ls) <= span * (1 + 1e-9), -math.log(2 * span), -np.inf)
            log_g = log_g + log_us
            log_u_all = log_u_all + log_us
        log_prior = np.logaddexp(math.log1p(-reappear) + log_f, math.log(reappear) + log_u_all)
        log_q = np.logaddexp(math.log1p(-fraction) + log_f if fraction < 1 else -np.inf, math.log(fraction) + log_g)
        return out_prev, out, log_prior - log_q

    return propose
