"""Mode-based multiple hypotheses: the steps of Cham & Rehg (004) as pure functions.

The density over shape is a handful of *modes*, each a Gaussian over the second-order state
``𝒳 = (X_{k-1}; X_k)`` (a :class:`~trackcli.dynamics.kalman.KalmanState`) with a log weight.
Together they form the piecewise-Gaussian density of 004 eq 2,

    p(X) ∝ max_j  w_j exp(-½ (X - m_j)ᵀ P_j⁻¹ (X - m_j)),

in which a point belongs to the mode that contributes most there; ``w_j`` is the height of
mode ``j``'s peak (not its mass, so a cluster of weak modes does not outweigh a strong one,
004 Fig 2).  One frame is, in order (004 §3):

1. the prior: every mode through the Kalman prediction (:func:`trackcli.dynamics.kalman.predict`);
2. seeds drawn from the piecewise-Gaussian prior (:func:`draw_seeds`, 004 §3.3.2): each mode's
   predicted mean, then draws from mode ``j`` chosen with probability ``∝ w_j``, kept only
   when they fall in mode ``j``'s own cell of the piecewise density;
3. every seed refined to a local maximum (:func:`refine`): Gauss–Newton steps, each one a
   measurement along the normals of the current curve (gated by the prior mode) and a Kalman
   assimilation against the seed's prior mode (an iterated Kalman update, which is Gauss–Newton on the posterior;
   its covariance is the mode's local statistics, 004 §3.3.3);
4. each refined hypothesis weighted by its prior mode's weight times the likelihood of its
   curve (:func:`hypothesis_log_weights`, 004 §3.4: a likelihood mode paired with its prior
   mode);
5. hypotheses that converged to the same place merged and the best ``K`` kept
   (:func:`merge_modes`).

Notation: ``Nx`` the shape-space dimension, ``K`` modes, ``N`` seeds; distances between
shapes in the metric ``H`` of the shape-space (AC eq 8.5–8.6), i.e. the RMS displacement of
the curve in pixels.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.dynamics import kalman
from trackcli.dynamics.kalman import KalmanState

__all__ = ["component_log_density", "draw_seeds", "hypothesis_log_weights", "merge_modes", "normalise_log",
           "precisions", "refine"]

#: ``measure(X, P) -> (Z, S)``: the information of one measurement of each of ``N`` curves
#: ``X`` (N, Nx), gated by the shape covariances ``P`` (N, Nx, Nx); ``Z`` (N, Nx) relative to ``X``.
Measure = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def precisions(covs: np.ndarray) -> np.ndarray:
    """Inverses (pseudo-inverses when singular) of covariances ``(K, Nx, Nx)``."""
    covs = np.asarray(covs, dtype=float)
    return np.stack([np.linalg.pinv(0.5 * (c + c.T), hermitian=True) for c in covs])


def component_log_density(X: np.ndarray, means: np.ndarray, precs: np.ndarray, log_w: np.ndarray) -> np.ndarray:
    """``log w_j - ½ (X - m_j)ᵀ P_j⁻¹ (X - m_j)`` for every point and mode: (N, Nx) → (N, K).

    The piecewise-Gaussian density (004 eq 2) at a point is the maximum over ``j``; the
    mode attaining it owns the point.
    """
    X = np.atleast_2d(np.asarray(X, dtype=float))
    d = X[:, None, :] - np.asarray(means, dtype=float)[None]
    maha = np.einsum("nki,kij,nkj->nk", d, precs, d)
    return np.asarray(log_w, dtype=float)[None] - 0.5 * maha


def normalise_log(log_w: np.ndarray) -> np.ndarray:
    """Log weights shifted so that their exponentials sum to 1."""
    log_w = np.asarray(log_w, dtype=float)
    top = float(np.max(log_w))
    return log_w - (top + np.log(np.sum(np.exp(log_w - top))))


def _root(cov: np.ndarray) -> np.ndarray:
    """A square root ``L`` with ``L Lᵀ = cov`` of a positive semi-definite matrix."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    return vectors * np.sqrt(np.clip(values, 0.0, None))


def draw_seeds(means: np.ndarray, covs: np.ndarray, log_w: np.ndarray, n: int, rng: np.random.Generator, *,
               spread: float = 1.0, truncate: bool = True, rounds: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Starting points for the local search, drawn from the piecewise-Gaussian prior (004 §3.3.2).

    Parameters
    ----------
    means : ndarray of shape (K, Nx)
        Predicted shapes of the modes.
    covs : ndarray of shape (K, Nx, Nx)
        Their predicted covariances.
    log_w : ndarray of shape (K,)
        Log weights (peak heights) of the modes.
    n : int
        Seeds wanted, at least ``K``.
    rng : numpy.random.Generator
    spread : float
        Factor on the standard deviations the draws are made with (1: the prior itself).
    truncate : bool
        Keep a draw from mode ``j`` only where mode ``j`` is the largest component of the
        piecewise density (004's rejection step); a rejected draw is drawn again, at most
        ``rounds`` times, and then left out.
    rounds : int
        Redraws allowed for rejected seeds.

    Returns
    -------
    seeds : ndarray of shape (N', Nx)
        The ``K`` means first (in the order given), then the draws; ``K <= N' <= n``.
    parent : ndarray of shape (N',), int
        The mode each seed was drawn from.
    """
    means = np.atleast_2d(np.asarray(means, dtype=float))
    k, nx = means.shape
    covs = np.asarray(covs, dtype=float)
    log_w = np.asarray(log_w, dtype=float)
    if covs.shape != (k, nx, nx) or log_w.shape != (k,):
        raise DataError(f"draw_seeds: expected covs ({k}, {nx}, {nx}) and log_w ({k},), got {covs.shape} and {log_w.shape}")
    if n < k:
        raise ConfigError(f"draw_seeds: {n} seeds cannot start {k} modes (need n >= K)")
    if not (np.isfinite(spread) and spread > 0):
        raise ConfigError(f"spread: expected a number > 0, got {spread!r}")
    roots = np.stack([_root(c) for c in covs])
    precs = precisions(covs) if truncate and k > 1 else None
    p = np.exp(normalise_log(log_w))
    seeds, parent = [means], [np.arange(k)]
    want = n - k
    for _ in range(rounds + 1 if truncate else 1):
        if want <= 0:
            break
        j = rng.choice(k, size=want, p=p)
        draws = means[j] + spread * np.einsum("nij,nj->ni", roots[j], rng.standard_normal((want, nx)))
        if precs is not None:
            owner = np.argmax(component_log_density(draws, means, precs, log_w), axis=1)
            ok = owner == j
            draws, j = draws[ok], j[ok]
        seeds.append(draws)
        parent.append(j)
        want -= j.size
    return np.concatenate(seeds), np.concatenate(parent)


def refine(prior: Sequence[KalmanState], seeds: np.ndarray, measure: Measure, iterations: int) -> list[KalmanState]:
    """Take every seed to a local maximum of its posterior by Gauss–Newton steps (004 §3.3.3).

    Step ``i`` measures the curves at the current shapes ``X_i`` (the seeds at first), with
    the validation gates of the seed's prior mode (AC Fig 8.6: the uncertainty of the
    prediction, now centred on the current curve; gates narrowed to the refined covariance
    lost the object on the cluttered sample clip).  The information ``Z_i`` of that
    measurement is relative to ``X_i``; relative to the mode's prediction ``X̃`` it is ``Z_i + S_i (X_i - X̃)``, and
    :func:`trackcli.dynamics.kalman.assimilate` against the prior mode gives the next
    shape and its covariance.  Which feature each normal takes depends on where the curve
    is, so seeds in different places climb to different maxima.  With a seed at the
    prediction and one step this is exactly one Kalman update (AC Fig 10.3).

    Parameters
    ----------
    prior : sequence of N KalmanState
        The prior of each seed: its predicted mode (displaced with the seed when the motion
        prior made it jump).
    seeds : ndarray of shape (N, Nx)
    measure : callable
        ``measure(X, P) -> (Z, S)`` (see :data:`Measure`).
    iterations : int
        Gauss–Newton steps, at least 1.

    Returns
    -------
    list of KalmanState
        The refined belief of each seed.
    """
    if iterations < 1:
        raise ConfigError(f"iterations: expected an integer >= 1, got {iterations!r}")
    seeds = np.atleast_2d(np.asarray(seeds, dtype=float))
    if len(prior) != seeds.shape[0]:
        raise DataError(f"refine: expected one prior per seed, got {len(prior)} for {seeds.shape[0]} seeds")
    X = seeds.copy()
    P = np.stack([p.P for p in prior])
    states: list[KalmanState] = []
    for _ in range(iterations):
        Z, S = measure(X, P)
        states = [kalman.assimilate(p, Z[i] + S[i] @ (X[i] - p.X), S[i]) for i, p in enumerate(prior)]
        X = np.stack([s.X for s in states])
    return states


def hypothesis_log_weights(parent: np.ndarray, prior_log_w: np.ndarray, loglik: np.ndarray) -> np.ndarray:
    """Log weight of each refined hypothesis: its prior mode's weight times its likelihood.

    ``log w_j + log p(z | X)`` with ``j`` the hypothesis's prior mode, (N,) parents and
    log-likelihoods → (N,).  The refinement already pairs the hypothesis with its prior mode
    (004 §3.4); its weight is not lowered further by its distance from the prediction: as
    004 argues for weak predictors, the likelihood decides between the modes, and a mode
    held in place by a confident prediction is exactly how a single Kalman filter is lured
    away by clutter.
    """
    parent = np.asarray(parent, dtype=int)
    return np.asarray(prior_log_w, dtype=float)[parent] + np.asarray(loglik, dtype=float)


def merge_modes(X: np.ndarray, log_w: np.ndarray, metric: np.ndarray, distance: float, keep: int) -> np.ndarray:
    """Merge hypotheses that reached the same mode and keep the ``keep`` heaviest modes.

    In order of decreasing weight, a hypothesis becomes a mode unless it lies within
    ``distance`` of a mode already kept, ``‖X_a - X_b‖_H = sqrt(ΔXᵀ H ΔX) < distance``, in
    which case it is merged into it.  A mode keeps the shape, covariance and weight of its
    heaviest member: the peak of the piecewise density (004 eq 2) rather than the sum of its
    members, so that many seeds falling into one mode do not inflate it.

    Parameters
    ----------
    X : ndarray of shape (N, Nx)
        Refined shapes.
    log_w : ndarray of shape (N,)
    metric : ndarray of shape (Nx, Nx)
        ``H`` of the shape-space: distances are RMS curve displacements, px.
    distance : float
        Merge radius, > 0.
    keep : int
        Most modes kept, >= 1.

    Returns
    -------
    ndarray of int
        Indices into ``X`` of the modes kept, heaviest first; at most ``keep`` of them,
        pairwise at least ``distance`` apart.
    """
    if not (np.isfinite(distance) and distance > 0):
        raise ConfigError(f"merge_distance: expected a number > 0, got {distance!r}")
    if keep < 1:
        raise ConfigError(f"modes: expected an integer >= 1, got {keep!r}")
    X = np.atleast_2d(np.asarray(X, dtype=float))
    log_w = np.asarray(log_w, dtype=float)
    if log_w.shape != (X.shape[0],):
        raise DataError(f"merge_modes: expected log_w of shape ({X.shape[0]},), got {log_w.shape}")
    order = np.argsort(-np.where(np.isnan(log_w), -np.inf, log_w), kind="stable")
    kept: list[int] = []
    limit = distance * distance
    for i in order:
        if kept:
            d = X[kept] - X[i]
            if np.min(np.einsum("ki,ij,kj->k", d, metric, d)) < limit:
                continue
        kept.append(int(i))
        if len(kept) == keep:
            break
    return np.asarray(kept, dtype=int)
