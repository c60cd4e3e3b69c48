"""Rauch–Tung–Striebel smoothing over the Kalman filter, and the information-form forward pass.

Notation follows :mod:`trackcli.dynamics.kalman`: the second-order state ``𝒳_k = (X_{k-1}; X_k)``
(length ``2 Nx``) evolves as ``𝒳_k = A 𝒳_{k-1} + offset + B w_k`` (AC eqs 9.16–9.18), and
the forward pass is the filter of AC Fig 10.3 (:func:`trackcli.dynamics.kalman.predict` and
:func:`trackcli.dynamics.kalman.assimilate`).  Given the filtered beliefs ``(𝒳̂_k, P_k)`` of frames
``k = 0 .. T-1`` the backward pass (Rauch, Tung & Striebel 1965) is::

    𝒳̃_{k+1} = A 𝒳̂_k + offset,          P̃_{k+1} = A P_k Aᵀ + B Bᵀ
    J_k      = P_k Aᵀ P̃_{k+1}⁻¹
    𝒳ˢ_k     = 𝒳̂_k + J_k (𝒳ˢ_{k+1} - 𝒳̃_{k+1})
    Pˢ_k     = P_k + J_k (Pˢ_{k+1} - P̃_{k+1}) J_kᵀ

starting from ``𝒳ˢ_{T-1} = 𝒳̂_{T-1}``.  The lag-one cross-covariance that EM needs
(:mod:`trackcli.dynamics.em`) is ``Cov(𝒳_{k+1}, 𝒳_k | all frames) = Pˢ_{k+1} J_kᵀ``.

Observations in information form
--------------------------------
The tracker's measurement of a frame is the information pair of AC §8: ``S`` (any rank)
and ``Z``, relative to the prediction.  Written absolutely, ``z = Z + S X̃`` is distributed
as ``S X + v`` with ``v ~ N(0, S)``.  With ``S = L Lᵀ`` (``L`` of shape ``(Nx, r)``,
``r = rank S``) this is the same information as the whitened measurement
``y = Lᵀ X + e``, ``e ~ N(0, I_r)``, whose log-density :func:`filter_information` sums
into the log-likelihood of a sequence.  That forward pass is the predict / assimilate step
of AC Fig 10.3 (the same gain form and Joseph update as :mod:`trackcli.dynamics.kalman`) written on
plain arrays with the whitening of each frame computed once, because EM runs it over every
training frame at every iteration.  The log-likelihood is therefore that of the
whitened measurements: it differs from the density of any other parametrisation of the
same data by a constant that does not depend on the dynamics, which is all that
comparing or maximising over dynamics needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from trackcli.dynamics import kalman
from trackcli.dynamics.kalman import KalmanState
from trackcli.errors import DataError

__all__ = ["Smoothed", "filter_information", "rts_smooth", "smooth_filtered", "whiten"]

# Eigenvalues of S below this fraction of the largest are treated as no information.
_RANK_RTOL = 1e-10


@dataclass(frozen=True, eq=False)
class Smoothed:
    """Smoothed beliefs over a sequence of ``T`` frames.

    Attributes
    ----------
    means : ndarray of shape (T, 2 Nx)
        ``𝒳ˢ_k``: the mean of ``(X_{k-1}; X_k)`` given every frame.
    covs : ndarray of shape (T, 2 Nx, 2 Nx)
        ``Pˢ_k``, its covariance.
    cross : ndarray of shape (T - 1, 2 Nx, 2 Nx)
        ``cross[k] = Cov(𝒳_{k+1}, 𝒳_k | all frames)``, the lag-one cross-covariances.
    """

    means: np.ndarray
    covs: np.ndarray
    cross: np.ndarray

    @property
    def states(self) -> list[KalmanState]:
        """The smoothed beliefs as :class:`~trackcli.dynamics.kalman.KalmanState` values."""
        return [KalmanState(m, c) for m, c in zip(self.means, self.covs)]

    @property
    def nx(self) -> int:
        return int(self.means.shape[1] // 2)

    @property
    def X(self) -> np.ndarray:
        """Smoothed shapes ``X̂ˢ_k``, shape (T, Nx)."""
        return self.means[:, self.nx:]

    @property
    def X_std(self) -> np.ndarray:
        """Their standard deviations ``sqrt(diag Pˢ)``, shape (T, Nx)."""
        nx = self.nx
        return np.sqrt(np.clip(np.diagonal(self.covs[:, nx:, nx:], axis1=1, axis2=2), 0.0, None))


def _solve_psd(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``matrix⁻¹ rhs`` for a symmetric PSD ``matrix``; pseudo-inverse if it is singular.

    A singular predicted covariance arises when some direction of the state has no process
    noise (``B0`` singular) and was known exactly; the pseudo-inverse then leaves that
    direction as filtered, which is its smoothed value.
    """
    try:
        lower = np.linalg.cholesky(matrix)
        out = np.linalg.solve(lower.T, np.linalg.solve(lower, rhs))
        if np.all(np.isfinite(out)):
            return out
    except np.linalg.LinAlgError:
        pass
    return np.linalg.pinv(matrix, hermitian=True) @ rhs


def _backward(A: np.ndarray, Q: np.ndarray, offset: np.ndarray, means: np.ndarray,
              covs: np.ndarray) -> Smoothed:
    T, n = means.shape
    s_means = np.empty_like(means)
    s_covs = np.empty_like(covs)
    cross = np.zeros((max(T - 1, 0), n, n))
    s_means[-1], s_covs[-1] = means[-1], covs[-1]
    for k in range(T - 2, -1, -1):
        m, P = means[k], covs[k]
        m_pred = A @ m + offset
        P_pred = A @ P @ A.T + Q
        P_pred = 0.5 * (P_pred + P_pred.T)
        J = _solve_psd(P_pred, A @ P).T  # P Aᵀ P̃⁻¹ (P and P̃ symmetric)
        s_means[k] = m + J @ (s_means[k + 1] - m_pred)
        cov = P + J @ (s_covs[k + 1] - P_pred) @ J.T
        s_covs[k] = 0.5 * (cov + cov.T)
        cross[k] = s_covs[k + 1] @ J.T
    return Smoothed(s_means, s_covs, cross)


def rts_smooth(dynamics: Any, filtered: Sequence[KalmanState]) -> Smoothed:
    """Rauch–Tung–Striebel backward pass over the filtered beliefs of a sequence.

    Parameters
    ----------
    dynamics : object
        The AR(2) model the forward pass used (``A1, A2, B0`` (Nx, Nx), ``mean`` (Nx,)).
    filtered : sequence of KalmanState, length T >= 1
        Posterior of every frame from the forward pass, in order, each obtained from the
        previous one by :func:`trackcli.dynamics.kalman.predict` then
        :func:`trackcli.dynamics.kalman.assimilate` (the first may start anywhere).

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
    return _backward(A, B @ B.T, offset, np.array([f.mean for f in filtered]),
                     np.array([f.cov for f in filtered]))


def whiten(z: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``L`` (Nx, r) with ``S = L Lᵀ`` on its range, and ``y`` (r,) with ``z = L y``.

    ``z = S X + v = L (Lᵀ X + e)``, so ``y = Lᵀ X + e`` with ``e ~ N(0, I_r)``; ``r = rank S``
    (eigenvalues below ``1e-10`` of the largest count as zero).
    """
    values, vectors = np.linalg.eigh(S)
    top = float(values[-1]) if values.size else 0.0
    keep = values > _RANK_RTOL * top if top > 0 else np.zeros(values.size, dtype=bool)
    d = np.sqrt(values[keep])
    V = vectors[:, keep]
    return V * d, (V.T @ z) / d


def _update(mean: np.ndarray, cov: np.ndarray, H: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Assimilate ``y = H 𝒳 + N(0, I)``; return the posterior and ``log p(y)``.

    The gain form with Joseph covariance of :func:`trackcli.dynamics.kalman.assimilate`, for a
    whitened measurement of any block of the state.
    """
    r = y.size
    if r == 0:
        return mean, cov, 0.0
    innovation = y - H @ mean
    PHt = cov @ H.T
    G = H @ PHt + np.eye(r)
    lower = np.linalg.cholesky(0.5 * (G + G.T))
    white = np.linalg.solve(lower, innovation)
    gain = np.linalg.solve(lower.T, np.linalg.solve(lower, PHt.T)).T
    reduce = np.eye(mean.size) - gain @ H
    new_cov = reduce @ cov @ reduce.T + gain @ gain.T
    loglik = -0.5 * (r * math.log(2.0 * math.pi) + 2.0 * float(np.sum(np.log(np.diag(lower))))
                     + float(white @ white))
    return mean + gain @ innovation, 0.5 * (new_cov + new_cov.T), loglik


def filter_information(
    dynamics: Any,
    prior: KalmanState,
    z: np.ndarray,
    S: np.ndarray,
    *,
    whitened: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
) -> tuple[Smoothed, float]:
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
    whitened : sequence of (L, y), optional
        :func:`whiten` of every frame, when the caller keeps them across passes.

    Returns
    -------
    filtered : Smoothed
        The filtered beliefs over ``(X_{k-1}; X_k)`` for ``k = 1 .. T-1`` (the first combines
        the prior with frames 0 and 1, each later one is the predict / assimilate step of AC
        Fig 10.3) in the arrays of a :class:`Smoothed` (``cross`` empty); pass it to
        :func:`smooth_filtered`.
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
    T = z.shape[0]
    if whitened is None:
        whitened = [whiten(z[k], S[k]) for k in range(T)]
    A, B, offset = kalman.state_space(dynamics)
    Q = B @ B.T
    # frames 0 and 1 together, into the prior over (X_0; X_1)
    (L0, y0), (L1, y1) = whitened[0], whitened[1]
    H = np.zeros((y0.size + y1.size, 2 * nx))
    H[: y0.size, :nx] = L0.T
    H[y0.size:, nx:] = L1.T
    mean, cov, total = _update(prior.mean, prior.cov, H, np.concatenate([y0, y1]))
    means = np.empty((T - 1, 2 * nx))
    covs = np.empty((T - 1, 2 * nx, 2 * nx))
    means[0], covs[0] = mean, cov
    for k in range(2, T):
        mean = A @ mean + offset
        cov = A @ cov @ A.T + Q
        L, y = whitened[k]
        H = np.zeros((y.size, 2 * nx))
        H[:, nx:] = L.T
        mean, cov, ll = _update(mean, 0.5 * (cov + cov.T), H, y)
        total += ll
        means[k - 1], covs[k - 1] = mean, cov
    return Smoothed(means, covs, np.zeros((0, 2 * nx, 2 * nx))), total


def smooth_filtered(dynamics: Any, filtered: Smoothed) -> Smoothed:
    """:func:`rts_smooth` over the array form returned by :func:`filter_information`."""
    A, B, offset = kalman.state_space(dynamics)
    return _backward(A, B @ B.T, offset, filtered.means, filtered.covs)
