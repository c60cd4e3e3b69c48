"""Second-order auto-regressive (AR(2)) dynamics in shape-space.

A shape vector ``X`` of length ``Nx`` moves by (AC eq 9.15)::

    X_k - X̄ = A2 (X_{k-2} - X̄) + A1 (X_{k-1} - X̄) + B0 w_k,    w_k ~ N(0, I_Nx)

with ``A2, A1, B0`` of shape ``(Nx, Nx)``, mean ``X̄`` and frame interval ``tau`` seconds.
The driving noise has covariance ``C = B0 B0ᵀ``.  Stacking two frames into the state
``𝒳_k = (X_{k-1}; X_k)`` gives a first-order process (AC eqs 9.16-9.18)::

    𝒳_k - 𝒳̄ = A (𝒳_{k-1} - 𝒳̄) + B w_k,   A = [[0, I], [A2, A1]],   B = [[0], [B0]]

whose covariance obeys ``P_k = A P_{k-1} Aᵀ + B Bᵀ`` (AC eq 9.23).  For a stable model
(every eigenvalue of ``A`` inside the unit circle) ``P`` tends to the steady state ``P∞``,
which is solved for directly here as a discrete Lyapunov equation.

Hand-set models built from damped oscillators (AC §9.6) are in :mod:`trackcli.dynamics.handset`.

Modal analysis (AC eqs 11.10-11.13) reads a model as a set of damped oscillations: each
eigenvalue ``λ`` of ``A`` gives a damping ``β = -log|λ| / τ`` and a frequency
``f = arg λ / (2πτ)``; the upper half of its eigenvector is the pattern of motion.

The model, its state-space form, steady state and modes are the AR(2) equations of AC
ch. 9 and 11, each written once here for every other module to use.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trackcli.errors import ConfigError, DataError, ModelError

log = logging.getLogger(__name__)

__all__ = [
    "AR2",
    "Mode",
    "check_metric",
    "dynamics_arrays",
    "predict_samples",
    "spectral_radius",
    "state_matrices",
    "stationary_covariance",
    "symmetric_sqrt",
]


# ---------------------------------------------------------------------------------------------
# Small linear-algebra helpers


def symmetric_sqrt(M: np.ndarray, *, inverse: bool = False) -> np.ndarray:
    """Symmetric square root of a symmetric positive semi-definite matrix.

    Parameters
    ----------
    M : ndarray of shape (n, n)
        Symmetric matrix; it is symmetrised first, and eigenvalues below zero (rounding
        error in a covariance) are clipped to zero.
    inverse : bool
        Return ``M^{-1/2}`` instead; then ``M`` must be positive definite.

    Returns
    -------
    ndarray of shape (n, n)
        The symmetric ``S`` with ``S @ S = M`` (or ``S @ S = M^{-1}``).
    """
    M = np.asarray(M, dtype=float)
    vals, vecs = np.linalg.eigh(0.5 * (M + M.T))
    if inverse:
        if vals.min() <= 0:
            raise DataError(f"matrix is not positive definite (smallest eigenvalue {vals.min():.3g}); no inverse square root")
        roots = 1.0 / np.sqrt(vals)
    else:
        roots = np.sqrt(np.clip(vals, 0.0, None))
    S = (vecs * roots) @ vecs.T
    return 0.5 * (S + S.T)


def check_metric(H: Any, nx: int) -> np.ndarray:
    """Validate a shape-space metric matrix ``H`` of shape ``(nx, nx)``."""
    H = np.asarray(H, dtype=float)
    if H.shape != (nx, nx):
        raise DataError(f"metric matrix H must have shape ({nx}, {nx}) to match the shape-space, got {H.shape}")
    if not np.all(np.isfinite(H)):
        raise DataError("metric matrix H contains non-finite values")
    scale = max(float(np.abs(H).max()), np.finfo(float).tiny)
    if np.abs(H - H.T).max() > 1e-9 * scale:
        raise DataError("metric matrix H must be symmetric")
    H = 0.5 * (H + H.T)
    smallest = float(np.linalg.eigvalsh(H).min())
    if smallest <= 1e-12 * scale:
        raise DataError(f"metric matrix H must be positive definite (smallest eigenvalue {smallest:.3g})")
    return H


# ---------------------------------------------------------------------------------------------
# The model


#: eigenvalues are read to this precision in the modal analysis: ``eig`` returns a repeated
#: eigenvalue (a Jordan block, e.g. constant velocity or critical damping) only to about the
#: square root of the machine precision, as a pair 1 ± 1e-8 or 0.92 ± 1e-9 i
MODULUS_TOLERANCE = 1e-6


def _snap(lam: complex) -> complex:
    """An eigenvalue with its rounding from a repeated root removed: imaginary parts and
    distances of the modulus from 1 below :data:`MODULUS_TOLERANCE` set to exactly 0 and 1."""
    re, im = lam.real, lam.imag
    if abs(im) <= MODULUS_TOLERANCE:
        im = 0.0
    modulus = math.hypot(re, im)
    if modulus > 0 and abs(modulus - 1.0) <= MODULUS_TOLERANCE:
        re, im = re / modulus, im / modulus
    return complex(re, im)


@dataclass(frozen=True, eq=False)
class Mode:
    """One mode of an AR(2) model (AC §11.3, eqs 11.10-11.13).

    A complex eigenvalue stands for its conjugate pair: one damped oscillation
    ``exp(-βt) cos(2πft)``.  A real positive eigenvalue is a plain exponential decay
    (``f = 0``); a real negative one flips sign every frame, ``f = 1/(2τ)``.

    Attributes
    ----------
    eigenvalue : complex
        Eigenvalue ``λ`` of the state matrix ``A`` (the member with ``Im λ >= 0``).
    modulus : float
        ``|λ|``; the mode is stable when it is below 1.
    beta : float
        Damping rate ``-log|λ| / τ`` in 1/s (negative for a growing mode, ``inf`` for λ = 0).
    frequency : float
        Oscillation frequency ``|arg λ| / (2πτ)`` in Hz.
    decay_time : float
        ``1 / β`` in seconds (negative: the e-folding time of a growing mode; ``inf``: β = 0).
    period : float
        ``1 / f`` in seconds (``inf`` for a non-oscillating mode).
    stable : bool
        ``|λ| < 1``.
    shape : ndarray of shape (Nx,), complex
        Pattern of motion: the upper half of the eigenvector, scaled to unit length and
        rotated so that its largest component is real and positive.  Moduli are
        amplitudes, arguments are relative phases.
    weights : ndarray of shape (Nx,)
        ``|shape|²``, the share of each shape-space component (sums to 1).
    """

    eigenvalue: complex
    modulus: float
    beta: float
    frequency: float
    decay_time: float
    period: float
    stable: bool
    shape: np.ndarray = field(repr=False)
    weights: np.ndarray = field(repr=False)

    @property
    def oscillatory(self) -> bool:
        """True for a conjugate pair (a damped sinusoid), false for a real eigenvalue."""
        return self.eigenvalue.imag > 0

    def dominant(self, count: int = 3, H: np.ndarray | None = None) -> list[tuple[int, float]]:
        """The ``count`` largest components of the mode shape.

        Parameters
        ----------
        count : int
            How many components.
        H : ndarray of shape (Nx, Nx), optional
            Shape-space metric.  Components of a shape vector have different units
            (pixels for translation, fractions for scale); with ``H`` each component is
            weighted by the curve displacement it causes, ``|shape[i]|² H[i, i]``, so the
            weights compare like with like.

        Returns
        -------
        list of (index, weight)
            Shape-space indices with their weights (summing to 1 over all components),
            largest first.
        """
        w = self.weights
        if H is not None:
            w = np.abs(self.shape) ** 2 * np.clip(np.diag(np.asarray(H, dtype=float)), 0.0, None)
            total = float(w.sum())
            w = w / total if total > 0 else self.weights
        order = np.argsort(-w, kind="stable")[: max(int(count), 0)]
        return [(int(i), float(w[i])) for i in order]

    def summary(self) -> str:
        """One line describing the mode, for reports."""
        kind = f"f = {self.frequency:.3g} Hz" if self.frequency > 0 else "no oscillation"
        parts = ", ".join(f"X[{i}] {w:.2f}" for i, w in self.dominant() if w >= 0.01)
        state = "stable" if self.stable else ("marginal" if self.modulus == 1.0 else "UNSTABLE")
        return (f"|λ| = {self.modulus:.4f} ({state}), {kind}, β = {self.beta:.3g}/s "
                f"(decay {self.decay_time:.3g} s); shape: {parts}")


@dataclass(frozen=True, eq=False)
class AR2:
    """Second-order AR dynamics in shape-space (AC eq 9.15).

    ``X_k - mean = A2 (X_{k-2} - mean) + A1 (X_{k-1} - mean) + B0 w_k``, ``w_k ~ N(0, I)``.

    Attributes
    ----------
    A2 : ndarray of shape (Nx, Nx)
        Coefficient of the shape two frames back.
    A1 : ndarray of shape (Nx, Nx)
        Coefficient of the previous shape.
    B0 : ndarray of shape (Nx, Nx)
        Noise gain; the driving noise covariance is ``C = B0 B0ᵀ``.
    mean : ndarray of shape (Nx,)
        Mean shape ``X̄``.
    tau : float
        Frame interval in seconds.

    The arrays are stored as read-only float64 copies.  Construction raises
    :class:`~trackcli.errors.ModelError` when shapes disagree or values are not finite.
    """

    A2: np.ndarray
    A1: np.ndarray
    B0: np.ndarray
    mean: np.ndarray
    tau: float

    def __post_init__(self) -> None:
        arrays = {}
        for name in ("A2", "A1", "B0", "mean"):
            try:
                a = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                raise ModelError(f"dynamics {name} must be an array of numbers") from None
            arrays[name] = a
        mean = arrays["mean"]
        if mean.ndim != 1 or mean.size == 0:
            raise ModelError(f"dynamics mean must be a vector of length Nx >= 1, got an array of shape {mean.shape}")
        nx = mean.size
        for name in ("A2", "A1", "B0"):
            if arrays[name].shape != (nx, nx):
                raise ModelError(f"dynamics {name} must have shape ({nx}, {nx}) to match the mean of length {nx}, "
                                 f"got {arrays[name].shape}")
        for name, a in arrays.items():
            if not np.all(np.isfinite(a)):
                raise ModelError(f"dynamics {name} contains non-finite values")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        try:
            tau = float(self.tau)
        except (TypeError, ValueError):
            raise ModelError(f"dynamics tau must be a number of seconds, got {self.tau!r}") from None
        if not (math.isfinite(tau) and tau > 0):
            raise ModelError(f"dynamics tau (frame interval) must be a positive number of seconds, got {self.tau!r}")
        object.__setattr__(self, "tau", tau)

    # -- structure ----------------------------------------------------------------------------

    @property
    def nx(self) -> int:
        """Shape-space dimension ``Nx``."""
        return int(self.mean.size)

    def noise_covariance(self) -> np.ndarray:
        """``C = B0 B0ᵀ``, shape ``(Nx, Nx)``."""
        return self.B0 @ self.B0.T

    def state_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """State-space form for ``𝒳_k = (X_{k-1}; X_k)`` (AC eq 9.18).

        Returns
        -------
        A : ndarray of shape (2 Nx, 2 Nx)
            ``[[0, I], [A2, A1]]``.
        B : ndarray of shape (2 Nx, Nx)
            ``[[0], [B0]]``.
        """
        return state_matrices(self.A2, self.A1, self.B0)

    def state_mean(self) -> np.ndarray:
        """Mean state ``(X̄; X̄)``, shape ``(2 Nx,)``."""
        return np.concatenate([self.mean, self.mean])

    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of the state matrix ``A``, shape ``(2 Nx,)`` (complex)."""
        return np.linalg.eigvals(self.state_matrices()[0])

    def spectral_radius(self) -> float:
        """Largest eigenvalue modulus of ``A``; the model is stable when it is below 1."""
        return float(np.abs(self.eigenvalues()).max())

    def stability(self) -> str:
        """``"stable"`` (every mode decays), ``"marginal"`` (the slowest neither decays nor
        grows, e.g. constant velocity) or ``"UNSTABLE"``, with the spectral radius read to
        :data:`MODULUS_TOLERANCE` (a repeated eigenvalue 1 comes out of ``eig`` as 1 ± 1e-8)."""
        r = self.spectral_radius()
        if abs(r - 1.0) <= MODULUS_TOLERANCE:
            return "marginal"
        return "stable" if r < 1.0 else "UNSTABLE"

    def is_stable(self) -> bool:
        """True when every mode decays (spectral radius < 1), so a steady state exists."""
        return self.spectral_radius() < 1.0

    # -- steady state -------------------------------------------------------------------------

    def steady_state_covariance(self) -> np.ndarray:
        """Steady-state covariance ``P∞`` of the state ``𝒳 = (X_{k-1}; X_k)``.

        The fixed point of ``P = A P Aᵀ + B Bᵀ`` (AC eq 9.23), solved as a discrete
        Lyapunov equation.  The lower-right ``(Nx, Nx)`` block is the covariance of ``X``
        (the Gaussian envelope), the off-diagonal blocks the lag-one covariance.

        Returns
        -------
        ndarray of shape (2 Nx, 2 Nx)

        Raises
        ------
        DataError
            If the model is not stable (spectral radius >= 1), e.g. constant velocity.
        """
        radius = self.spectral_radius()
        if radius >= 1.0:
            raise DataError(f"the model has no steady state: its spectral radius is {radius:.6g} (must be < 1); "
                            "constant-velocity and other undamped motion grows without bound")
        return stationary_covariance(*self.state_matrices())

    def rms_displacement(self, H: np.ndarray, projector: np.ndarray | None = None) -> float:
        """Steady-state RMS curve displacement from the mean, ``sqrt(trace(H P_XX))``.

        Parameters
        ----------
        H : ndarray of shape (Nx, Nx)
            Shape-space metric matrix (``‖X‖² = Xᵀ H X`` is the mean-square displacement
            along the curve, AC eq 8.6).
        projector : ndarray of shape (Nx, Nx), optional
            An H-orthogonal projector ``E`` onto a subspace; then the RMS displacement of
            ``E X`` alone, ``sqrt(trace(H E P_XX Eᵀ))``.

        Returns
        -------
        float
            In the units of the curve (pixels).
        """
        H = check_metric(H, self.nx)
        n = self.nx
        P = self.steady_state_covariance()[n:, n:]
        if projector is not None:
            E = np.asarray(projector, dtype=float)
            if E.shape != (n, n):
                raise DataError(f"projector must have shape ({n}, {n}), got {E.shape}")
            P = E @ P @ E.T
        return math.sqrt(max(float(np.trace(H @ P)), 0.0))

    # -- sampling -----------------------------------------------------------------------------

    def predict(self, prev: np.ndarray, cur: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Sample ``X_k`` from ``X_{k-2}, X_{k-1}`` (shape ``(N, Nx)`` or ``(Nx,)``): :func:`predict_samples`."""
        prev, cur = np.asarray(prev, dtype=float), np.asarray(cur, dtype=float)
        if cur.shape != prev.shape or cur.ndim not in (1, 2) or cur.shape[-1] != self.nx:
            raise DataError(f"prev and cur must both have shape (N, {self.nx}) or ({self.nx},), "
                            f"got {prev.shape} and {cur.shape}")
        out = predict_samples(np.atleast_2d(prev), np.atleast_2d(cur), self, rng)
        return out[0] if cur.ndim == 1 else out

    def simulate(self, n_frames: int, rng: np.random.Generator, *, x0: np.ndarray | None = None,
                 x1: np.ndarray | None = None, burn_in: int = 0) -> np.ndarray:
        """Draw one sample path (AC Fig 11.7: the quickest check of a model).

        Parameters
        ----------
        n_frames : int
            Number of frames returned.
        rng : numpy.random.Generator
            Source of the driving noise.
        x0, x1 : ndarray of shape (Nx,), optional
            The first two shapes of the path.  ``x0`` defaults to the mean; ``x1``
            defaults to ``x0`` (starting at rest).
        burn_in : int
            Frames generated first and discarded, so that a stable model forgets its
            starting point; the returned path then starts ``burn_in`` frames later.

        Returns
        -------
        ndarray of shape (n_frames, Nx)
            With ``burn_in = 0`` the first two rows are ``x0`` and ``x1``.
        """
        n_frames, burn_in = int(n_frames), int(burn_in)
        if n_frames < 1:
            raise DataError(f"n_frames must be at least 1, got {n_frames}")
        if burn_in < 0:
            raise DataError(f"burn_in must be >= 0, got {burn_in}")
        start = self.mean if x0 is None else self._vector(x0, "x0")
        second = start if x1 is None else self._vector(x1, "x1")
        total = n_frames + burn_in
        dev = np.zeros((max(total, 2), self.nx))
        dev[0], dev[1] = start - self.mean, second - self.mean
        noise = rng.standard_normal((max(total - 2, 0), self.nx)) @ self.B0.T
        for k in range(2, total):
            dev[k] = self.A2 @ dev[k - 2] + self.A1 @ dev[k - 1] + noise[k - 2]
        return (dev + self.mean)[burn_in:total]

    def _vector(self, x: Any, name: str) -> np.ndarray:
        v = np.asarray(x, dtype=float)
        if v.shape != (self.nx,):
            raise DataError(f"{name} must be a shape vector of length {self.nx}, got shape {v.shape}")
        return v

    # -- modal analysis -----------------------------------------------------------------------

    def modes(self) -> list[Mode]:
        """Modal analysis of the state matrix (AC §11.3, eqs 11.10-11.13).

        Returns
        -------
        list of Mode
            One entry per real eigenvalue and one per conjugate pair, slowest decay
            (largest ``|λ|``) first.
        """
        A, _ = self.state_matrices()
        vals, vecs = np.linalg.eig(A)
        n, tau = self.nx, self.tau
        out = []
        for lam, vec in zip(vals, vecs.T):
            lam = _snap(complex(lam))
            if lam.imag < 0:
                continue  # represented by its conjugate
            x = np.asarray(vec[:n], dtype=complex)
            x = x / np.linalg.norm(x)
            big = int(np.argmax(np.abs(x)))
            x = x * (abs(x[big]) / x[big])
            if lam.imag == 0:
                x = x.real.astype(complex)
            modulus = abs(lam)
            beta = math.inf if modulus == 0 else 0.0 if modulus == 1.0 else -math.log(modulus) / tau
            if lam.imag > 0:
                freq = math.atan2(lam.imag, lam.real) / (2 * math.pi * tau)
            elif lam.real < 0:
                freq = 1.0 / (2 * tau)
            else:
                freq = 0.0
            decay = math.inf if beta == 0 else 1.0 / beta
            period = math.inf if freq == 0 else 1.0 / freq
            weights = np.abs(x) ** 2
            x.setflags(write=False)
            weights.setflags(write=False)
            out.append(Mode(eigenvalue=lam, modulus=modulus, beta=beta, frequency=freq, decay_time=decay,
                            period=period, stable=modulus < 1.0, shape=x, weights=weights))
        out.sort(key=lambda m: (-m.modulus, m.frequency))
        return out

    # -- files --------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """Plain nested lists and floats, for YAML."""
        return {
            "tau": float(self.tau),
            "mean": [float(v) for v in self.mean],
            "A2": [[float(v) for v in row] for row in self.A2],
            "A1": [[float(v) for v in row] for row in self.A1],
            "B0": [[float(v) for v in row] for row in self.B0],
        }

    @classmethod
    def from_dict(cls, d: Any, where: str = "dynamics") -> AR2:
        """Rebuild a model from :meth:`to_dict` output, validating everything.

        Raises
        ------
        ModelError
            Naming ``where`` and the offending key when the mapping is malformed.
        """
        keys = ("tau", "mean", "A2", "A1", "B0")
        if not isinstance(d, Mapping):
            raise ModelError(f"{where}: expected a mapping with keys {', '.join(keys)}, got {type(d).__name__}")
        missing = [k for k in keys if k not in d]
        if missing:
            raise ModelError(f"{where}: missing {', '.join(missing)} (an AR(2) model needs {', '.join(keys)})")
        unknown = sorted(str(k) for k in d if k not in keys)
        if unknown:
            raise ModelError(f"{where}: unknown key(s) {', '.join(unknown)} (valid: {', '.join(keys)})")
        values: dict[str, Any] = {}
        for key, ndim in (("mean", 1), ("A2", 2), ("A1", 2), ("B0", 2)):
            raw = d[key]
            what = "a list of numbers" if ndim == 1 else "a list of rows of numbers"
            if isinstance(raw, (str, bytes)) or isinstance(raw, Mapping):
                raise ModelError(f"{where}.{key}: expected {what}, got {raw!r}")
            try:
                arr = np.array(raw, dtype=float)
            except (TypeError, ValueError):
                raise ModelError(f"{where}.{key}: expected {what} (rows of equal length)") from None
            if arr.ndim != ndim:
                raise ModelError(f"{where}.{key}: expected {what}, got an array of shape {arr.shape}")
            values[key] = arr
        tau = d["tau"]
        if isinstance(tau, bool) or not isinstance(tau, (int, float)):
            raise ModelError(f"{where}.tau: expected the frame interval in seconds, got {tau!r}")
        try:
            return cls(values["A2"], values["A1"], values["B0"], values["mean"], float(tau))
        except ModelError as exc:
            raise ModelError(f"{where}: {exc}") from None


# ---------------------------------------------------------------------------------------------
# State-space form, steady state, prediction of samples


def state_matrices(A2: np.ndarray, A1: np.ndarray, B0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First-order form of AR(2) dynamics on ``𝒳_k = (X_{k-1}; X_k)`` (AC eq 9.18).

    Returns ``A = [[0, I], [A2, A1]]`` (the block-companion matrix, shape ``(2 Nx, 2 Nx)``)
    and ``B = [[0], [B0]]`` (shape ``(2 Nx, Nw)``).
    """
    A2, A1, B0 = (np.asarray(m, dtype=float) for m in (A2, A1, B0))
    n = A1.shape[0]
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = A2
    A[n:, n:] = A1
    B = np.zeros((2 * n, B0.shape[1]))
    B[n:] = B0
    return A, B


def spectral_radius(A2: np.ndarray, A1: np.ndarray) -> float:
    """Largest eigenvalue modulus of the state matrix ``[[0, I], [A2, A1]]`` (AC eq 9.17)."""
    A, _ = state_matrices(A2, A1, np.zeros((np.shape(A1)[0], 1)))
    return float(np.abs(np.linalg.eigvals(A)).max())


def stationary_covariance(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The fixed point of ``P = A P Aᵀ + B Bᵀ`` (AC eq 9.23), a discrete Lyapunov equation.

    The caller checks that ``A`` is stable; the result is symmetrised.
    """
    import warnings

    import scipy.linalg  # imported here, not at start-up: it takes a tenth of a second

    Q = B @ B.T
    with warnings.catch_warnings():
        # near the edge of stability scipy warns of an ill-conditioned system; what matters is
        # whether the solution satisfies the equation, checked below
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        P = scipy.linalg.solve_discrete_lyapunov(A, Q)
    P = 0.5 * (P + P.T)
    residual = np.linalg.norm(A @ P @ A.T + Q - P) / max(np.linalg.norm(P), 1e-300)
    if not residual < 1e-6:
        log.warning(
            "the stationary covariance is inaccurate (relative residual %.1g): the dynamics are close to "
            "the edge of stability", residual)
    return P


def dynamics_arrays(dynamics: Any, nx: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A1, A2, B0, mean)`` of any object that has them (an :class:`AR2`, or a duck), checked.

    Shapes ``A1, A2: (Nx, Nx)``, ``B0: (Nx, Nw)``, ``mean: (Nx,)``, all finite; with ``nx``,
    ``Nx`` must equal it.  Raises :class:`~trackcli.errors.ConfigError` naming what is wrong (the same for every
    filter that takes dynamics).
    """
    try:
        a1, a2, b0, mean = (np.asarray(getattr(dynamics, k), dtype=np.float64) for k in ("A1", "A2", "B0", "mean"))
    except AttributeError as exc:
        raise ConfigError(f"dynamics: expected attributes A1, A2, B0 and mean ({exc})") from None
    size = mean.shape[0] if mean.ndim == 1 else -1
    if nx is not None and size != nx:
        raise ConfigError(f"dynamics: mean has shape {mean.shape}, expected ({nx},) to match the state")
    if size < 1 or a1.shape != (size, size) or a2.shape != (size, size) or b0.ndim != 2 or b0.shape[0] != size:
        raise ConfigError(
            f"dynamics: expected A1, A2 of shape (Nx, Nx), B0 of shape (Nx, Nw) and mean of shape (Nx,); "
            f"got {a1.shape}, {a2.shape}, {b0.shape}, {mean.shape}"
        )
    for name, value in (("A1", a1), ("A2", a2), ("B0", b0), ("mean", mean)):
        if not np.all(np.isfinite(value)):
            raise ConfigError(f"dynamics.{name} contains NaN or inf")
    return a1, a2, b0, mean


def predict_samples(prev: np.ndarray, cur: np.ndarray, dynamics: Any, rng: np.random.Generator) -> np.ndarray:
    """Draw ``X_{k+1}`` for every sample from the AR(2) model (AC eq 9.15; the predict step of AC Fig 12.6).

    Parameters
    ----------
    prev, cur : ndarray of shape (N, Nx)
        ``X_{k-1}`` and ``X_k``.
    dynamics
        Object with ``A1``, ``A2`` (Nx, Nx), ``B0`` (Nx, Nw), ``mean`` (Nx,).
    rng : numpy.random.Generator
        Source of the fresh noise ``w ~ N(0, I_Nw)``.

    Returns
    -------
    ndarray of shape (N, Nx)
        ``X̄ + A2 (X_{k-1} - X̄) + A1 (X_k - X̄) + B0 w``.
    """
    prev = np.asarray(prev, dtype=np.float64)
    cur = np.asarray(cur, dtype=np.float64)
    a1, a2, b0, mean = dynamics_arrays(dynamics, cur.shape[-1] if cur.ndim == 2 else None)
    if cur.ndim != 2 or prev.shape != cur.shape:
        raise DataError(f"prev and cur: expected equal shapes (N, Nx), got {prev.shape} and {cur.shape}")
    out = rng.standard_normal((cur.shape[0], b0.shape[1])) @ b0.T
    out += cur @ a1.T
    out += prev @ a2.T
    out += mean - (a1 + a2) @ mean  # few temporaries: this runs on every sample every frame
    return out
