"""Smoothing a track as it is made: consumers of the trackers' per-frame results.

``trackcli track --smooth`` feeds every :class:`trackcli.trackers.base.FrameResult` to one of
these (``push``, which may hand back smoothed results that are final) and writes the smoothed
results, in frame order, as a second track; ``finish`` returns the rest at the end of the
clip (both smoothers here use the whole clip, so everything comes from ``finish``).  They read
what the frame loops leave in ``FrameResult.display`` for offline consumers: the Kalman
tracker's filtered belief (``"state"``) and CONDENSATION's weighted sample set (``"particles"``).

- :class:`KalmanTrackSmoother`: the Rauch–Tung–Striebel pass of :mod:`trackcli.dynamics.rts`
  over the Kalman filter's beliefs (the filter steps are in :mod:`trackcli.dynamics.kalman`).
- :class:`ParticleSmoother`: forward-filtering backward-smoothing of CONDENSATION's sample
  sets, :func:`particle_smoothing_weights`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Sequence

import numpy as np

from trackcli.dynamics.kalman import KalmanState
from trackcli.dynamics.rts import rts_smooth
from trackcli.errors import DataError

__all__ = ["KalmanTrackSmoother", "ParticleSmoother", "particle_smoothing_weights"]


def _smoothed_result(result: Any, space: Any, X: np.ndarray, X_std: np.ndarray) -> Any:
    from trackcli.shapes.outline import contour_summary

    contour, centroid, bbox = contour_summary(space, X)
    return dataclasses.replace(result, X=np.array(X, dtype=float), X_std=np.array(X_std, dtype=float),
                               contour=contour, centroid=centroid, bbox=bbox, display={})


class KalmanTrackSmoother:
    """Rauch–Tung–Striebel smoothing of a Kalman contour track, over the whole clip.

    Keeps each frame's filtered belief (``O(Nx²)`` numbers a frame) and smooths them all in
    ``finish``: the estimate of every frame then uses every frame of the clip.
    """

    def __init__(self, space: Any, dynamics: Any):
        self.space, self.dynamics = space, dynamics
        self._results: list[Any] = []
        self._states: list[KalmanState] = []

    def push(self, result: Any) -> list[Any]:
        state = result.display.get("state")
        if not isinstance(state, KalmanState):
            raise DataError("Kalman smoothing needs the tracker's filtered state of every frame")
        self._states.append(state)
        self._results.append(dataclasses.replace(result, display={}))
        return []

    def finish(self) -> list[Any]:
        if not self._states:
            return []
        smoothed = rts_smooth(self.dynamics, self._states)
        out = [_smoothed_result(r, self.space, X, s) for r, X, s in zip(self._results, smoothed.X, smoothed.X_std)]
        self._results, self._states = [], []
        return out


def _logsumexp(a: np.ndarray, axis: int) -> np.ndarray:
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    return np.squeeze(top, axis=axis) + np.log(np.sum(np.exp(a - top), axis=axis))


class ParticleSmoother:
    """Forward-filtering backward-smoothing of a CONDENSATION track (the marginal smoother).

    With the filter's weighted samples ``{𝒳ᵢ_k, wᵢ_k}`` of every frame, the smoothed
    weights are computed backwards from the last frame (Doucet, Godsill & Andrieu 2000)::

        wᵢ_{k|T} = wᵢ_k Σ_j w^j_{k+2|T} g(𝒳^j_{k+2} | 𝒳ᵢ_k) / Σ_l w^l_k g(𝒳^j_{k+2} | 𝒳^l_k)

    over *two* frames: the one-frame transition of the second-order state
    ``𝒳 = (X_{k-1}; X_k)`` repeats ``X_k`` exactly, so its density is zero between a sample
    and every frame-``k`` sample but its parent and the one-step smoother would only follow
    ancestry (which collapses onto a few ancestors after repeated resampling).  The two-frame
    transition ``g`` of ``(X_{k+1}, X_{k+2})`` given ``(X_{k-1}, X_k)`` is a proper Gaussian,
    and the recursion stays exact because ``Z_{k+1}`` depends on ``X_{k+1}`` alone, which is
    in ``𝒳_{k+2}``.  Frame ``T-1`` takes its weights from the last frame by ancestry.

    Cost: memory for every frame's samples, ``O(T · N · Nx)`` numbers (about 36 kB a frame
    for N = 500 in a 4-dimensional shape-space); time ``O(N² · Nx)`` a frame, in ``finish``
    (:func:`particle_smoothing_weights`).
    """

    def __init__(self, space: Any, dynamics: Any):
        self.space, self.dynamics = space, dynamics
        self._frames: list[tuple[Any, np.ndarray, np.ndarray, np.ndarray]] = []

    def push(self, result: Any) -> list[Any]:
        particles = result.display.get("particles")
        if particles is None:
            raise DataError("particle smoothing needs CONDENSATION's weighted sample set of every frame")
        log_w = np.asarray(particles.log_w, dtype=float)
        self._frames.append((dataclasses.replace(result, display={}), np.array(particles.prev),
                             np.array(particles.cur), log_w - _logsumexp(log_w, 0)))
        return []

    def finish(self) -> list[Any]:
        frames, self._frames = self._frames, []
        if not frames:
            return []
        smoothed = particle_smoothing_weights([f[1] for f in frames], [f[2] for f in frames],
                                              [f[3] for f in frames], self.dynamics)
        out = []
        for (result, _, cur, _), w in zip(frames, smoothed):
            X = w @ cur
            dev = cur - X
            out.append(_smoothed_result(result, self.space, X, np.sqrt(np.maximum(w @ (dev * dev), 0.0))))
        return out


def _parents(prev: np.ndarray, before: np.ndarray) -> np.ndarray:
    """Index into ``before`` (N0, Nx) of the row equal to each row of ``prev`` (N, Nx)."""
    index = {row.tobytes(): i for i, row in enumerate(before)}
    parents = np.fromiter((index.get(row.tobytes(), -1) for row in prev), dtype=np.int64, count=prev.shape[0])
    if (parents < 0).any():
        raise DataError("particle smoothing: a sample's previous shape matches no sample of the frame before; "
                        "the sample sets of consecutive frames are needed")
    return parents


def particle_smoothing_weights(prev: Sequence[np.ndarray], cur: Sequence[np.ndarray], log_w: Sequence[np.ndarray],
                               dynamics: Any) -> list[np.ndarray]:
    """Smoothed weights of every frame's samples (:class:`ParticleSmoother`).

    Parameters
    ----------
    prev, cur : sequences of ndarray of shape (N_k, Nx)
        The weighted sample sets of frames ``k = 0 .. T-1``, as CONDENSATION leaves them
        (``prev`` of frame ``k`` holding the parents' ``X_{k-1}``).
    log_w : sequence of ndarray of shape (N_k,)
        Their log-weights (any normalisation).
    dynamics : object
        The AR(2) model of the filter (``A1, A2, B0`` (Nx, Nx), ``mean`` (Nx,)).

    Returns
    -------
    list of ndarray of shape (N_k,)
        Normalised smoothed weights.
    """
    T = len(cur)
    A1, A2 = np.asarray(dynamics.A1, dtype=float), np.asarray(dynamics.A2, dtype=float)
    B0 = np.asarray(dynamics.B0, dtype=float)
    values, vectors = np.linalg.eigh(B0 @ B0.T)
    keep = values > 1e-12 * max(float(values[-1]), 1e-300)
    W = (vectors[:, keep] / np.sqrt(values[keep])).T          # Wᵀ W = (B0 B0ᵀ)⁺
    D = (np.eye(A1.shape[0]) - A2 - A1) @ np.asarray(dynamics.mean, dtype=float)
    filt = [np.asarray(lw, dtype=float) - _logsumexp(np.asarray(lw, dtype=float), 0) for lw in log_w]
    smoothed: list[np.ndarray] = [np.empty(0)] * T
    smoothed[-1] = filt[-1]
    if T > 1:
        parents = _parents(np.asarray(prev[-1]), np.asarray(cur[-2]))
        mass = np.bincount(parents, weights=np.exp(filt[-1]), minlength=len(cur[-2]))
        with np.errstate(divide="ignore"):
            smoothed[-2] = np.log(mass)
    for k in range(T - 3, -1, -1):
        x1, x2 = np.asarray(prev[k + 2]), np.asarray(cur[k + 2])  # (X_{k+1}, X_{k+2}) of frame k+2's samples
        p0, c0 = np.asarray(prev[k]), np.asarray(cur[k])
        # g(𝒳_{k+2} | 𝒳_k) = N(X_{k+1}; A2 X_{k-1} + A1 X_k + D, C) N(X_{k+2}; A2 X_k + A1 X_{k+1} + D, C)
        # = exp(-|alpha_j - beta_i|² / 2) up to a constant, after whitening by W
        alpha = np.hstack([x1 @ W.T, (x2 - x1 @ A1.T - D) @ W.T])
        beta = np.hstack([(p0 @ A2.T + c0 @ A1.T + D) @ W.T, c0 @ A2.T @ W.T])
        sq = np.sum(alpha**2, axis=1)[:, None] + np.sum(beta**2, axis=1)[None, :] - 2.0 * alpha @ beta.T
        log_g = -0.5 * np.maximum(sq, 0.0)                         # (N_{k+2}, N_k)
        log_den = _logsumexp(filt[k][None, :] + log_g, 1)
        smoothed[k] = filt[k] + _logsumexp(smoothed[k + 2][:, None] + log_g - log_den[:, None], 0)
    return [np.exp(s - _logsumexp(s, 0)) for s in smoothed]
