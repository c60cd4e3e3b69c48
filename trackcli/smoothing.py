"""Offline smoothing of contour tracks: the Rauch–Tung–Striebel pass over the Kalman filter.

Notation follows :mod:`trackcli.kalman`: the second-order state ``𝒳_k = (X_{k-1}; X_k)``
(length ``2 Nx``) evolves as ``𝒳_k = A 𝒳_{k-1} + offset + B w_k`` (AC eqs 9.16–9.18), and
the forward pass is the filter of AC Fig 10.3 (:func:`trackcli.kalman.predict` and
:func:`trackcli.kalman.assimilate`).  Given the filtered beliefs ``(𝒳̂_k, P_k)`` of frames
``k = 0 .. T-1`` the backward pass (Rauch, Tung & Striebel 1965) is::

    𝒳̃_{k+1} = A 𝒳̂_k + offset,          P̃_{k+1} = A P_k Aᵀ + B Bᵀ
    J_k      = P_k Aᵀ P̃_{k+1}⁻¹
    𝒳ˢ_k     = 𝒳̂_k + J_k (𝒳ˢ_{k+1} - 𝒳̃_{k+1})
    Pˢ_k     = P_k + J_k (Pˢ_{k+1} - P̃_{k+1}) J_kᵀ

starting from ``𝒳ˢ_{T-1} = 𝒳̂_{T-1}``.  The lag-one cross-covariance that EM needs
(:mod:`trackcli.em`) is ``Cov(𝒳_{k+1}, 𝒳_k | all frames) = Pˢ_{k+1} J_kᵀ``.

Observations in information form
--------------------------------
The tracker's measurement of a frame is the information pair of AC §8: ``S`` (any rank)
and ``Z``, relative to the prediction.  Written absolutely, ``z = Z + S X̃`` is distributed
as ``S X + v`` with ``v ~ N(0, S)``.  With ``S = L Lᵀ`` (``L`` of shape ``(Nx, r)``,
``r = rank S``) this is the same information as the whitened measurement
``y = Lᵀ X + e``, ``e ~ N(0, I_r)``, whose log-density :func:`filter_information` sums
into the log-likelihood of a sequence.  The log-likelihood is therefore that of the
whitened measurements: it differs from the density of any other parametrisation of the
same data by a constant that does not depend on the dynamics, which is all that
comparing or maximising over dynamics needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import scipy.linalg

from . import kalman
from .errors import DataError
from .kalman import KalmanState

__all__ = ["Smoothed", "filter_information", "rts_smooth"]

# Eigenvalues of S below this fraction of the largest are treated as no information.
_RANK_RTOL = 1e-10


@dataclass(frozen=True, eq=False)
class Smoothed:
    """Smoothed beliefs over a sequence of ``T`` frames.

    Attributes
    ----------
    states : list of KalmanState, length T
        ``(𝒳ˢ_k, Pˢ_k)``: the belief over ``(X_{k-1}; X_k)`` given every frame.
    cross : ndarray of shape (T - 1, 2 Nx, 2 Nx)
        ``cross[k] = Cov(𝒳_{k+1}, 𝒳_k | all frames)``, the lag-one cross-covariances.
    """

    states: list[KalmanState]
    cross: np.ndarray

    @property
    def X(self) -> np.ndarray:
        """Smoothed shapes ``X̂ˢ_k``, shape (T, Nx)."""
        return np.array([s.X for s in self.states])

    @property
    def X_std(self) -> np.ndarray:
        """Their standard deviations ``sqrt(diag Pˢ)``, shape (T, Nx)."""
        return np.array([s.X_std for s in self.states])


def _solve_psd(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``matrix⁻¹ rhs`` for a symmetric PSD ``matrix``; pseudo-inverse if it is singular.

    A singular predicted covariance arises when some direction of the state has no process
    noise (``B0`` singular) and was known exactly; the pseudo-inverse then leaves that
    direction as filtered, which is its smoothed value.
    """
    try:
        factor = scipy.linalg.cho_factor(matrix, check_finite=False)
        out = scipy.linalg.cho_solve(factor, rhs, check_finite=False)
        if np.all(np.isfinite(out)):
            return out
    except np.linalg.LinAlgError:
        pass
    return np.linalg.pinv(matrix, hermitian=True) @ rhs


def rts_smooth(dynamics: Any, filtered: Sequence[KalmanState]) -> Smoothed:
    """Rauch–Tung–Striebel backward pass over the filtered beliefs of a sequence.

    Parameters
    ----------
    dynamics : object
        The AR(2) model the forward pass used (``A1, A2, B0`` (Nx, Nx), ``mean`` (Nx,)).
    filtered : sequence of KalmanState, length T >= 1
        Posterior of every frame from the forward pass, in order, each obtained from the
        previous one by :func:`trackcli.kalman.predict` then
        :func:`trackcli.kalman.assimilate` (the first may start anywhere).

    Returns
    -------
    Smoothed
        Smoothed means and covariances and the lag-one cross-covariances.
    """
    filtered = list(filtered)
    if not filtered:
        raise DataError("nothing to smooth: the sequence has no frames")
    A, B, offset = kalman.state_space(dynamics)
    if A.shape[0] != filtered[0].mean.size:
        raise DataError(f"the dynamics have Nx = {A.shape[0] // 2} but the filtered states have "
                        f"Nx = {filtered[0].nx}")
    Q = B @ B.T
    T = len(filtered)
    n = A.shape[0]
    means = [np.empty(0)] * T
    covs = [np.empty(0)] * T
    cross = np.zeros((max(T - 1, 0), n, n))
    means[-1] = filtered[-1].mean
    covs[-1] = filtered[-1].cov
    for k in range(T - 2, -1, -1):
        m, P = filtered[k].mean, filtered[k].cov
        m_pred = A @ m + offset
        P_pred = A @ P @ A.T + Q
        P_pred = 0.5 * (P_pred + P_pred.T)
        J = _solve_psd(P_pred, A @ P).T  # P Aᵀ P̃⁻¹ (P and P̃ symmetric)
        means[k] = m + J @ (means[k + 1] - m_pred)
        cov = P + J @ (covs[k + 1] - P_pred) @ J.T
        covs[k] = 0.5 * (cov + cov.T)
        cross[k] = covs[k + 1] @ J.T
    return Smoothed([KalmanState(m, c) for m, c in zip(means, covs)], cross)


def _whiten(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvectors ``V`` (n, r) and ``sqrt`` eigenvalues ``d`` (r,) of ``S`` on its range: ``L = V diag(d)``."""
    values, vectors = np.linalg.eigh(S)
    top = float(values[-1]) if values.size else 0.0
    keep = values > _RANK_RTOL * top if top > 0 else np.zeros(values.size, dtype=bool)
    return vectors[:, keep], np.sqrt(values[keep])


def _whitened(z: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``L`` (m, r) with ``S = L Lᵀ`` on its range, and ``y`` (r,) with ``z = L y``.

    ``z = S X + v = L (Lᵀ X + e)``, so ``y = Lᵀ X + e`` with ``e ~ N(0, I_r)``.
    """
    V, d = _whiten(S)
    return V * d, (V.T @ z) / d


def _loglik(innovation: np.ndarray, G: np.ndarray) -> tuple[float, Any]:
    """``log N(innovation; 0, G)`` and the Cholesky factor of ``G``."""
    factor = scipy.linalg.cho_factor(0.5 * (G + G.T))
    logdet = 2.0 * float(np.sum(np.log(np.diag(factor[0]))))
    quad = float(innovation @ scipy.linalg.cho_solve(factor, innovation))
    return -0.5 * (innovation.size * math.log(2.0 * math.pi) + logdet + quad), factor


def _measurement_loglik(predicted: KalmanState, z: np.ndarray, S: np.ndarray) -> float:
    """Log-density of the whitened measurement of ``X_k`` given the prediction."""
    L, y = _whitened(z, S)
    if y.size == 0:
        return 0.0
    G = L.T @ predicted.P @ L + np.eye(y.size)
    return _loglik(y - L.T @ predicted.X, G)[0]


def _initial_step(prior: KalmanState, z: np.ndarray, S: np.ndarray) -> tuple[KalmanState, float]:
    """Assimilate frames 0 and 1 (``z``, ``S`` of shapes (2, Nx), (2, Nx, Nx)) into the prior.

    The gain-form update of :func:`trackcli.kalman.assimilate` with Joseph covariance, for a
    measurement of both blocks of the state.
    """
    nx = prior.nx
    blocks = [_whitened(z[i], S[i]) for i in range(2)]
    r = [y.size for _, y in blocks]
    if sum(r) == 0:
        return prior, 0.0
    H = np.zeros((sum(r), 2 * nx))
    H[: r[0], :nx] = blocks[0][0].T
    H[r[0]:, nx:] = blocks[1][0].T
    y = np.concatenate([blocks[0][1], blocks[1][1]])
    mean, cov = prior.mean, prior.cov
    innovation = y - H @ mean
    PHt = cov @ H.T
    loglik, factor = _loglik(innovation, H @ PHt + np.eye(y.size))
    gain = scipy.linalg.cho_solve(factor, PHt.T).T
    reduce = np.eye(2 * nx) - gain @ H
    new_cov = reduce @ cov @ reduce.T + gain @ gain.T
    return KalmanState(mean + gain @ innovation, 0.5 * (new_cov + new_cov.T)), loglik


def filter_information(
    dynamics: Any,
    prior: KalmanState,
    z: np.ndarray,
    S: np.ndarray,
) -> tuple[list[KalmanState], float]:
    """Forward pass over absolute information pairs, with the log-likelihood of the sequence.

    Parameters
    ----------
    dynamics : object
        AR(2) model (``A1, A2, B0`` (Nx, Nx), ``mean`` (Nx,)).
    prior : KalmanState
        Belief over ``(X_0; X_1)``, the first two frames, before any measurement.  It does
        not depend on the dynamics, so the log-likelihoods of different dynamics are
        comparable (and EM's is a proper marginal likelihood).
    z : ndarray of shape (T, Nx)
        Absolute information vectors ``z_k = Z_k + S_k X̃_k``, T >= 2.
    S : ndarray of shape (T, Nx, Nx)
        Information matrices (symmetric positive semi-definite, any rank; 0 = no measurement).

    Returns
    -------
    filtered : list of KalmanState, length T - 1
        Posterior over ``(X_{k-1}; X_k)`` for ``k = 1 .. T-1``: the first combines the prior
        with frames 0 and 1, each later one is :func:`trackcli.kalman.predict` then
        :func:`trackcli.kalman.assimilate` with ``Z = z_k - S_k X̃_k``.
    loglik : float
        ``log p(y_0 .. y_{T-1})`` of the whitened measurements (module docstring).
    """
    z = np.asarray(z, dtype=float)
    S = np.asarray(S, dtype=float)
    nx = prior.nx
    if z.ndim != 2 or z.shape[1] != nx or z.shape[0] < 2:
        raise DataError(f"information vectors must have shape (T >= 2, {nx}), got {z.shape}")
    if S.shape != (z.shape[0], nx, nx):
        raise DataError(f"information matrices must have shape ({z.shape[0]}, {nx}, {nx}), got {S.shape}")
    state, total = _initial_step(prior, z[:2], S[:2])
    filtered = [state]
    for k in range(2, z.shape[0]):
        predicted = kalman.predict(state, dynamics)
        total += _measurement_loglik(predicted, z[k], S[k])
        state = kalman.assimilate(predicted, z[k] - S[k] @ predicted.X, S[k])
        filtered.append(state)
    return filtered, total
