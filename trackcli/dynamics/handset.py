"""Hand-set dynamics (AC §9.6): damped oscillators, and the motion model a template gets
before any learning.

A damped oscillator is set by a frequency ``f`` (Hz), a damping rate ``beta`` (1/s) and a
steady-state RMS displacement ``rho`` (pixels, measured with the curve norm
``‖X‖² = Xᵀ H X``), which fix its coefficients ``(a1, a2, b0)`` by AC eqs 9.25-9.26
(:func:`oscillator_coefficients`); the constant-velocity case ``f = beta = 0`` is set by a
growth rate ``gamma0`` instead (eq 9.28).  :func:`partitioned` splits shape-space into
H-orthogonal subspaces, each with its own oscillator (eq 9.30), into one
:class:`~trackcli.dynamics.ar2.AR2` model; :func:`handset_dynamics` does so for a template's
space from the ``dynamics`` settings.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trackcli.dynamics.ar2 import AR2, check_metric, symmetric_sqrt
from trackcli.errors import ConfigError, DataError
from trackcli.settings import DynamicsSettings, SubspaceDynamics
from trackcli.shapes.outline import object_size
from trackcli.shapes.shape_space import ShapeSpace

__all__ = ["SubspaceModel", "h_orthogonal_projector", "handset_dynamics", "oscillator_coefficients", "partitioned"]


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be a number, got {value!r}")
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return out


def oscillator_coefficients(f: float, beta: float, rho: float | None, tau: float, *,
                            gamma0: float | None = None) -> tuple[float, float, float]:
    """Coefficients ``(a1, a2, b0)`` of a one-dimensional damped oscillator (AC §9.6).

    ``a2 = -exp(-2βτ)`` and ``a1 = 2 exp(-βτ) cos(2πfτ)`` (AC eq 9.25) put the state
    matrix eigenvalues at ``exp(-βτ ± 2πifτ)``.  ``b0`` gives the steady-state RMS
    displacement ``rho`` (AC eq 9.26)::

        b0 = rho * sqrt(1 - a2² - a1² - 2 a2 a1² / (1 - a2))

    evaluated in an algebraically equal form that keeps its precision when ``βτ`` is
    small.  ``f = 0`` is critical damping.

    Constant velocity, ``f = beta = 0`` (so ``a1 = 2, a2 = -1``), has no steady state and
    ``rho`` is not used; the noise is set by the growth rate ``gamma0`` instead,
    ``b0 = gamma0 τ^{3/2}`` (AC eq 9.28).  With that ``b0`` the RMS displacement after
    ``n`` frames from a known position and velocity is ``b0 sqrt(Σ_{m=1..n} m²)``, which
    grows as ``(gamma0/√3) t^{3/2}``: the book's ``ρ(t) = gamma0 t^{3/2}`` up to that
    constant factor.

    With ``f = 0``, ``beta > 0``, ``rho = None`` and ``gamma0`` given, the model is a
    *damped velocity* with a free position: ``a1 = 1 + exp(-βτ)``, ``a2 = -exp(-βτ)``
    (eigenvalues 1 and ``exp(-βτ)``), ``b0 = gamma0 τ^{3/2}``.  The velocity forgets itself
    at the rate ``beta`` and the position has no steady state and no preferred place — the
    right prior for the translation of an object that may roam anywhere in the frame.

    Parameters
    ----------
    f : float
        Frequency in Hz, ``0 <= f <= 1/(2τ)`` (higher frequencies alias).
    beta : float
        Damping rate in 1/s, ``>= 0``; 0 only together with ``f = 0``.
    rho : float or None
        Steady-state RMS displacement (pixels), ``>= 0``; ignored for constant velocity.
    tau : float
        Frame interval in seconds, ``> 0``.
    gamma0 : float, optional
        Constant-velocity growth rate in pixels / s^{3/2}; required when ``f = beta = 0``.

    Returns
    -------
    (a1, a2, b0) : tuple of float
    """
    f = _number("f", f)
    beta = _number("beta", beta)
    tau = _number("tau", tau)
    if tau <= 0:
        raise ConfigError(f"tau (frame interval) must be > 0 seconds, got {tau}")
    if beta < 0:
        raise ConfigError(f"beta (damping rate) must be >= 0 per second, got {beta}")
    nyquist = 1.0 / (2.0 * tau)
    if not 0 <= f <= nyquist * (1 + 1e-12):
        raise ConfigError(f"f must lie between 0 and the Nyquist frequency 1/(2 tau) = {nyquist:.6g} Hz, got {f}")
    if beta == 0:
        if f != 0:
            raise ConfigError(f"an undamped oscillation (beta = 0, f = {f} Hz) has no steady state; "
                              "use beta > 0, or f = beta = 0 for constant velocity")
        if gamma0 is None:
            raise ConfigError("constant-velocity dynamics (f = beta = 0) have no steady state, so rho cannot set "
                              "the noise: give gamma0 (RMS growth rate, pixels / s^1.5; AC eq 9.28)")
        g = _number("gamma0", gamma0)
        if g < 0:
            raise ConfigError(f"gamma0 must be >= 0, got {g}")
        return 2.0, -1.0, g * tau**1.5
    if rho is None and gamma0 is not None and f == 0:
        # Damped velocity, free position: eigenvalues 1 and exp(-βτ), so
        # X_k - X_{k-1} = exp(-βτ) (X_{k-1} - X_{k-2}) + b0 w_k, with b0 = gamma0 τ^{3/2}
        # as in the constant-velocity case (AC eq 9.28), which this becomes as β → 0.
        g = _number("gamma0", gamma0)
        if g < 0:
            raise ConfigError(f"gamma0 must be >= 0, got {g}")
        decay = math.exp(-beta * tau)
        return 1.0 + decay, -decay, g * tau**1.5
    if rho is None:
        raise ConfigError(f"rho (steady-state RMS displacement) is required for a damped oscillator (beta = {beta}); "
                          "or give gamma0 with f = 0 and rho null for a damped velocity with a free position")
    r = _number("rho", rho)
    if r < 0:
        raise ConfigError(f"rho must be >= 0, got {r}")
    decay = math.exp(-beta * tau)
    theta = 2.0 * math.pi * f * tau
    a2 = -decay * decay
    a1 = 2.0 * decay * math.cos(theta)
    # 1 - a2² - a1² - 2 a2 a1²/(1 - a2) = (1 + a2)(1 - a2 - a1)(1 - a2 + a1) / (1 - a2), with
    # 1 + a2 = -expm1(-2βτ), 1 - a2 ∓ a1 = (1 - e)² + 4 e sin²(θ/2)  resp.  (1 - e)² + 4 e cos²(θ/2).
    one_plus_a2 = -math.expm1(-2.0 * beta * tau)
    gap = -math.expm1(-beta * tau)
    minus = gap * gap + 4.0 * decay * math.sin(theta / 2) ** 2
    plus = gap * gap + 4.0 * decay * math.cos(theta / 2) ** 2
    b0 = r * math.sqrt(one_plus_a2 * minus * plus / (1.0 - a2))
    return a1, a2, b0


@dataclass(frozen=True, eq=False)
class SubspaceModel:
    """One part of a partitioned model (AC eq 9.30): a subspace and its oscillator.

    Attributes
    ----------
    projector : ndarray of shape (Nx, Nx)
        H-orthogonal projector ``E`` onto the subspace (``E² = E``, ``H E`` symmetric).
    a1, a2, b0 : float
        Oscillator coefficients, e.g. from :func:`oscillator_coefficients`.
    """

    projector: np.ndarray
    a1: float
    a2: float
    b0: float

    def __post_init__(self) -> None:
        E = np.array(self.projector, dtype=float)
        if E.ndim != 2 or E.shape[0] != E.shape[1]:
            raise DataError(f"a subspace projector must be a square matrix, got shape {E.shape}")
        if not np.all(np.isfinite(E)):
            raise DataError("a subspace projector contains non-finite values")
        E.setflags(write=False)
        object.__setattr__(self, "projector", E)
        for name in ("a1", "a2", "b0"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise DataError(f"subspace coefficient {name} must be finite, got {value}")
            object.__setattr__(self, name, value)

    @classmethod
    def oscillator(cls, projector: np.ndarray, f: float, beta: float, rho: float | None, tau: float, *,
                   gamma0: float | None = None) -> SubspaceModel:
        """A subspace with the oscillator of :func:`oscillator_coefficients`."""
        a1, a2, b0 = oscillator_coefficients(f, beta, rho, tau, gamma0=gamma0)
        return cls(projector, a1, a2, b0)

    @property
    def rank(self) -> int:
        """Dimension ``N_i`` of the subspace (the trace of the projector)."""
        return int(round(float(np.trace(self.projector))))


def h_orthogonal_projector(H: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """H-orthogonal projector onto the span of some shape-space directions.

    ``E = V (Vᵀ H V)⁻¹ Vᵀ H``: ``E X`` is the closest point of the subspace to ``X`` in the
    curve norm, and ``I - E`` projects onto its H-orthogonal complement.

    Parameters
    ----------
    H : ndarray of shape (Nx, Nx)
        Shape-space metric matrix.
    basis : ndarray of shape (Nx, k)
        Columns spanning the subspace (e.g. the unit vectors of the translation
        components of an affine space).

    Returns
    -------
    ndarray of shape (Nx, Nx)
    """
    V = np.asarray(basis, dtype=float)
    if V.ndim == 1:
        V = V[:, None]
    if V.ndim != 2 or V.shape[1] < 1:
        raise DataError(f"basis must be an (Nx, k) array of column vectors, got shape {V.shape}")
    H = check_metric(H, V.shape[0])
    G = V.T @ H @ V
    if np.linalg.matrix_rank(G) < V.shape[1]:
        raise DataError(f"the {V.shape[1]} basis columns are linearly dependent")
    return V @ np.linalg.solve(G, V.T @ H)


def partitioned(H: np.ndarray, parts: Sequence[SubspaceModel], mean: np.ndarray, tau: float) -> AR2:
    """Partitioned harmonic model across H-orthogonal subspaces (AC eq 9.30).

    ``A2 = Σ a2ⁱ Eⁱ``, ``A1 = Σ a1ⁱ Eⁱ``, ``B0 = Σ (b0ⁱ / √Nᵢ) Eⁱ H^{-1/2}`` with the
    symmetric square root of ``H``.  Because the projectors are H-orthogonal, each
    subspace moves independently and its steady-state covariance is
    ``(ρᵢ² / Nᵢ) Eⁱ H⁻¹`` (AC eq 9.29 per subspace), so the RMS displacement of ``Eⁱ X`` is
    the ``ρᵢ`` its ``b0ⁱ`` was designed for; the variances add up over subspaces.  One part
    with ``E = I`` is the isotropic model of AC §9.6.

    Parameters
    ----------
    H : ndarray of shape (Nx, Nx)
        Shape-space metric matrix.
    parts : sequence of SubspaceModel
        Subspaces whose projectors sum to the identity.
    mean : ndarray of shape (Nx,)
        Mean shape ``X̄`` (e.g. zeros: the template itself).
    tau : float
        Frame interval in seconds.

    Returns
    -------
    AR2
    """
    mean = np.asarray(mean, dtype=float)
    if mean.ndim != 1:
        raise DataError(f"mean must be a shape vector of shape (Nx,), got {mean.shape}")
    n = mean.size
    H = check_metric(H, n)
    parts = list(parts)
    if not parts:
        raise DataError("a partitioned model needs at least one subspace")
    eye = np.eye(n)
    total = np.zeros((n, n))
    A2 = np.zeros((n, n))
    A1 = np.zeros((n, n))
    B0 = np.zeros((n, n))
    h_inv_root = symmetric_sqrt(H, inverse=True)
    tol = 1e-8
    for i, part in enumerate(parts):
        if not isinstance(part, SubspaceModel):
            raise DataError(f"part {i} must be a SubspaceModel, got {type(part).__name__}")
        E = part.projector
        if E.shape != (n, n):
            raise DataError(f"part {i}: projector must have shape ({n}, {n}), got {E.shape}")
        scale = max(1.0, float(np.abs(E).max()))
        if np.abs(E @ E - E).max() > tol * scale:
            raise DataError(f"part {i}: the matrix is not a projector (E @ E differs from E)")
        HE = H @ E
        if np.abs(HE - HE.T).max() > tol * scale * float(np.abs(H).max()):
            raise DataError(f"part {i}: the projector is not H-orthogonal (H E must be symmetric); "
                            "build it with h_orthogonal_projector")
        rank = part.rank
        if rank < 1:
            raise DataError(f"part {i}: the projector is zero (rank 0)")
        total += E
        A2 += part.a2 * E
        A1 += part.a1 * E
        B0 += (part.b0 / math.sqrt(rank)) * E
    if np.abs(total - eye).max() > tol * len(parts):
        raise DataError("the subspace projectors must sum to the identity (every shape direction in exactly one part)")
    return AR2(A2, A1, B0 @ h_inv_root, mean, tau)


def _subspace_part(E: np.ndarray, s: SubspaceDynamics, tau: float, what: str, unit: float) -> SubspaceModel:
    rho = None if s.rho is None else s.rho * unit
    gamma0 = None if s.gamma0 is None else s.gamma0 * unit
    try:
        return SubspaceModel.oscillator(E, s.f, s.beta, rho, tau, gamma0=gamma0)
    except ConfigError as exc:
        raise ConfigError(f"dynamics.{what}: {exc}") from None


def handset_dynamics(space: ShapeSpace, settings: DynamicsSettings, tau: float) -> AR2:
    """Partitioned damped-oscillator dynamics (AC §9.6, eq 9.30) on translation and the rest.

    The translation subspace gets ``settings.translation``; its H-orthogonal complement
    (rotation, scale and other deformation) gets ``settings.deformation``.  The mean shape is
    the template (``X̄ = 0``), so a damped deformation returns to the template's shape and
    size: scale and rotation cannot drift without bound.

    With ``settings.units = "object"`` the steady-state RMS displacements ``rho`` (and
    ``gamma0``) are in units of the template's size (:func:`~trackcli.shapes.outline.object_size`),
    so the same settings describe a small and a large object alike; the damping ``beta`` (1/s)
    and frequency ``f`` (Hz) are converted per frame with the clip's frame interval ``tau``.
    """
    unit = object_size(space) if settings.units == "object" else 1.0
    Es = space.translation_projector()
    parts = [_subspace_part(Es, settings.translation, tau, "translation", unit)]
    if space.Nx > 2:
        parts.append(_subspace_part(np.eye(space.Nx) - Es, settings.deformation, tau, "deformation", unit))
    return partitioned(space.H, parts, np.zeros(space.Nx), tau)
