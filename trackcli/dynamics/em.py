"""Learning AR(2) dynamics by expectation-maximisation from noisy measurements.

Maximum likelihood (:func:`trackcli.dynamics.learning.fit_ar2`, AC Fig 11.6) treats the tracked
shapes ``X_k`` as exact.  They are not: each is a filter's estimate from noisy image
measurements, and the noise inflates the fitted driving noise ``B0`` and damps the fitted
oscillations.  EM (Dempster, Laird & Rubin 1977; for dynamical contour models North & Blake
1997, cited in Blake et al. 1998 §6) instead maximises the likelihood of the *measurements*,
treating the shapes as hidden:

E-step
    Under the current dynamics, run the Kalman filter and the Rauch–Tung–Striebel smoother
    (:mod:`trackcli.dynamics.rts`) over each training sequence; the smoothed means ``m``,
    covariances ``V`` and lag-one cross-covariances give the expected sufficient statistics
    of AC Fig 11.6 over the frame triples ``k = 2 .. T-1``::

        E[R_i]  = Σ_k E[X_{k-i}]
        E[R_ij] = Σ_k ( Cov(X_{k-i}, X_{k-j} | all) + E[X_{k-i}] E[X_{k-j}]ᵀ )

M-step
    The Fig 11.6 formulas with those statistics in place of the sums over tracked shapes
    (:func:`trackcli.dynamics.learning.fit_ar2` on an :class:`~trackcli.dynamics.learning.AR2Statistics`).
    Sequences are pooled by adding statistics, as for MLE.

Each iteration cannot lower the log-likelihood of the measurements (the E-step's
by-product, :func:`trackcli.dynamics.rts.filter_information`); iterations stop when it rises by
less than ``tolerance`` nats per frame.  The belief over the first two frames of each
sequence is a fixed broad Gaussian around the first two rough shapes, so it does not depend
on the dynamics.  EM starts from the MLE fit to the rough shapes.

Measurements
------------
A sequence is a list of absolute information pairs ``(z_k, S_k)``: ``z_k ~ N(S_k X_k, S_k)``
(see :mod:`trackcli.dynamics.rts`).  From the Kalman contour tracker they are the aggregated
normals of AC §8 (``z = Z + S X̃``); from a track CSV (``learn --from-tracks``) the shape
``X_k`` with its reported standard deviations, ``S_k = diag(std⁻²)``, and no measurement on
frames the tracker marked lost.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.kalman import KalmanState
from trackcli.dynamics.learning import AR2Statistics, LearningReport, fit_ar2
from trackcli.dynamics.rts import Smoothed, filter_information, smooth_filtered, whiten
from trackcli.errors import DataError

__all__ = ["EMReport", "InformationSequence", "expected_statistics", "fit_ar2_em"]

log = logging.getLogger(__name__)

#: Default stopping rule: log-likelihood gain per frame, nats.
DEFAULT_TOLERANCE = 1e-4
#: Default cap on the number of M-steps.
DEFAULT_MAX_ITERATIONS = 200


@dataclass(frozen=True, eq=False)
class InformationSequence:
    """The measurements of one training sequence of ``T`` frames.

    Attributes
    ----------
    z : ndarray of shape (T, Nx)
        Absolute information vectors.
    S : ndarray of shape (T, Nx, Nx)
        Information matrices (symmetric positive semi-definite; zero = no measurement).
    X : ndarray of shape (T, Nx)
        Rough shape estimates (the tracked shapes): they start EM (MLE on them) and centre
        the belief over the first two frames.
    """

    z: np.ndarray
    S: np.ndarray
    X: np.ndarray

    def __post_init__(self) -> None:
        z = np.asarray(self.z, dtype=float)
        S = np.asarray(self.S, dtype=float)
        X = np.asarray(self.X, dtype=float)
        if X.ndim != 2 or X.shape[1] < 1:
            raise DataError(f"shapes must have shape (T, Nx), got {X.shape}")
        T, nx = X.shape
        if z.shape != (T, nx) or S.shape != (T, nx, nx):
            raise DataError(f"information must have shapes ({T}, {nx}) and ({T}, {nx}, {nx}), "
                            f"got {z.shape} and {S.shape}")
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(S)) and np.all(np.isfinite(X))):
            raise DataError("measurements and shapes must be finite (found NaN or inf)")
        for name, value in (("z", z), ("S", S), ("X", X)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        # the whitened measurements do not change across EM iterations
        object.__setattr__(self, "_whitened", [whiten(z[k], S[k]) for k in range(T)])

    @classmethod
    def from_shapes(cls, X: Any, std: Any, lost: Any = None) -> InformationSequence:
        """Shapes measured independently per component with standard deviations ``std``.

        Parameters
        ----------
        X, std : array_like of shape (T, Nx)
            Tracked shapes and their reported standard deviations (positive).
        lost : array_like of bool, shape (T,), optional
            Frames without a measurement (the tracker had lost lock).
        """
        X = np.asarray(X, dtype=float)
        std = np.asarray(std, dtype=float)
        if std.shape != X.shape:
            raise DataError(f"standard deviations must have the shape of the shapes {X.shape}, got {std.shape}")
        seen = np.ones(X.shape[0], dtype=bool) if lost is None else ~np.asarray(lost, dtype=bool)
        bad = seen & ~np.all(np.isfinite(std) & (std > 0), axis=1)
        if bad.any():
            raise DataError(f"the reported standard deviation is not a positive number at row(s) "
                            f"{', '.join(str(int(i)) for i in np.flatnonzero(bad)[:5])}; "
                            "EM needs each frame's uncertainty")
        info = np.where(seen[:, None], 1.0 / np.where(seen[:, None], std, 1.0) ** 2, 0.0)
        S = np.einsum("ti,ij->tij", info, np.eye(X.shape[1]))
        return cls(info * X, S, X)

    @property
    def frames(self) -> int:
        return int(self.X.shape[0])

    @property
    def nx(self) -> int:
        return int(self.X.shape[1])

    def prior(self) -> KalmanState:
        """Belief over ``(X_0; X_1)`` before any measurement: broad, and fixed across EM iterations.

        Centred on the first two rough shapes, independent components with the variance of
        each component over the whole sequence (at least a small floor).
        """
        var = self.X.var(axis=0)
        var = np.maximum(var, 1e-6 * (1.0 + float(var.max())))
        return KalmanState(np.concatenate([self.X[0], self.X[1]]), np.diag(np.concatenate([var, var])))


def expected_statistics(smoothed: Smoothed, n_frames: int) -> AR2Statistics:
    """Expected sufficient statistics of AC Fig 11.6 from a smoothed sequence.

    Parameters
    ----------
    smoothed : Smoothed
        Beliefs over ``(X_{k-1}; X_k)`` for ``k = 1 .. T-1`` (as from
        :func:`trackcli.dynamics.rts.filter_information` then
        :func:`trackcli.dynamics.rts.smooth_filtered`).
    n_frames : int
        ``T``, recorded in the statistics.

    Returns
    -------
    AR2Statistics
        Over the ``T - 2`` frame triples; ``products[i, j] = Σ E[X_{k-i} X_{k-j}ᵀ]``.
    """
    means, covs = smoothed.means, smoothed.covs
    nx = smoothed.nx
    count = means.shape[0] - 1
    sums = np.zeros((3, nx))
    products = np.zeros((3, 3, nx, nx))
    if count <= 0:
        return AR2Statistics(0, sums, products, 1, n_frames)
    cur_m, prv_m = means[1:], means[:-1]          # (X_{k-1}; X_k) and (X_{k-2}; X_{k-1})
    cur_P, prv_P, cross = covs[1:], covs[:-1], smoothed.cross
    lo, hi = slice(nx, 2 * nx), slice(0, nx)
    mu = [cur_m[:, lo], cur_m[:, hi], prv_m[:, hi]]    # E[X_k], E[X_{k-1}], E[X_{k-2}]
    cov = {
        (0, 0): cur_P[:, lo, lo], (0, 1): cur_P[:, lo, hi], (1, 1): cur_P[:, hi, hi],
        (2, 2): prv_P[:, hi, hi], (1, 2): prv_P[:, lo, hi], (0, 2): cross[:, lo, hi],
    }
    for i in range(3):
        sums[i] = mu[i].sum(axis=0)
        for j in range(i, 3):
            products[i, j] = cov[(i, j)].sum(axis=0) + mu[i].T @ mu[j]
            products[j, i] = products[i, j].T
    return AR2Statistics(count, sums, products, 1, n_frames)


@dataclass(frozen=True, eq=False)
class EMReport:
    """What :func:`fit_ar2_em` did.

    Attributes
    ----------
    iterations : int
        M-steps taken.
    log_likelihood : list of float
        Log-likelihood of the measurements before the first M-step (the MLE start) and after
        each M-step; never decreasing, up to rounding.
    converged : bool
        The last gain was below ``tolerance`` per frame (else the iteration cap stopped EM).
    tolerance : float
        Stopping gain, nats per frame.
    frames : int
        Frames of measurements in all sequences.
    stabilised_log_likelihood : float or None
        When the converged model was unstable and ``enforce_stability`` pulled its modes in,
        the log-likelihood of the returned (stabilised) model.
    """

    iterations: int
    log_likelihood: list[float] = field(default_factory=list)
    converged: bool = False
    tolerance: float = DEFAULT_TOLERANCE
    frames: int = 0
    stabilised_log_likelihood: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"iterations": self.iterations, "converged": self.converged, "tolerance": self.tolerance,
                "frames": self.frames, "log_likelihood": [float(v) for v in self.log_likelihood],
                "stabilised_log_likelihood": self.stabilised_log_likelihood}


def _e_step(model: AR2, sequences: Sequence[InformationSequence]) -> tuple[float, AR2Statistics]:
    total = 0.0
    stats = []
    for seq in sequences:
        filtered, loglik = filter_information(model, seq.prior(), seq.z, seq.S, whitened=seq._whitened)
        total += loglik
        stats.append(expected_statistics(smooth_filtered(model, filtered), seq.frames))
    return total, sum(stats[1:], stats[0])


def fit_ar2_em(
    sequences: Sequence[InformationSequence],
    tau: float,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    enforce_stability: bool = False,
    max_spectral_radius: float = 0.99,
    init: AR2 | None = None,
) -> tuple[AR2, LearningReport, EMReport]:
    """AR(2) dynamics maximising the likelihood of noisy measurements, by EM.

    Parameters
    ----------
    sequences : sequence of InformationSequence
        Training sequences (pooled); those of fewer than 3 frames are left out.
    tau : float
        Frame interval, seconds.
    tolerance : float
        Stop when an M-step raises the log-likelihood by less than ``tolerance`` nats per
        frame of measurements.
    max_iterations : int
        At most this many M-steps.
    enforce_stability, max_spectral_radius
        As for :func:`trackcli.dynamics.learning.fit_ar2`, applied once to the converged model (the
        iterations themselves are unconstrained, which is what makes them monotone).
    init : AR2, optional
        Starting dynamics; default the MLE fit to the sequences' rough shapes.

    Returns
    -------
    model : AR2
    report : LearningReport
        Of the last M-step; its ``log_likelihood`` is replaced by the log-likelihood of the
        measurements under the returned model.
    em : EMReport

    Raises
    ------
    DataError
        No usable sequence, mismatched dimensions, or an M-step that cannot be solved (the
        same conditions as :func:`trackcli.dynamics.learning.fit_ar2`).
    """
    sequences = [s for s in sequences if s.frames >= 3]
    if not sequences:
        raise DataError("EM needs at least one training sequence of 3 frames or more")
    if len({s.nx for s in sequences}) > 1:
        raise DataError("training sequences have shape vectors of different dimensions")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise DataError(f"EM tolerance must be a positive number, got {tolerance}")
    if max_iterations < 1:
        raise DataError(f"EM needs at least one iteration, got {max_iterations}")
    frames = sum(s.frames for s in sequences)
    model = init
    if model is None:
        model, _ = fit_ar2([s.X for s in sequences], tau)
    report: LearningReport | None = None
    path: list[float] = []
    converged = False
    stats = None
    iterations = 0
    while True:
        loglik, stats = _e_step(model, sequences)
        path.append(loglik)
        log.debug("EM iteration %d: log-likelihood %.6f", iterations, loglik)
        if len(path) > 1 and path[-1] - path[-2] < tolerance * frames:
            converged = True
            break
        if iterations >= max_iterations:
            break
        model, report = fit_ar2(stats, tau)
        iterations += 1
    stabilised_ll = None
    final_ll = path[-1]
    if enforce_stability and model.spectral_radius() > max_spectral_radius:
        model, report = fit_ar2(stats, tau, enforce_stability=True, max_spectral_radius=max_spectral_radius)
        final_ll = stabilised_ll = _e_step(model, sequences)[0]
    report = dataclasses.replace(report, log_likelihood=final_ll)
    em = EMReport(iterations=iterations, log_likelihood=path, converged=converged, tolerance=tolerance,
                  frames=frames, stabilised_log_likelihood=stabilised_ll)
    return model, report, em


def learn_em(sequences: Sequence[InformationSequence], tau: float, settings: Any) -> tuple[AR2, dict[str, Any]]:
    """:func:`fit_ar2_em` with the ``em`` and ``learning`` settings; a report for the model file.

    The report is that of :func:`trackcli.dynamics.learning.fit_ar2` (``log_likelihood`` being the
    log-likelihood of the measurements) with ``method: em`` and the ``em`` record of
    :class:`EMReport` (iterations, convergence, the log-likelihood path).
    """
    model, report, em = fit_ar2_em(sequences, tau, tolerance=settings.em.tolerance,
                                   max_iterations=settings.em.max_iterations,
                                   enforce_stability=settings.learning.enforce_stability,
                                   max_spectral_radius=settings.learning.max_spectral_radius)
    path = em.log_likelihood
    log.info("EM: %d iteration(s)%s; log-likelihood of the measurements %.2f -> %.2f (gain %.3g per frame)",
             em.iterations, "" if em.converged else f" (stopped at em.max_iterations = {settings.em.max_iterations})",
             path[0], path[-1], (path[-1] - path[0]) / max(em.frames, 1))
    for k, value in enumerate(path):
        log.debug("EM iteration %d: log-likelihood %.6f", k, value)
    if em.stabilised_log_likelihood is not None:
        log.info("EM: the converged model was unstable; stabilised, log-likelihood %.2f",
                 em.stabilised_log_likelihood)
    return model, {**report.to_dict(), "method": "em", "em": em.to_dict()}


def information_from_track(path: Any, names: Sequence[str]) -> InformationSequence:
    """The measurements of a track CSV: each shape with its reported standard deviations.

    Frames marked lost carry no measurement.
    """
    from trackcli.io.tracks import read_track, read_track_uncertainty

    _, X, _ = read_track(path, names)
    std, lost = read_track_uncertainty(path, names)
    try:
        return InformationSequence.from_shapes(X, std, lost)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None


def change_space(z: np.ndarray, S: np.ndarray, old: Any, new: Any, X: np.ndarray) -> InformationSequence:
    """Measurements ``(z, S)`` about shapes in space ``old``, as information about shapes in ``new``.

    With ``X_old = T X_new + c`` (the L2 projection into ``old`` of ``new``'s curves, exact
    when ``new`` lies within ``old``, as a PCA space learned from ``old``'s tracked outlines
    does), a measurement ``z ~ N(S X_old, S)`` is the information ``(Tᵀ (z - S c), Tᵀ S T)``
    about ``X_new``.  ``X`` (T, Nx_new) are the rough shapes in the new space.
    """
    c = old.project(new.to_control(np.zeros(new.Nx)))
    T = np.column_stack([old.project(new.to_control(e)) - c for e in np.eye(new.Nx)])
    z_new = (np.asarray(z) - np.einsum("tij,j->ti", S, c)) @ T
    S_new = np.einsum("ai,tab,bj->tij", T, S, T)
    return InformationSequence(z_new, 0.5 * (S_new + S_new.transpose(0, 2, 1)), X)
