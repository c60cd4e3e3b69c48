"""Re-acquisition: a proposal from the colour map (ICONDENSATION, AC §12 notes).

While the tracker is lost, :func:`colour_peaks` finds object-coloured regions of the object's
size in a window about where it was last held (growing with the time lost, up to the whole
frame) and :func:`reacquisition_proposal` draws a share of the samples there, with the
importance weights that keep the set a fair sample of the posterior (Isard & Blake's
ICONDENSATION).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from trackcli.errors import ConfigError
from trackcli.observe.appearance import LazyColourMap, colour_array
from trackcli.observe.measure import _as_image

__all__ = ["ScaleSearch", "colour_peaks", "reacquisition_proposal"]


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
