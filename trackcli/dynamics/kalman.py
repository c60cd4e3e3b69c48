"""Second-order Kalman filter steps for contour tracking (AC Fig 10.3, §10.1).

Notation
--------
The shape vector ``X`` (length ``Nx``) follows the AR(2) model of AC eq 9.15::

    X_k - X̄ = A2 (X_{k-2} - X̄) + A1 (X_{k-1} - X̄) + B0 w_k,   w_k ~ N(0, I)

The filter works on the second-order state ``𝒳_k = (X_{k-1}; X_k)`` of length
``2 Nx`` (AC eqs 9.16–9.18), whose transition is::

    𝒳_k - 𝒳̄ = A (𝒳_{k-1} - 𝒳̄) + B w_k,
    A = [[0, I], [A2, A1]],   B = [[0], [B0]],   𝒳̄ = (X̄; X̄).

The state covariance is split into ``Nx × Nx`` blocks as in AC eq 9.20::

    P = [[P'', P'ᵀ],
         [P',  P  ]]

``P`` (lower right) is the covariance of the current shape ``X_k``; ``P''`` that of
the previous shape ``X_{k-1}``; ``P'`` their cross-covariance.  Only ``X_k`` is
observed, through ``H = (0  I)`` (AC eq 10.5).

Image measurement arrives aggregated (AC Fig 8.6): with the predicted shape ``X̃``
the measurement module casts normals, and each normal ``i`` that finds a feature
contributes ``hᵢ hᵢᵀ / σᵢ²`` to the information matrix ``S`` and ``hᵢ νᵢ / σᵢ²`` to
the information vector ``Z``, where ``νᵢ`` is the innovation measured from ``X̃``.
``Z`` is therefore *relative to the prediction*: it estimates ``S (X - X̃)``.
``S`` may have any rank, including 0 when no normal found a feature.

Assimilation uses the gain form of AC eq 10.6 / Fig 10.3, which inverts only
``I + S P̃`` (never ``S``) and so tolerates a rank-deficient or zero ``S``::

    K  = P̃_full Hᵀ (I + S P̃)⁻¹                      (2Nx × Nx)
    𝒳̂  = 𝒳̃ + K Z
    P⁺ = (I - K S H) P̃_full (I - K S H)ᵀ + K S Kᵀ

The covariance update is written in Joseph form: ``Z`` is distributed as
``S (X - X̃) + v`` with ``v ~ N(0, S)``, so this is the covariance of the updated
estimate for the gain ``K``, a sum of two positive semi-definite terms.  It equals
the book's ``(I - K S H) P̃_full`` in exact arithmetic but cannot lose positive
semi-definiteness to rounding.

Three initial conditions are provided (AC §10.1): known static position
(:func:`init_known_static`), unknown position (:func:`init_unknown`) and known
initial velocity (:func:`init_known_velocity`).

Dynamics objects are duck-typed: anything with numpy attributes ``A1``, ``A2``,
``B0`` (each ``(Nx, Nx)``), ``mean`` (``(Nx,)``, the mean shape ``X̄``) and ``tau``
(frame interval in seconds) will do.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, TypeAlias

import numpy as np
import scipy.linalg

from trackcli.dynamics.ar2 import dynamics_arrays, state_matrices, stationary_covariance
from trackcli.errors import ConfigError, DataError

__all__ = [
    "KalmanState",
    "assimilate",
    "filter_sequence",
    "gate_rho",
    "init_known_static",
    "init_known_velocity",
    "init_unknown",
    "predict",
    "state_space",
]

# Relative tolerances used when checking that a matrix is symmetric / PSD.
_SYMMETRY_RTOL = 1e-8
_PSD_RTOL = 1e-8
# Spectral radius at or above which the AR(2) process has no steady state.
_STABILITY_LIMIT = 1.0 - 1e-9


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class KalmanState:
    """Gaussian belief over the second-order state ``𝒳 = (X_{k-1}; X_k)``.

    Parameters
    ----------
    mean : ndarray of shape (2 * Nx,)
        ``(X̂'; X̂)``: the estimate of the previous shape followed by the current one.
    cov : ndarray of shape (2 * Nx, 2 * Nx)
        State covariance, blocks ``[[P'', P'ᵀ], [P', P]]`` (AC eq 9.20).

    The arrays are copied and made read-only, so a state is a value.
    """

    mean: np.ndarray
    cov: np.ndarray

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=float)
        cov = np.asarray(self.cov, dtype=float)
        if mean.ndim != 1 or mean.size == 0 or mean.size % 2:
            raise DataError(
                f"KalmanState mean must be a 1-D array of even length 2*Nx, got shape {mean.shape}"
            )
        n = mean.size
        if cov.shape != (n, n):
            raise DataError(
                f"KalmanState cov must have shape ({n}, {n}) to match the mean, got {cov.shape}"
            )
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
            raise DataError("KalmanState mean and cov must be finite (found NaN or inf)")
        object.__setattr__(self, "mean", _frozen(mean))
        object.__setattr__(self, "cov", _frozen(cov))

    @property
    def nx(self) -> int:
        """Dimension ``Nx`` of the shape-space."""
        return self.mean.size // 2

    @property
    def X(self) -> np.ndarray:
        """Current shape estimate ``X̂_k``, shape (Nx,)."""
        return self.mean[self.nx :]

    @property
    def X_prev(self) -> np.ndarray:
        """Previous shape estimate ``X̂_{k-1}`` (the book's ``X̂'``), shape (Nx,)."""
        return self.mean[: self.nx]

    @property
    def P(self) -> np.ndarray:
        """Covariance of the current shape, the lower-right block ``P``, shape (Nx, Nx)."""
        return self.cov[self.nx :, self.nx :]

    @property
    def P_prev(self) -> np.ndarray:
        """Covariance of the previous shape, the upper-left block ``P''``, shape (Nx, Nx)."""
        return self.cov[: self.nx, : self.nx]

    @property
    def P_cross(self) -> np.ndarray:
        """Cross-covariance ``P' = Cov(X_k, X_{k-1})``, the lower-left block, shape (Nx, Nx)."""
        return self.cov[self.nx :, : self.nx]

    @property
    def velocity(self) -> np.ndarray:
        """Shape change over the last frame, ``X̂_k - X̂_{k-1}``, shape (Nx,).

        In shape units per frame; divide by the frame interval ``tau`` for units per second.
        """
        return self.X - self.X_prev

    @property
    def X_std(self) -> np.ndarray:
        """Standard deviations of the current shape coordinates, ``sqrt(diag P)``, shape (Nx,)."""
        return np.sqrt(np.clip(np.diag(self.P), 0.0, None))


Observation: TypeAlias = (
    tuple[np.ndarray, np.ndarray] | Callable[[KalmanState], tuple[np.ndarray, np.ndarray]]
)
"""One frame's aggregated measurement, or a function measuring it from the prediction."""


def state_space(dynamics: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First-order form of the AR(2) dynamics on the state ``(X_{k-1}; X_k)``.

    Parameters
    ----------
    dynamics : object
        Has ``A1, A2, B0`` of shape (Nx, Nx) and ``mean`` of shape (Nx,).

    Returns
    -------
    A : ndarray of shape (2 * Nx, 2 * Nx)
        ``[[0, I], [A2, A1]]`` (AC eq 9.18).
    B : ndarray of shape (2 * Nx, Nx)
        ``[[0], [B0]]``.
    offset : ndarray of shape (2 * Nx,)
        ``(0; (I - A2 - A1) X̄)``, so that ``𝒳_k = A 𝒳_{k-1} + offset + B w_k``.
    """
    A1, A2, B0, mean = dynamics_arrays(dynamics)
    A, B = state_matrices(A2, A1, B0)
    offset = np.zeros(A.shape[0])
    offset[A1.shape[0]:] = (np.eye(A1.shape[0]) - A2 - A1) @ mean
    return A, B, offset


def _check_nx(state: KalmanState, A: np.ndarray) -> None:
    if A.shape[0] != state.mean.size:
        raise ConfigError(
            f"dynamics has Nx = {A.shape[0] // 2} but the Kalman state has Nx = {state.nx}"
        )


def _symmetric(matrix: np.ndarray) -> np.ndarray:
    return 0.5 * (matrix + matrix.T)


def predict(state: KalmanState, dynamics: Any) -> KalmanState:
    """Prediction step of AC Fig 10.3 (AC eq 10.3).

    ``𝒳̃ = A 𝒳̂ + offset`` and ``P̃ = A P Aᵀ + B Bᵀ``, i.e. ``X̃' = X̂``,
    ``X̃ = A2 X̂' + A1 X̂ + (I - A2 - A1) X̄`` and the block formulas of the figure.

    Parameters
    ----------
    state : KalmanState
        Posterior at frame ``k - 1`` (state size 2 * Nx).
    dynamics : object
        AR(2) model with ``A1, A2, B0`` (Nx, Nx) and ``mean`` (Nx,).

    Returns
    -------
    KalmanState
        Prediction for frame ``k``; its covariance is exactly symmetric.
    """
    A, B, offset = state_space(dynamics)
    _check_nx(state, A)
    mean = A @ state.mean + offset
    cov = _symmetric(A @ state.cov @ A.T + B @ B.T)
    return KalmanState(mean, cov)


def _check_observation(Z: Any, S: Any, nx: int) -> tuple[np.ndarray, np.ndarray]:
    Z = np.asarray(Z, dtype=float)
    S = np.asarray(S, dtype=float)
    if Z.shape != (nx,):
        raise DataError(f"information vector Z must have shape ({nx},), got {Z.shape}")
    if S.shape != (nx, nx):
        raise DataError(f"information matrix S must have shape ({nx}, {nx}), got {S.shape}")
    if not (np.all(np.isfinite(Z)) and np.all(np.isfinite(S))):
        raise DataError("Z and S must be finite (found NaN or inf)")
    scale = float(np.max(np.abs(S), initial=0.0))
    if np.max(np.abs(S - S.T), initial=0.0) > _SYMMETRY_RTOL * max(scale, 1.0):
        raise DataError("information matrix S must be symmetric")
    S = _symmetric(S)
    if scale > 0.0:
        lowest = float(np.linalg.eigvalsh(S)[0])
        if lowest < -_PSD_RTOL * scale:
            raise DataError(
                "information matrix S must be positive semi-definite; "
                f"smallest eigenvalue {lowest:.3g}"
            )
    return Z, S


def assimilate(predicted: KalmanState, Z: np.ndarray, S: np.ndarray) -> KalmanState:
    """Assimilation step of AC Fig 10.3, in the gain form valid for ``S`` of any rank.

    Parameters
    ----------
    predicted : KalmanState
        Prediction ``(𝒳̃, P̃)`` for this frame (state size 2 * Nx).
    Z : ndarray of shape (Nx,)
        Aggregated information vector ``Σ hᵢ νᵢ / σᵢ²``, innovations measured from the
        predicted shape ``X̃``.
    S : ndarray of shape (Nx, Nx)
        Aggregated information matrix ``Σ hᵢ hᵢᵀ / σᵢ²``; symmetric positive
        semi-definite, any rank.

    Returns
    -------
    KalmanState
        Posterior for this frame.  If ``S = 0`` (no feature found) the prediction itself
        is returned unchanged.

    Raises
    ------
    DataError
        If ``Z`` or ``S`` has the wrong shape, is not finite, ``S`` is not symmetric
        positive semi-definite, or ``S = 0`` while ``Z ≠ 0``.

    Notes
    -----
    With ``P̃`` the shape block of the predicted covariance and ``H = (0  I)``::

        K  = P̃_full Hᵀ (I + S P̃)⁻¹     (the book's K' and K stacked, AC eq 10.7)
        𝒳̂  = 𝒳̃ + K Z
        P⁺ = (I - K S H) P̃_full (I - K S H)ᵀ + K S Kᵀ

    ``I + S P̃`` has eigenvalues ``1 + λ(P̃^½ S P̃^½) ≥ 1``, so it is always invertible.
    """
    nx = predicted.nx
    Z, S = _check_observation(Z, S, nx)
    if not S.any():
        if Z.any():
            raise DataError("Z must be zero when S is zero (no features means no information)")
        return predicted
    cov = predicted.cov
    P = predicted.P
    # Kᵀ = (I + P̃ S)⁻¹ H P̃_full, the transpose of P̃_full Hᵀ (I + S P̃)⁻¹.
    gain = np.linalg.solve(np.eye(nx) + P @ S, cov[nx:, :]).T
    mean = predicted.mean + gain @ Z
    reduce = np.eye(2 * nx)
    reduce[:, nx:] -= gain @ S
    updated = reduce @ cov @ reduce.T + gain @ S @ gain.T
    return KalmanState(mean, _symmetric(updated))


def gate_rho(state: KalmanState, h: np.ndarray) -> np.ndarray:
    """Validation-gate widths ``ρᵢ = sqrt(hᵢᵀ P hᵢ)`` along the normals (AC Fig 8.6).

    Pass the *predicted* state of the frame about to be measured, so that ``P`` is
    ``P̃`` as in the Measure step of AC Fig 10.3.  The search segment is then
    ``|ν| < κ ρᵢ``.

    Parameters
    ----------
    state : KalmanState
        Usually the prediction for the frame (state size 2 * Nx).
    h : ndarray of shape (M, Nx)
        Row ``i`` is ``hᵢᵀ = n(sᵢ)ᵀ U(sᵢ) W``; ``M`` may be 0.

    Returns
    -------
    ndarray of shape (M,)
        Standard deviation, in pixels, of the predicted curve's displacement along each
        normal.
    """
    h = np.asarray(h, dtype=float)
    if h.ndim != 2 or h.shape[1] != state.nx:
        raise DataError(f"h must have shape (M, {state.nx}), got {h.shape}")
    variance = np.einsum("mi,ij,mj->m", h, state.P, h)
    return np.sqrt(np.clip(variance, 0.0, None))


def _information(nx: int, S: Any, sigma: float | None) -> np.ndarray:
    if (S is None) == (sigma is None):
        raise ConfigError("give exactly one of S (an (Nx, Nx) information matrix) or sigma")
    if sigma is not None:
        sigma = float(sigma)
        if not (np.isfinite(sigma) and sigma > 0.0):
            raise ConfigError(f"sigma must be a positive finite number, got {sigma}")
        return np.eye(nx) / sigma**2
    _, S = _check_observation(np.zeros(nx), S, nx)
    if not S.any():
        raise DataError(
            "S = 0 carries no information; a known position needs a non-zero S "
            "(use init_unknown for an unknown position)"
        )
    return S


def _vector(name: str, value: Any, nx: int) -> np.ndarray:
    value = np.asarray(value, dtype=float)
    if value.shape != (nx,) or not np.all(np.isfinite(value)):
        raise DataError(f"{name} must be a finite vector of shape ({nx},), got shape {value.shape}")
    return value


def _closed_loop_cov(dynamics: Any, S: np.ndarray) -> np.ndarray:
    """Posterior covariance at the closed-loop steady state with constant information ``S``."""
    A, B, _ = state_space(dynamics)
    nx = A.shape[0] // 2
    # Factor S = L Lᵀ (L of shape (Nx, r), r = rank S): the information S is that of a
    # measurement Lᵀ X + v with v ~ N(0, I_r), so the predicted covariance solves the
    # filter Riccati equation with C = Lᵀ H and R = I_r.  scipy solves the control form;
    # the filter form is its dual (a = Aᵀ, b = Cᵀ).
    values, vectors = np.linalg.eigh(S)
    keep = values > _PSD_RTOL * values[-1]
    L = vectors[:, keep] * np.sqrt(values[keep])
    C = np.zeros((L.shape[1], 2 * nx))
    C[:, nx:] = L.T
    try:
        predicted = scipy.linalg.solve_discrete_are(A.T, C.T, B @ B.T, np.eye(L.shape[1]))
    except (np.linalg.LinAlgError, ValueError) as error:
        raise DataError(
            "the closed-loop steady state does not exist for these dynamics and this "
            "information matrix S (a mode of the model is neither observed through S "
            f"nor stable): {error}"
        ) from error
    if not np.all(np.isfinite(predicted)):
        raise DataError("the closed-loop steady state did not give a finite covariance")
    predicted = _symmetric(predicted)
    # The solution is the steady state only if it stabilises the loop: the error of the
    # filter then evolves by A (I - K S H), whose spectral radius must be below 1.  When
    # an unstable mode is invisible to S, scipy may still return a (meaningless) matrix.
    gain = np.linalg.solve(np.eye(nx) + predicted[nx:, nx:] @ S, predicted[nx:, :]).T
    loop = np.eye(2 * nx)
    loop[:, nx:] -= gain @ S
    radius = float(np.max(np.abs(np.linalg.eigvals(A @ loop))))
    if radius >= _STABILITY_LIMIT:
        raise DataError(
            "the closed-loop steady state does not exist: a mode of the dynamics that is "
            f"not stable is not observed through S (closed-loop spectral radius {radius:.6g}); "
            "give an S that observes every shape coordinate"
        )
    state = assimilate(KalmanState(np.zeros(2 * nx), predicted), np.zeros(nx), S)
    return state.cov


def init_known_static(
    X0: np.ndarray,
    dynamics: Any,
    *,
    S: np.ndarray | None = None,
    sigma: float | None = None,
) -> KalmanState:
    """Initial state for an object held still at a known shape ``X0`` (AC §10.1).

    The covariance is the closed-loop steady state of the filter fed with constant
    "artificial" measurements of information ``S``: the fixed point of
    :func:`predict` followed by :func:`assimilate` with that ``S``.  It is found by
    solving the discrete algebraic Riccati equation directly
    (``scipy.linalg.solve_discrete_are``), not by running the filter.

    The mean is ``(X0; X0)``: the object is at ``X0`` and at rest.  (Running the filter
    on the artificial measurements would leave the mean slightly pulled from ``X0``
    towards the model mean ``X̄``; the position is taken as known here instead.)

    Parameters
    ----------
    X0 : ndarray of shape (Nx,)
        Known initial shape.
    dynamics : object
        AR(2) model with ``A1, A2, B0`` (Nx, Nx) and ``mean`` (Nx,).
    S : ndarray of shape (Nx, Nx), optional
        Information matrix of a full set of successful image measurements, i.e.
        ``Σ hᵢ hᵢᵀ / σ²`` over every normal of the template.  It may be rank
        deficient if the model is stable in the directions it does not observe.
    sigma : float, optional
        Instead of ``S``: each shape coordinate measured independently with standard
        deviation ``sigma`` (shape-space units), ``S = I / sigma²``.

    Returns
    -------
    KalmanState
        Mean ``(X0; X0)`` and the closed-loop steady-state covariance (state size 2 * Nx).

    Raises
    ------
    ConfigError
        If neither or both of ``S`` and ``sigma`` are given, or ``sigma`` is not positive.
    DataError
        If ``S`` is zero, malformed, or leaves an unstable mode of the model unobserved
        (no steady state).
    """
    V0 = np.zeros_like(np.asarray(X0, dtype=float))
    return init_known_velocity(X0, V0, dynamics, S=S, sigma=sigma)


def init_known_velocity(
    X0: np.ndarray,
    V0: np.ndarray,
    dynamics: Any,
    *,
    S: np.ndarray | None = None,
    sigma: float | None = None,
) -> KalmanState:
    """Initial state for a known shape ``X0`` moving with known velocity ``V0`` (AC §10.1).

    ``X̂(t0) = X0``, ``X̂'(t0) = X0 - V0 τ``, with the covariance at the closed-loop
    steady state as in :func:`init_known_static`.

    Parameters
    ----------
    X0 : ndarray of shape (Nx,)
        Known initial shape.
    V0 : ndarray of shape (Nx,)
        Velocity offset in shape units per second (zero outside the subspace where it
        is known).
    dynamics : object
        AR(2) model with ``A1, A2, B0`` (Nx, Nx), ``mean`` (Nx,) and ``tau`` (seconds).
    S, sigma
        Information of a full set of measurements, as for :func:`init_known_static`.

    Returns
    -------
    KalmanState
        Mean ``(X0 - V0 τ; X0)`` and the closed-loop steady-state covariance.
    """
    A, _, _ = state_space(dynamics)
    nx = A.shape[0] // 2
    X0 = _vector("X0", X0, nx)
    V0 = _vector("V0", V0, nx)
    tau = float(getattr(dynamics, "tau", np.nan))
    if V0.any() and not (np.isfinite(tau) and tau > 0.0):
        raise ConfigError(f"dynamics.tau must be a positive frame interval in seconds, got {tau}")
    info = _information(nx, S, sigma)
    previous = X0 - V0 * tau if V0.any() else X0
    return KalmanState(np.concatenate([previous, X0]), _closed_loop_cov(dynamics, info))


def init_unknown(dynamics: Any) -> KalmanState:
    """Initial state for an object at an unknown position (AC §10.1).

    The open-loop steady state of the model: mean ``(X̄; X̄)`` and the stationary
    covariance ``P∞ = A P∞ Aᵀ + B Bᵀ`` (AC eq 9.23), solved directly with
    ``scipy.linalg.solve_discrete_lyapunov``.  The tracker then starts from the whole
    Gaussian envelope of the model and locks on as measurements arrive (AC Fig 10.4).

    Parameters
    ----------
    dynamics : object
        AR(2) model with ``A1, A2, B0`` (Nx, Nx) and ``mean`` (Nx,).

    Returns
    -------
    KalmanState
        Mean ``(X̄; X̄)`` and stationary covariance (state size 2 * Nx).

    Raises
    ------
    DataError
        If the model has no steady state: some mode has ``|eigenvalue| ≥ 1``, as for a
        constant-velocity model (``A2 = -I, A1 = 2I``) or an unstable learned model.
    """
    A, B, _ = state_space(dynamics)
    radius = float(np.max(np.abs(np.linalg.eigvals(A))))
    if radius >= _STABILITY_LIMIT:
        raise DataError(
            f"the dynamics have no open-loop steady state (spectral radius {radius:.6g} >= 1, "
            "e.g. a constant-velocity model), so an unknown initial position cannot be "
            "represented; start from a known position instead (init_known_static)"
        )
    mean = np.asarray(dynamics.mean, dtype=float)
    return KalmanState(np.concatenate([mean, mean]), stationary_covariance(A, B))


def filter_sequence(
    dynamics: Any,
    init_state: KalmanState,
    observations: Iterable[Observation],
) -> list[KalmanState]:
    """Run predict / assimilate over a sequence of frames.

    Parameters
    ----------
    dynamics : object
        AR(2) model with ``A1, A2, B0`` (Nx, Nx) and ``mean`` (Nx,).
    init_state : KalmanState
        Posterior at frame 0 (e.g. from :func:`init_known_static`).
    observations : iterable
        One item per frame ``k = 1, 2, ...``.  Each item is either a pair ``(Z, S)``
        (``Z`` of shape (Nx,), ``S`` of shape (Nx, Nx)) already relative to that frame's
        prediction, or a callable ``measure(predicted) -> (Z, S)`` that measures from
        the predicted state, as the image measurement does.

    Returns
    -------
    list of KalmanState
        Posterior states for frames 1, 2, ... (``init_state`` is not included).
    """
    states: list[KalmanState] = []
    state = init_state
    for item in observations:
        predicted = predict(state, dynamics)
        Z, S = item(predicted) if callable(item) else item
        state = assimilate(predicted, Z, S)
        states.append(state)
    return states
