"""Making shape-spaces (AC ch 4 and §8.4, SPEC §2): every kind is a
:class:`~trackcli.shapes.space.ShapeSpace` with the same metric and projections.

Constructive spaces
-------------------
:func:`translation`, :func:`similarity` and :func:`affine` on a template, about an anchor
(by default the template curve's area centroid, :func:`trackcli.shapes.spline.curve_centre`);
their columns are given in :mod:`trackcli.shapes.space`.  :func:`keyframes` appends
key-frame columns ``Q_i − Q0`` to a space.

Learned spaces
--------------
:func:`pca` is L2-norm PCA inside a shape-space (AC Figure 8.9); :func:`residual_pca` adds
PCA modes of what a constructive space leaves unexplained (AC eqs 8.26–8.27).  A space's
``kind`` records how it was made: ``"translation"``, ``"similarity"``, ``"affine"``,
``"pca"``, or a constructive kind extended with ``"+keyframes"`` or ``"+pca"``; the first
columns of an extended space are those of its base, so :meth:`ShapeSpace.pose` still
reads them directly.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.shapes.space import ShapeSpace, constructive_columns
from trackcli.shapes.spline import SplineBasis, curve_centre

__all__ = [
    "ShapeSpace",
    "translation",
    "similarity",
    "affine",
    "keyframes",
    "pca",
    "residual_pca",
    "explained_fraction",
]


def _constructive(kind: str, basis: SplineBasis, Q0, origin) -> ShapeSpace:
    if not isinstance(basis, SplineBasis):
        raise ConfigError(f"basis must be a SplineBasis, got {type(basis).__name__}")
    Q0 = np.asarray(Q0, dtype=float)
    if Q0.shape != (2 * basis.n_ctrl,):
        raise DataError(f"template Q0 must have shape ({2 * basis.n_ctrl},), got {Q0.shape}")
    o = curve_centre(Q0, basis) if origin is None else np.asarray(origin, dtype=float)
    if o.shape != (2,):
        raise DataError(f"origin must have shape (2,), got {o.shape}")
    W, names = constructive_columns(kind, basis, Q0, o)
    return ShapeSpace(W, Q0, basis, kind, names, o)


def translation(basis: SplineBasis, Q0, *, origin=None) -> ShapeSpace:
    """Rigid translation, ``Nx = 2``, ``X = (tx, ty)``.

    Parameters
    ----------
    basis : SplineBasis
    Q0 : array_like of shape (2 Nq,)
        Template.
    origin : array_like of shape (2,), optional
        Anchor; default :func:`~trackcli.shapes.spline.curve_centre` of the template.
    """
    return _constructive("translation", basis, Q0, origin)


def similarity(basis: SplineBasis, Q0, *, origin=None) -> ShapeSpace:
    """Euclidean similarity about the anchor, ``Nx = 4``, ``X = (tx, ty, s cosθ − 1, s sinθ)``.

    Arguments as for :func:`translation`.
    """
    return _constructive("similarity", basis, Q0, origin)


def affine(basis: SplineBasis, Q0, *, origin=None) -> ShapeSpace:
    """Planar affine about the anchor, ``Nx = 6``, ``X = (tx, ty, a11 − 1, a22 − 1, a21, a12)``.

    Arguments as for :func:`translation`.
    """
    return _constructive("affine", basis, Q0, origin)


def _extend_kind(kind: str, suffix: str) -> str:
    return kind if kind.endswith("+" + suffix) else f"{kind}+{suffix}"


def _fresh_names(prefix: str, k: int, existing: Sequence[str]) -> tuple[str, ...]:
    taken, out, i = set(existing), [], 1
    while len(out) < k:
        name = f"{prefix}{i}"
        if name not in taken:
            out.append(name)
        i += 1
    return tuple(out)


def keyframes(base: ShapeSpace, frames) -> ShapeSpace:
    """Append key-frame columns ``Q_i − Q0`` to a space (AC §4, SPEC §2).

    ``Q0``, the anchor and the base columns are unchanged, so ``X = 0`` is still the
    template and setting one key-frame coordinate to 1 (others 0) gives that key-frame.
    For key-frames alone, pass ``translation(basis, Q0)`` as the base.

    Parameters
    ----------
    base : ShapeSpace
    frames : array_like of shape (K, 2 Nq)
        Key-frame control vectors, in the same image coordinates as ``base.Q0``.

    Returns
    -------
    ShapeSpace
        ``Nx = base.Nx + K``, kind ``base.kind + "+keyframes"``, new names ``k1, k2, ...``.

    Raises
    ------
    DataError
        A key-frame adds no new direction (it lies in the span of the others).
    """
    F = np.asarray(frames, dtype=float)
    if F.ndim == 1:
        F = F[None, :]
    if F.ndim != 2 or F.shape[1] != 2 * base.Nq or F.shape[0] < 1:
        raise DataError(f"key-frames must have shape (K, {2 * base.Nq}), got {F.shape}")
    W = np.column_stack([base.W, (F - base.Q0).T])
    names = base.names + _fresh_names("k", len(F), base.names)
    kind = _extend_kind(base.kind, "keyframes")
    return ShapeSpace(W, base.Q0, base.basis, kind, names, base.origin)


def _check_k(k, limit: int, what: str) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= limit:
        raise ConfigError(f"number of {what} modes must be an integer in [1, {limit}], got {k!r}")
    return int(k)


def _samples(a, width: int, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] != width:
        raise DataError(f"{what} must have shape (T, {width}), got {a.shape}")
    if a.shape[0] < 2:
        raise DataError(f"PCA needs at least 2 samples, got {a.shape[0]}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"{what} contain NaN or infinite values")
    return a


def _metric_eig(P: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition of ``P G`` for symmetric ``P ≥ 0`` and ``G > 0``.

    With ``G = C Cᵀ`` (Cholesky), ``Cᵀ P C`` is symmetric with the same eigenvalues, and
    its orthonormal eigenvectors ``u`` give ``v = C⁻ᵀ u`` with ``vᵢᵀ G vⱼ = δᵢⱼ``.  Returns
    eigenvalues in descending order (clipped at 0) and the matching ``v`` as columns,
    signed so that the largest component of each ``u`` is positive.
    """
    from scipy.linalg import solve_triangular  # imported here, not at start-up: it takes a tenth of a second

    C = np.linalg.cholesky(G)
    lam, u = np.linalg.eigh(C.T @ P @ C)
    lam, u = lam[::-1], u[:, ::-1]
    big = np.argmax(np.abs(u), axis=0)
    u = u * np.sign(u[big, np.arange(u.shape[1])])
    v = solve_triangular(C.T, u, lower=False)
    return np.clip(lam, 0.0, None), v


def pca(space: ShapeSpace, X_samples, k: int) -> tuple[ShapeSpace, np.ndarray]:
    """L2-norm PCA inside a shape-space (AC Figure 8.9).

    With the sample mean ``X̄`` and covariance ``P = (1/T) Σ (X_t − X̄)(X_t − X̄)ᵀ``, the
    eigenvectors ``v_i`` of ``P H`` in descending order of eigenvalue give
    ``W' = W (v_1 … v_k)`` and ``Q0' = W X̄ + Q0``.  The ``v_i`` are scaled so that
    ``v_iᵀ H v_j = δ_ij``: the new ``H'`` is the identity, and a new coordinate measures
    root-mean-square displacement along the curve, in pixels.

    Parameters
    ----------
    space : ShapeSpace
    X_samples : array_like of shape (T, Nx)
        Training shapes in ``space``, ``T >= 2``.
    k : int
        Number of modes kept, ``1 <= k <= Nx``.

    Returns
    -------
    ShapeSpace
        Kind ``"pca"``, names ``pc1 … pck``, anchor at the centre of the mean shape.
    explained : ndarray of shape (k,)
        Fraction of the total L2 variance ``tr(P H)`` carried by each mode; over all
        ``Nx`` modes the fractions sum to 1.

    Raises
    ------
    DataError
        Fewer than 2 samples, wrong shape, or no variation at all.
    """
    X = _samples(X_samples, space.Nx, "shape samples")
    k = _check_k(k, space.Nx, "PCA")
    mean = X.mean(axis=0)
    D = X - mean
    P = D.T @ D / len(X)
    lam, V = _metric_eig(P, space.H)
    total = lam.sum()
    if not total > 0:
        raise DataError("the shape samples do not vary: PCA has nothing to explain")
    W = space.W @ V[:, :k]
    Q0 = space.to_control(mean)
    out = ShapeSpace(
        W, Q0, space.basis, "pca", _fresh_names("pc", k, ()), curve_centre(Q0, space.basis)
    )
    return out, lam[:k] / total


def residual_pca(base: ShapeSpace, Q_samples, k: int) -> tuple[ShapeSpace, np.ndarray]:
    """Extend a constructive space with PCA modes of its residual (AC eqs 8.26–8.27).

    Each training curve is projected onto ``base`` (L2); the residuals
    ``R_t = Q_t − (W_c X_t + Q0_c)`` are 𝒰-orthogonal to the base columns.  With their mean
    ``R̄`` and covariance ``Pʳ``, the eigenvectors of ``Pʳ 𝒰`` in descending order
    (𝒰-normalised) become the new columns ``W_r``, and the augmented space is
    ``W_a = (W_c | W_r)``, ``Q0_a = Q0_c + R̄``.  Because ``R̄`` and ``W_r`` are 𝒰-orthogonal to
    ``W_c``, ``H_a`` is block diagonal and projecting onto the augmented space gives the
    same base coordinates as projecting onto ``base``; the base part keeps its meaning
    (e.g. pose), and ``X = 0`` is the template plus the mean residual shape.

    Parameters
    ----------
    base : ShapeSpace
    Q_samples : array_like of shape (T, 2 Nq)
        Training curves as control vectors, ``T >= 2``.
    k : int
        Number of residual modes, ``1 <= k <= 2 Nq − Nx``; each must have non-zero variance.

    Returns
    -------
    ShapeSpace
        Kind ``base.kind + "+pca"``, names ``base.names + (r1 … rk)``, anchor of ``base``.
    explained : ndarray of shape (k,)
        Fraction of the *total* L2 variance of the samples, ``tr(P 𝒰)``, carried by each
        residual mode.  The base space carries ``1 − tr(Pʳ 𝒰) / tr(P 𝒰)``; that plus all
        residual fractions sums to 1.

    Raises
    ------
    DataError
        Wrong shape, fewer than 2 samples, or fewer than ``k`` residual directions with
        non-zero variance.
    """
    Q = _samples(Q_samples, 2 * base.Nq, "curve samples")
    k = _check_k(k, 2 * base.Nq - base.Nx, "residual PCA")
    U = base.basis.U
    Dq = Q - Q.mean(axis=0)
    total = np.einsum("ti,ij,tj->", Dq, U, Dq) / len(Q)
    if not total > 0:
        raise DataError("the curve samples do not vary: PCA has nothing to explain")
    R = Q - base.to_control(base.project(Q))
    mean = R.mean(axis=0)
    D = R - mean
    lam, V = _metric_eig(D.T @ D / len(R), U)
    if not lam[k - 1] > 1e-12 * max(lam[0], 1e-300):
        n_ok = int(np.sum(lam > 1e-12 * max(lam[0], 1e-300)))
        raise DataError(
            f"the residual after projecting on the {base.kind} space varies in only {n_ok} "
            f"direction(s); cannot take k={k} residual modes"
        )
    Wr = V[:, :k]
    Wr = Wr - base.W @ (base.pinv @ Wr)  # remove rounding leaks into the base span
    Wr = Wr / np.sqrt(np.einsum("ik,ij,jk->k", Wr, U, Wr))
    mean = mean - base.W @ (base.pinv @ mean)
    out = ShapeSpace(
        np.column_stack([base.W, Wr]),
        base.Q0 + mean,
        base.basis,
        _extend_kind(base.kind, "pca"),
        base.names + _fresh_names("r", k, base.names),
        base.origin,
    )
    return out, lam[:k] / total


def explained_fraction(space: ShapeSpace, Q_samples) -> float:
    """Fraction of the L2 variance of curves about their mean lying in the span of ``W``.

    ``1 − Σ_t ‖(I − W W⁺)(Q_t − Q̄)‖²_𝒰 / Σ_t ‖Q_t − Q̄‖²_𝒰``: 1 when every difference between
    the curves is a combination of the space's columns.

    Parameters
    ----------
    space : ShapeSpace
    Q_samples : array_like of shape (T, 2 Nq)
    """
    Q = _samples(Q_samples, 2 * space.Nq, "curve samples")
    U = space.basis.U
    D = Q - Q.mean(axis=0)
    total = np.einsum("ti,ij,tj->", D, U, D)
    if not total > 0:
        raise DataError("the curve samples do not vary")
    E = D - (D @ space.pinv.T) @ space.W.T
    return float(1.0 - np.einsum("ti,ij,tj->", E, U, E) / total)
