"""The edge likelihoods of the papers, on the features of :mod:`trackcli.observe.measure`.

- :func:`log_likelihood`, the clutter model of CONDENSATION (AC eq 12.2): ``N`` hypotheses at
  once, ``sum_i log(1 + (1 / (sqrt(2 pi) sigma alpha)) sum_m exp(-nu_m^2 / (2 sigma^2)))``,
  the inner sum running over every feature on normal ``i``'s fixed segment ``[-h, h]``;
- :func:`truncated_log_likelihood`, the simpler model of Isard & Blake 1996 (their eqs
  10–11), ``-(1 / (2 sigma^2)) mean_i min(nu_i^2, rho)`` with ``nu_i`` the feature nearest
  the curve on normal ``i``.
"""

from __future__ import annotations

import math

import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.observe.measure import (MAX_HALF_WIDTH, _as_image, _as_normals, _check_polarity, _check_threshold,
                                      _scan_chunks)

__all__ = ["log_likelihood", "truncated_log_likelihood"]


def log_likelihood(
    fimg: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    *,
    h: float,
    sigma: float,
    alpha: float,
    threshold: float,
    polarity: str = "any",
) -> np.ndarray:
    """Log of the clutter observation density of many hypothesised curves (AC eq 12.2).

    For each curve, ``log p(Z | X) = sum_i log(1 + c sum_m exp(-nu_m^2 / (2 sigma^2)))`` with
    ``c = 1 / (sqrt(2 pi) sigma alpha)``, the inner sum over every feature ``m`` found on
    normal ``i``'s segment ``[-h, h]`` and ``nu_m`` its offset from the curve; up to an
    additive constant common to all curves.  A normal with no feature contributes 0.

    Parameters
    ----------
    fimg : ndarray of shape (H, W)
        Feature image from :func:`trackcli.observe.measure.feature_image`.
    points, normals : ndarray of shape (..., M, 2)
        Measurement points and unit normals of every hypothesis, e.g. (N, M, 2).
    h : float
        Fixed search half-width, pixels (a few ``sigma``).
    sigma : float
        Standard deviation of a true feature about the curve, pixels.
    alpha : float
        Clutter parameter ``alpha = q lambda``, per pixel.
    threshold : float
        Contrast threshold, grey levels per pixel.
    polarity : {"any", "light_to_dark", "dark_to_light"}
        Accepted sign of the intensity change along the normal.

    Returns
    -------
    ndarray of shape (...), float64
        One log-likelihood per curve, e.g. (N,).
    """
    for name, value in (("sigma", sigma), ("alpha", alpha)):
        if not (np.isfinite(value) and value > 0):
            raise ConfigError(f"{name}: expected a number > 0, got {value!r}")
    if not (np.isfinite(h) and 0 <= h <= MAX_HALF_WIDTH):
        raise ConfigError(f"h: expected a search half-width in [0, {MAX_HALF_WIDTH}] px, got {h!r}")
    img = _as_image(fimg)
    pts, nrm, lead = _as_normals(points, normals)
    if len(lead) < 1:
        raise DataError(f"points: expected shape (..., M, 2), got {lead + (2,)}")
    c = 1.0 / (math.sqrt(2.0 * math.pi) * sigma * alpha)
    scale = np.float32(-0.5 / sigma**2)
    per_normal = np.zeros(pts.shape[0])
    chunks = _scan_chunks(img, pts, nrm, float(h), _check_threshold(threshold), _check_polarity(polarity))
    for k0, k1, row, nu, _ in chunks:
        near = np.bincount(row, weights=np.exp(nu * nu * scale), minlength=k1 - k0)
        per_normal[k0:k1] = np.log1p(c * near)
    return per_normal.reshape(lead).sum(axis=-1)


def truncated_log_likelihood(
    fimg: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    *,
    h: float,
    sigma: float,
    threshold: float,
    polarity: str = "any",
) -> np.ndarray:
    """Log of the truncated-Gaussian observation density of many curves (000 eqs 10–11).

    Isard & Blake (1996) score a curve by the feature nearest to it on each normal:

        log p(Z | X) = -(1 / (2 sigma^2)) * mean_i phi_i,
        phi_i = nu_i^2 if a feature lies within |nu_i| <= h of the curve, else rho,

    the mean over the ``M`` normals standing for the paper's integral over the curve
    parameter ``s`` in [0, 1].  The penalty for a normal with no feature is taken as
    ``rho = h^2``, which makes ``phi`` continuous at the edge of the search segment (the
    paper leaves ``rho`` open, "related to the probability of failing to find a feature").

    Unlike the clutter model of AC eq 12.2 (:func:`log_likelihood`), extra features near a
    curve add nothing beyond the nearest one, and the score is bounded, between
    ``-h^2 / (2 sigma^2)`` (nothing found) and 0 (a feature exactly on every normal): two
    well-outlined objects score alike, which lets a sample set hold several of them at once
    (the multi-modal experiment of 000 §5.1).

    Parameters
    ----------
    fimg, points, normals, threshold, polarity
        As for :func:`log_likelihood`.
    h : float
        Search half-width ``delta``, pixels; also sets the penalty ``rho = h^2``.
    sigma : float
        Scale of the quadratic, pixels.

    Returns
    -------
    ndarray of shape (...), float64
        The log-likelihood of each curve, bounded above by 0.
    """
    if not (np.isfinite(sigma) and sigma > 0):
        raise ConfigError(f"sigma: expected a number > 0, got {sigma!r}")
    if not (np.isfinite(h) and 0 < h <= MAX_HALF_WIDTH):
        raise ConfigError(f"h: expected a search half-width in (0, {MAX_HALF_WIDTH}] px, got {h!r}")
    img = _as_image(fimg)
    pts, nrm, lead = _as_normals(points, normals)
    if len(lead) < 1:
        raise DataError(f"points: expected shape (..., M, 2), got {lead + (2,)}")
    rho = float(h) ** 2
    phi = np.full(pts.shape[0], rho)
    chunks = _scan_chunks(img, pts, nrm, float(h), _check_threshold(threshold), _check_polarity(polarity))
    for k0, _, row, nu, _ in chunks:
        # rows are ascending, so each normal's features are one run: its smallest nu^2 is
        # the minimum over the run (np.minimum.reduceat over the run starts).
        if row.size:
            starts = np.flatnonzero(np.r_[True, row[1:] != row[:-1]])
            nearest = np.minimum.reduceat((nu * nu).astype(np.float64), starts)
            phi[k0 + row[starts]] = np.minimum(nearest, rho)
    return -phi.reshape(lead).mean(axis=-1) / (2.0 * sigma**2)
