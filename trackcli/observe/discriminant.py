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

Colour: the appearance learned on the first frame
-------------------------------------------------
A colour log-ratio ``L`` per pixel, object against background, learned from the template on
its first frame (:mod:`trackcli.observe.appearance`), is averaged along each normal at a few
offsets inside and outside the curve: ``c_i = (mean_inside L - mean_outside L) / 2``, in
``[-3, 3]``, positive when the curve separates object-coloured from background-coloured pixels.

The log-likelihood of a curve
-----------------------------
    log p(Z | X) = Σ_i [ log D_i + w_c c_i ]   (+ a constant),

``w_c`` = ``observation.colour_weight``.  The *presence score* of a curve is the same sum
divided by the number of normals: the average evidence per normal that the object is there.
It does not vanish when every sample of a particle set is wrong — a curve on background has a
score near or below zero whatever the other samples see — and is what the trackers' confidence
and ``lost`` verdict are computed from (:func:`confidence`).

The colour proposal of re-acquisition is :mod:`trackcli.observe.reacquire`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from trackcli.errors import DataError
from trackcli.observe.appearance import (Appearance, LazyColourMap, colour_array, feature_density, is_grey,
                                         local_mean_deviation)
from trackcli.observe.kernels import IN_VIEW_LEAST, discriminant_curves, discriminant_normals
from trackcli.observe.measure import _as_image, _as_normals, _scan_chunks

# is_grey and local_mean_deviation (trackcli.observe.appearance) are read from here by shapes.draw
__all__ = ["FrameEvidence", "confidence", "evidence", "in_picture", "is_grey", "local_mean_deviation",
           "normals_with_features", "per_normal", "per_normal_reference", "presence", "presence_in_view", "score",
           "visible_share"]


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
