"""Maximum-likelihood learning of AR(2) dynamics from tracked sequences (AC ch 11).

Given shape vectors ``X_1 .. X_M`` (one per frame), the AR(2) model (AC eq 9.15) written
with an intercept ``D = (I - A2 - A1) X̄`` is linear in its unknowns::

    X_k = A2 X_{k-2} + A1 X_{k-1} + D + B0 w_k,    k = 3 .. M

Maximising the likelihood (AC eq 11.6) therefore needs only the sums over the ``M - 2``
frame triples (AC Fig 11.6, step 1)::

    R_i  = Σ_k X_{k-i}                      i = 0, 1, 2
    R_ij = Σ_k X_{k-i} X_{k-j}ᵀ             i, j = 0, 1, 2
    R'_ij = R_ij - R_i R_jᵀ / (M - 2)

and then (steps 2-4)::

    [Â2 Â1] [[R'_22, R'_21], [R'_12, R'_11]] = [R'_02, R'_01]
    D̂ = (R_0 - Â2 R_2 - Â1 R_1) / (M - 2)
    X̄ = (I - Â2 - Â1)⁻¹ D̂
    Ĉ = Z / (M - 2),   Z = Σ_k r_k r_kᵀ the residual scatter,   B̂0 = √Ĉ

The normal equations are solved as one symmetric ``2Nx × 2Nx`` system, which is the
book's pair of formulas for ``Â2`` and ``Â1`` without the explicit inverses.  ``Ĉ``
divides by the number of triples, as the book does; it equals statsmodels'
``VAR(...).fit(2).sigma_u_mle`` (``sigma_u`` instead divides by the residual degrees of
freedom ``M - 2 - (2 Nx + 1)``).  With ``Nx = 1`` and a known zero mean this is the
univariate algorithm of AC Fig 11.2.

Several training sequences are combined by adding their statistics
(:class:`AR2Statistics` supports ``+`` and ``sum``), never by joining the clips: a join
would count the jump from the end of one clip to the start of the next as motion
(AC §11.2, "modular learning").  The pooled estimate is the least-squares fit with one
shared ``A2, A1, D`` over the triples of all sequences.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trackcli.dynamics.ar2 import AR2, state_matrices, symmetric_sqrt
from trackcli.errors import DataError

__all__ = ["AR2Statistics", "LearningReport", "fit_ar2", "stabilise"]

# Singular values of (I - Â2 - Â1) below this make the mean X̄ numerically undefined.
MEAN_SINGULAR_TOL = 1e-8
# Smallest eigenvalue of the correlation-scaled normal matrix accepted as non-singular.
NORMAL_EQUATIONS_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class AR2Statistics:
    """Sufficient statistics of AR(2) learning for one or more sequences (AC Fig 11.6).

    Attributes
    ----------
    count : int
        Number of frame triples ``(X_{k-2}, X_{k-1}, X_k)``: ``M - 2`` per sequence of
        ``M >= 3`` frames.
    sums : ndarray of shape (3, Nx)
        ``sums[i] = R_i = Σ X_{k-i}``.
    products : ndarray of shape (3, 3, Nx, Nx)
        ``products[i, j] = R_ij = Σ X_{k-i} X_{k-j}ᵀ``.
    n_sequences : int
        Number of sequences pooled.
    n_frames : int
        Total number of frames in them.

    Statistics of separate sequences add (``a + b``, ``sum([...])``); the result is the
    statistics of the triples of all of them, with no triple spanning two sequences.
    """

    count: int
    sums: np.ndarray
    products: np.ndarray
    n_sequences: int = 1
    n_frames: int = 0

    def __post_init__(self) -> None:
        sums = np.array(self.sums, dtype=float)
        products = np.array(self.products, dtype=float)
        if sums.ndim != 2 or sums.shape[0] != 3:
            raise DataError(f"sums must have shape (3, Nx), got {sums.shape}")
        nx = sums.shape[1]
        if products.shape != (3, 3, nx, nx):
            raise DataError(f"products must have shape (3, 3, {nx}, {nx}), got {products.shape}")
        if int(self.count) < 0:
            raise DataError(f"count must be >= 0, got {self.count}")
        sums.setflags(write=False)
        products.setflags(write=False)
        object.__setattr__(self, "sums", sums)
        object.__setattr__(self, "products", products)
        object.__setattr__(self, "count", int(self.count))

    @classmethod
    def from_sequence(cls, X: Any) -> AR2Statistics:
        """Statistics of one contiguous sequence.

        Parameters
        ----------
        X : array_like of shape (M, Nx), or (M,) for a one-dimensional signal
            Shape vectors of consecutive frames.  A sequence of fewer than 3 frames has no
            triples and contributes nothing (``count = 0``).

        Raises
        ------
        DataError
            If ``X`` has the wrong dimensions or contains NaN / infinity (split a track at
            lost frames and pool the pieces instead).
        """
        X = _as_sequence(X)
        m, nx = X.shape
        count = max(m - 2, 0)
        sums = np.zeros((3, nx))
        products = np.zeros((3, 3, nx, nx))
        if count:
            lagged = [X[2 - i: m - i] for i in range(3)]  # lagged[i][t] = X_{k-i}
            for i in range(3):
                sums[i] = lagged[i].sum(axis=0)
                for j in range(i, 3):
                    products[i, j] = lagged[i].T @ lagged[j]
                    products[j, i] = products[i, j].T
        return cls(count, sums, products, 1, m)

    @property
    def nx(self) -> int:
        """Shape-space dimension ``Nx``."""
        return int(self.sums.shape[1])

    def R(self, i: int) -> np.ndarray:
        """``R_i``, shape ``(Nx,)``."""
        return self.sums[i]

    def Rij(self, i: int, j: int) -> np.ndarray:
        """``R_ij``, shape ``(Nx, Nx)``."""
        return self.products[i, j]

    def Rprime(self, i: int, j: int) -> np.ndarray:
        """``R'_ij = R_ij - R_i R_jᵀ / count`` (AC Fig 11.6), shape ``(Nx, Nx)``."""
        if self.count == 0:
            raise DataError("no frame triples: R' is undefined")
        return self.products[i, j] - np.outer(self.sums[i], self.sums[j]) / self.count

    def __add__(self, other: AR2Statistics) -> AR2Statistics:
        if not isinstance(other, AR2Statistics):
            return NotImplemented
        if other.nx != self.nx:
            raise DataError(f"cannot pool statistics of {self.nx}-dimensional and {other.nx}-dimensional shape vectors")
        return AR2Statistics(self.count + other.count, self.sums + other.sums, self.products + other.products,
                             self.n_sequences + other.n_sequences, self.n_frames + other.n_frames)

    def __radd__(self, other: Any) -> AR2Statistics:
        if isinstance(other, int) and other == 0:  # lets sum() start from 0
            return self
        return NotImplemented


@dataclass(frozen=True, eq=False)
class LearningReport:
    """What :func:`fit_ar2` did, for logs and model files.

    Attributes
    ----------
    n_sequences, n_frames, n_triples : int
        Data used: sequences pooled, their frames, and the frame triples in the fit.
    spectral_radius : float
        Largest eigenvalue modulus of the returned model's state matrix.
    stable : bool
        ``spectral_radius < 1``.
    unconstrained_spectral_radius : float
        The same for the plain maximum-likelihood fit.
    stabilised : str
        ``"no"``; ``"modes"`` (only the modes above the limit were pulled in) or
        ``"scaled"`` (all modes scaled), see :func:`fit_ar2`.
    mean_source : str
        How ``X̄`` was found: ``"intercept"`` (``(I - Â2 - Â1)⁻¹ D̂``), ``"data"`` (some
        directions taken from the data mean because ``I - Â2 - Â1`` is singular) or
        ``"given"``.
    dropped_drift : float
        Norm of the part of ``D̂`` that the mean form of the model cannot express (a
        steady drift along a random-walk direction); 0 unless ``mean_source == "data"``.
    intercept : ndarray of shape (Nx,)
        ``D̂`` (for the returned ``A2, A1``).
    log_likelihood : float
        AC eq 11.6 at the returned parameters, including the Gaussian normalising
        constant ``-(n Nx / 2) log 2π``; ``inf`` if ``Ĉ`` is singular (noise-free data).
    residual_rms : float
        ``sqrt(trace(Ĉ) / Nx)``: RMS one-step prediction error per component.
    """

    n_sequences: int
    n_frames: int
    n_triples: int
    spectral_radius: float
    stable: bool
    unconstrained_spectral_radius: float
    stabilised: str
    mean_source: str
    dropped_drift: float
    intercept: np.ndarray = field(repr=False)
    log_likelihood: float
    residual_rms: float

    def to_dict(self) -> dict[str, Any]:
        """Plain values, for YAML or JSON."""
        return {
            "n_sequences": self.n_sequences,
            "n_frames": self.n_frames,
            "n_triples": self.n_triples,
            "spectral_radius": float(self.spectral_radius),
            "stable": bool(self.stable),
            "unconstrained_spectral_radius": float(self.unconstrained_spectral_radius),
            "stabilised": self.stabilised,
            "mean_source": self.mean_source,
            "dropped_drift": float(self.dropped_drift),
            "intercept": [float(v) for v in self.intercept],
            "log_likelihood": float(self.log_likelihood),
            "residual_rms": float(self.residual_rms),
        }


# ---------------------------------------------------------------------------------------------


def _as_sequence(X: Any) -> np.ndarray:
    try:
        X = np.array(X, dtype=float)
    except (TypeError, ValueError):
        raise DataError("a training sequence must be an array of numbers of shape (frames, Nx)") from None
    if X.ndim == 1:
        X = X[:, None]
    if X.ndim != 2 or X.shape[1] < 1:
        raise DataError(f"a training sequence must have shape (frames, Nx), got {X.shape}")
    bad = ~np.all(np.isfinite(X), axis=1)
    if bad.any():
        frames = np.flatnonzero(bad)
        listed = ", ".join(str(int(f)) for f in frames[:5]) + (", ..." if frames.size > 5 else "")
        raise DataError(f"training sequence has non-finite shape vectors at frame(s) {listed}; "
                        "split it at lost frames and pass the pieces as separate sequences")
    return X


def _collect(data: Any) -> AR2Statistics:
    if isinstance(data, AR2Statistics):
        return data
    if isinstance(data, np.ndarray):
        return AR2Statistics.from_sequence(data)
    if isinstance(data, (str, bytes)) or not isinstance(data, Iterable):
        raise DataError("training data must be AR2Statistics, one (frames, Nx) array, or a list of them; "
                        f"got {type(data).__name__}")
    items = [item if isinstance(item, AR2Statistics) else AR2Statistics.from_sequence(item) for item in data]
    if not items:
        raise DataError("no training sequences given")
    return sum(items[1:], items[0])


def _centred_products(stats: AR2Statistics, mean: np.ndarray | None) -> list[list[np.ndarray]]:
    """``S[i][j] = Σ (X_{k-i} - c_i)(X_{k-j} - c_j)ᵀ`` about the lag means, or about ``mean``."""
    n = stats.count
    S = [[np.empty(0)] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(3):
            if mean is None:
                S[i][j] = stats.Rprime(i, j)
            else:
                S[i][j] = (stats.Rij(i, j) - np.outer(stats.R(i), mean) - np.outer(mean, stats.R(j))
                           + n * np.outer(mean, mean))
    return S


def _solve_normal_equations(S: list[list[np.ndarray]], stats: AR2Statistics) -> np.ndarray:
    """``[Â2 Â1]`` of shape ``(Nx, 2Nx)`` from AC eq 11.8, with a clear error if singular."""
    nx = stats.nx
    G = np.block([[S[2][2], S[2][1]], [S[1][2], S[1][1]]])
    rhs = np.hstack([S[0][2], S[0][1]])
    G = 0.5 * (G + G.T)
    labels = [f"X[{c}] two frames back" for c in range(nx)] + [f"X[{c}] one frame back" for c in range(nx)]
    diag = np.diag(G).copy()
    # A component whose spread is lost in the rounding of its raw second moment never moves.
    raw = np.concatenate([np.diag(stats.Rij(2, 2)), np.diag(stats.Rij(1, 1))])
    flat = np.flatnonzero(diag <= 1e-10 * raw)
    if flat.size:
        comps = sorted({int(c) % nx for c in flat})
        names = ", ".join(f"X[{c}]" for c in comps)
        raise DataError(f"cannot learn dynamics: component(s) {names} never change over the training frames, "
                        "so the normal equations (AC eq 11.8) are singular; drop them from the shape-space "
                        "or train on motion in which they vary")
    d = np.sqrt(diag)
    corr = G / np.outer(d, d)
    vals, vecs = np.linalg.eigh(corr)
    if vals[0] <= NORMAL_EQUATIONS_TOL:
        weights = np.abs(vecs[:, 0])
        involved = [labels[int(k)] for k in np.argsort(-weights)[:4] if weights[k] > 0.1]
        raise DataError("cannot learn dynamics: the lagged shape vectors are linearly dependent "
                        f"(smallest normalised eigenvalue {vals[0]:.2g}), chiefly through "
                        f"{', '.join(involved)}; a component that stays fixed, or moves by a constant step, "
                        "or is a fixed combination of others cannot be learned — drop it from the shape-space "
                        "or add training data in which it moves freely")
    return np.linalg.solve(G, rhs.T).T


def _residual_scatter(S: list[list[np.ndarray]], coef: np.ndarray) -> np.ndarray:
    """``Z = Σ r rᵀ`` for ``[A2 A1] = coef`` with the intercept at its optimum for ``coef``."""
    G = np.block([[S[2][2], S[2][1]], [S[1][2], S[1][1]]])
    cross = np.hstack([S[0][2], S[0][1]])
    Z = S[0][0] - coef @ cross.T - cross @ coef.T + coef @ G @ coef.T
    return 0.5 * (Z + Z.T)


def stabilise(A2: np.ndarray, A1: np.ndarray, limit: float) -> tuple[np.ndarray, np.ndarray, str]:
    """Pull every state-matrix eigenvalue with ``|λ| > limit`` in to ``|λ| = limit``.

    Each offending eigenvalue keeps its argument (so its frequency) and its mode shape;
    the other modes are untouched.  The block-companion form is kept by rebuilding
    ``[A2 A1]`` from the modes: with upper eigenvector halves ``x_m`` and new eigenvalues
    ``λ'_m``, ``[A2 A1] [x_m; λ'_m x_m] = λ'_m² x_m`` for all ``2Nx`` modes.  If the
    eigenvectors are too nearly dependent for that (near-repeated eigenvalues), all
    eigenvalues are scaled by ``s = limit / radius`` instead, via ``A1 → s A1``,
    ``A2 → s² A2``, which keeps every frequency and mode shape and adds
    ``-log(s)/τ`` to every damping rate.
    """
    vals, vecs = np.linalg.eig(state_matrices(A2, A1, np.eye(A1.shape[0]))[0])
    radius = float(np.abs(vals).max())
    if radius <= limit:
        return A2, A1, "no"
    n = A1.shape[0]
    shrunk = np.where(np.abs(vals) > limit, vals * (limit / np.maximum(np.abs(vals), 1e-300)), vals)
    X = vecs[:n]
    V = np.vstack([X, X * shrunk])
    if np.linalg.cond(V) < 1e8:
        coef = np.linalg.solve(V.T, (X * shrunk**2).T).T
        scale = max(1.0, float(np.abs(coef).max()))
        if np.abs(coef.imag).max() <= 1e-9 * scale:
            new2, new1 = coef.real[:, :n], coef.real[:, n:]
            if float(np.abs(np.linalg.eigvals(state_matrices(new2, new1, np.eye(new1.shape[0]))[0])).max()) <= limit * (1 + 1e-9):
                return new2, new1, "modes"
    s = limit / radius
    return s * s * A2, s * A1, "scaled"


def _mean_from_intercept(D: np.ndarray, A2: np.ndarray, A1: np.ndarray,
                         data_mean: np.ndarray) -> tuple[np.ndarray, str, float]:
    """``X̄`` solving ``(I - A2 - A1) X̄ = D``; singular directions take the data mean."""
    M = np.eye(D.size) - A2 - A1
    U, s, Vt = np.linalg.svd(M)
    keep = s > MEAN_SINGULAR_TOL * max(1.0, float(s[0]))
    if keep.all():
        return np.linalg.solve(M, D), "intercept", 0.0
    Ur, Vr = U[:, keep], Vt[keep].T
    V0 = Vt[~keep].T
    mean = Vr @ ((Ur.T @ D) / s[keep]) + V0 @ (V0.T @ data_mean)
    dropped = float(np.linalg.norm(U[:, ~keep].T @ D))
    return mean, "data", dropped


def fit_ar2(data: Any, tau: float, *, mean: Any = None, enforce_stability: bool = False,
            max_spectral_radius: float = 0.99) -> tuple[AR2, LearningReport]:
    """Maximum-likelihood AR(2) dynamics from training sequences (AC Fig 11.6).

    Parameters
    ----------
    data : AR2Statistics, ndarray of shape (M, Nx), or a list of either
        Training data.  Several sequences are pooled by adding their statistics.  A 1-D
        array of shape (M,) is a one-dimensional signal (``Nx = 1``).
    tau : float
        Frame interval of the training clips, seconds.
    mean : ndarray of shape (Nx,), optional
        A known mean ``X̄``.  Then only ``Â2, Â1, Ĉ`` are estimated, from sums about that
        mean (with ``Nx = 1`` and ``mean = 0`` this is AC Fig 11.2).
    enforce_stability : bool
        If the fit has state-matrix eigenvalues with ``|λ| > max_spectral_radius``, pull
        just those in to ``|λ| = max_spectral_radius``, keeping their frequencies and mode
        shapes (when the eigenvectors are too close to dependent to do that, scale every
        eigenvalue by the same factor instead; the report says which).  ``D̂`` and ``Ĉ``
        are then re-estimated for the new ``A2, A1`` (their conditional maximum-likelihood
        values), and ``X̄`` is recomputed.
    max_spectral_radius : float
        The limit used by ``enforce_stability``, in ``(0, 1)``.

    Returns
    -------
    model : AR2
        ``A2, A1`` as fitted, ``B0 = √Ĉ`` (symmetric square root, tiny negative eigenvalues
        clipped to 0), ``mean = X̄``, ``tau``.
    report : LearningReport

    Notes
    -----
    ``X̄ = (I - Â2 - Â1)⁻¹ D̂`` is undefined when ``I - Â2 - Â1`` is singular (a random
    walk or constant velocity: ``A1 + A2 = I`` along some direction).  Along the
    directions whose singular values fall below ``MEAN_SINGULAR_TOL`` the mean is taken
    from the data (the average of the shapes in the fit) and the component of ``D̂``
    there — a constant drift that the mean form of the model cannot express — is
    dropped; its size is reported as ``dropped_drift``, and ``Ĉ`` grows by its outer
    product, since the returned model explains that drift as driving noise.  Other
    directions keep the maximum-likelihood value.  A fit that is merely close to a
    random walk keeps ``X̄ = (I - Â2 - Â1)⁻¹ D̂`` even if that lies far from the data:
    the model's one-step predictions near the data are unaffected.

    Raises
    ------
    DataError
        Too few frame triples (there must be more than ``2 Nx + 1``: the unknowns of one
        row of ``[A2 A1 D]``), a singular system (e.g. a component that never moves),
        or non-finite input.
    """
    stats = _collect(data)
    nx, n = stats.nx, stats.count
    tau = float(tau)
    if not (math.isfinite(tau) and tau > 0):
        raise DataError(f"tau (frame interval) must be a positive number of seconds, got {tau}")
    limit = float(max_spectral_radius)
    if not 0 < limit < 1:
        raise DataError(f"max_spectral_radius must lie strictly between 0 and 1, got {max_spectral_radius}")
    known_mean = None
    if mean is not None:
        known_mean = np.asarray(mean, dtype=float)
        if known_mean.shape != (nx,) or not np.all(np.isfinite(known_mean)):
            raise DataError(f"mean must be a finite vector of length {nx}, got shape {known_mean.shape}")
    unknowns = 2 * nx + (0 if known_mean is not None else 1)
    if n <= unknowns:
        raise DataError(f"too few frames to learn {nx}-dimensional AR(2) dynamics: the number of frame triples "
                        f"(X_k-2, X_k-1, X_k) must exceed 2·Nx{'' if known_mean is not None else '+1'} = {unknowns}, "
                        f"got {n} from {stats.n_sequences} sequence(s) of {stats.n_frames} frames in all "
                        f"(each sequence of M frames gives M - 2)")

    S = _centred_products(stats, known_mean)
    coef = _solve_normal_equations(S, stats)
    A2, A1 = coef[:, :nx], coef[:, nx:]
    free_radius = float(np.abs(np.linalg.eigvals(state_matrices(A2, A1, np.eye(A1.shape[0]))[0])).max())
    stabilised = "no"
    if enforce_stability:
        A2, A1, stabilised = stabilise(A2, A1, limit)
        coef = np.hstack([A2, A1])

    C = _residual_scatter(S, coef) / n
    if known_mean is not None:
        D = (np.eye(nx) - A2 - A1) @ known_mean
        X_bar, source, dropped = known_mean, "given", 0.0
    else:
        D = (stats.R(0) - A2 @ stats.R(2) - A1 @ stats.R(1)) / n
        X_bar, source, dropped = _mean_from_intercept(D, A2, A1, stats.R(0) / n)
        if source == "data":
            # The model's own intercept; the drift it cannot express becomes part of the noise.
            drift = D - (np.eye(nx) - A2 - A1) @ X_bar
            D = D - drift
            C = C + np.outer(drift, drift)
    B0 = symmetric_sqrt(C)
    model = AR2(A2, A1, B0, X_bar, tau)

    sign, logdet = np.linalg.slogdet(C)
    log_likelihood = math.inf if sign <= 0 else -0.5 * n * (nx * math.log(2 * math.pi) + logdet + nx)
    radius = model.spectral_radius()
    report = LearningReport(
        n_sequences=stats.n_sequences, n_frames=stats.n_frames, n_triples=n,
        spectral_radius=radius, stable=radius < 1.0, unconstrained_spectral_radius=free_radius,
        stabilised=stabilised, mean_source=source, dropped_drift=dropped, intercept=D,
        log_likelihood=float(log_likelihood), residual_rms=math.sqrt(max(float(np.trace(C)), 0.0) / nx),
    )
    return model, report
