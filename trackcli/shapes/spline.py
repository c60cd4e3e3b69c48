"""B-spline curves: basis functions, batched evaluation, normals and the L2 metric.

A curve is ``r(s) = U(s) Q`` with ``U(s) = diag(B(s)ᵀ, B(s)ᵀ)`` and ``Q = (Qx; Qy)`` the
``2 Nq`` stacked control coordinates (AC ch 3, restated in SPEC §2).  Knots are uniform,
one per unit of the parameter ``s``:

- **closed** (periodic) curves have ``L = Nq`` spans and ``s`` wraps modulo ``L``;
- **open** curves are clamped (end knots repeated ``degree + 1`` times) so that
  ``r(0)`` and ``r(L)`` are the first and last control points; ``L = Nq - degree``.

In both cases the span ``[i, i + 1)`` is shaped by control points ``i, ..., i + degree``
(indices modulo ``Nq`` when closed).  "Order" in the book is ``degree + 1``; quadratic
(degree 2) is the default.

The metric matrix ``𝓑 = (1/L) ∫₀ᴸ B(s) B(s)ᵀ ds`` gives the mean-square distance between
two curves along the parameter, ``(1/L) ∫ |r₁(s) − r₂(s)|² ds = (Q₁ − Q₂)ᵀ 𝒰 (Q₁ − Q₂)`` with
``𝒰 = diag(𝓑, 𝓑)`` (AC eqs 8.5–8.6).  All integrals here are piecewise polynomial and are
computed exactly by Gauss–Legendre quadrature with ``2·degree + 1`` nodes per span.

Coordinates are image ``(x, y)`` with ``y`` pointing down (see :mod:`trackcli`).

Normals (:meth:`CurveSampler.normals`) are unit vectors.  For a closed curve they point
*outward* whatever the direction in which the control polygon runs; the decision uses the
exact signed area of the curve.  For an open curve they point to the left of the direction
of increasing ``s`` as seen on the screen (with ``y`` down): a curve running left to right
has normals pointing up, towards smaller ``y``.  Formally ``n = (t_y, −t_x) / |t|`` for the
tangent ``t = dr/ds``.

The basis and the curve sampler share the span and knot arithmetic, so they live together;
the least-squares fit of a curve to points, which only evaluates the basis, is
:mod:`trackcli.shapes.fit`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit

from trackcli.errors import ConfigError, DataError

__all__ = [
    "SplineBasis",
    "CurveSampler",
    "polygon_area_centroid",
    "curve_area_centroid",
    "curve_centre",
    "signed_area",
    "dense_polygon",
]


def _reciprocal(width: np.ndarray) -> np.ndarray:
    """``1 / width``, 0 where the width is 0 (repeated knots)."""
    return np.divide(1.0, width, out=np.zeros_like(width), where=width > 0)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class SplineBasis:
    """Uniform B-spline basis of ``n_ctrl`` functions on ``s ∈ [0, L]``.

    Parameters
    ----------
    n_ctrl : int
        Number of control points ``Nq``.  At least ``degree + 1``.
    degree : int, default 2
        Polynomial degree (the book's order minus one), at least 1.
    closed : bool, default True
        Periodic (closed) curve if true, clamped open curve otherwise.

    Attributes
    ----------
    L : int
        Parameter length: ``Nq`` spans when closed, ``Nq - degree`` when open.
    metric : ndarray of shape (Nq, Nq)
        The metric matrix ``𝓑``.
    U : ndarray of shape (2 Nq, 2 Nq)
        ``diag(𝓑, 𝓑)``, the L2 metric on stacked control vectors.
    """

    n_ctrl: int
    degree: int = 2
    closed: bool = True

    def __post_init__(self) -> None:
        for name in ("n_ctrl", "degree"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ConfigError(f"spline {name} must be an integer, got {value!r}")
            object.__setattr__(self, name, int(value))
        if not isinstance(self.closed, (bool, np.bool_)):
            raise ConfigError(f"spline closed must be true or false, got {self.closed!r}")
        object.__setattr__(self, "closed", bool(self.closed))
        if self.degree < 1:
            raise ConfigError(f"spline degree must be at least 1, got {self.degree}")
        if self.n_ctrl < self.degree + 1:
            raise ConfigError(
                f"a degree-{self.degree} spline needs at least {self.degree + 1} control "
                f"points, got n_ctrl={self.n_ctrl}"
            )

    # ----------------------------------------------------------------- geometry of s
    @property
    def L(self) -> int:
        """Length of the parameter range (number of spans)."""
        return self.n_ctrl if self.closed else self.n_ctrl - self.degree

    @property
    def Nq(self) -> int:
        """Number of control points (alias of ``n_ctrl``)."""
        return self.n_ctrl

    def measurement_params(self, M: int) -> np.ndarray:
        """``M`` parameter values equally spaced along the curve.

        Closed curves: ``s_i = i L / M``.  Open curves: the centres of ``M`` equal
        parameter intervals, ``s_i = (i + ½) L / M``, so the two ends are treated alike.

        Returns
        -------
        s : ndarray of shape (M,)
        """
        if isinstance(M, bool) or not isinstance(M, (int, np.integer)) or M < 1:
            raise ConfigError(f"number of measurement points must be a positive integer, got {M!r}")
        i = np.arange(M, dtype=float)
        if self.closed:
            return i * (self.L / M)
        return (i + 0.5) * (self.L / M)

    def _wrap(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        if not np.all(np.isfinite(s)):
            raise DataError("spline parameter values must be finite")
        L = self.L
        if self.closed:
            s = np.mod(s, L)
            return np.where(s >= L, 0.0, s)  # np.mod(-1e-18, L) == L
        tol = 1e-9 * L
        if s.size and (s.min() < -tol or s.max() > L + tol):
            raise DataError(
                f"open-spline parameter out of range: got values in "
                f"[{s.min():g}, {s.max():g}], valid range is [0, {L}]"
            )
        return np.clip(s, 0.0, L)

    # ---------------------------------------------------------------- basis functions
    @cached_property
    def _knots(self) -> tuple[np.ndarray, np.ndarray]:
        """The knot vector and the map from its B-splines to the control points (columns)."""
        d, N = self.degree, self.n_ctrl
        if self.closed:  # N + d B-splines on uniform knots, the last d wrapping onto the first
            knots = np.arange(-d, N + d + 1, dtype=float)
            fold = np.zeros((N + d, N))
            fold[np.arange(N + d), np.arange(N + d) % N] = 1.0
        else:  # clamped: end knots repeated d + 1 times
            L = self.L
            knots = np.concatenate([np.zeros(d), np.arange(L + 1, dtype=float), np.full(d, float(L))])
            fold = np.eye(N)
        return knots, fold

    def _bsplines(self, x: np.ndarray, nu: int) -> np.ndarray:
        """``dᵛ/dxᵛ`` of every B-spline of the knot vector at ``x`` (K,): shape (K, n).

        Cox–de Boor: the degree-0 B-spline of ``x``'s span is 1 (the span of ``x``; the
        last non-empty one at the right end), and ``B_{i,k} = ω_{i,k} B_{i,k-1} +
        (1 - ω_{i+1,k}) B_{i+1,k-1}`` with ``ω_{i,k} = (x - t_i) / (t_{i+k} - t_i)``; the
        derivative ``B'_{i,k} = k (B_{i,k-1} / (t_{i+k} - t_i) - B_{i+1,k-1} / (t_{i+k+1} -
        t_{i+1}))`` is applied for the last ``nu`` degrees (0/0 = 0 throughout).
        """
        t = self._knots[0]
        d = self.degree
        n_all = t.size - 1  # degree-0 B-splines, one per knot interval
        span = np.clip(np.searchsorted(t, x, side="right") - 1, d, n_all - d - 1)
        b = np.zeros((x.size, n_all))
        b[np.arange(x.size), span] = 1.0
        for k in range(1, d + 1):
            n_k = n_all - k
            inv = _reciprocal(t[k : k + n_k] - t[:n_k])  # 1 / (t_{i+k} - t_i)
            inv1 = _reciprocal(t[k + 1 : k + 1 + n_k] - t[1 : 1 + n_k])  # 1 / (t_{i+k+1} - t_{i+1})
            if k > d - nu:  # the last nu degrees: derivatives
                b = k * (b[:, :n_k] * inv - b[:, 1 : n_k + 1] * inv1)
            else:
                b = (x[:, None] - t[:n_k]) * inv * b[:, :n_k] + (t[k + 1 : k + 1 + n_k] - x[:, None]) * inv1 * b[:, 1:]
        return b

    def basis(self, s) -> np.ndarray:
        """Basis values ``B(s)ᵀ``.

        Parameters
        ----------
        s : array_like of shape (M,)
            Parameter values.  Wrapped modulo ``L`` when closed; must lie in ``[0, L]``
            when open.

        Returns
        -------
        ndarray of shape (M, Nq)
            Row ``m`` holds ``B(s_m)ᵀ``; rows sum to one.
        """
        return self.basis_derivative(s, 0)

    def basis_derivative(self, s, nu: int = 1) -> np.ndarray:
        """Derivatives ``dᵛB(s)ᵀ/dsᵛ`` of the basis, shape ``s.shape + (Nq,)``.

        ``nu`` may be 0 (the basis itself) up to ``degree``.
        """
        valid = isinstance(nu, (int, np.integer)) and not isinstance(nu, bool)
        if not valid or not 0 <= nu <= self.degree:
            raise ConfigError(
                f"derivative order must be an integer in [0, {self.degree}], got {nu!r}"
            )
        s = self._wrap(s)
        out = self._bsplines(s.ravel(), nu) @ self._knots[1]
        return out.reshape(s.shape + (self.n_ctrl,))

    # ------------------------------------------------------------- exact integrals
    @cached_property
    def _quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        """Gauss–Legendre nodes and weights on every span: exact for degree ≤ 4·degree+1."""
        x, w = np.polynomial.legendre.leggauss(2 * self.degree + 1)
        starts = np.arange(self.L, dtype=float)[:, None]
        nodes = (starts + 0.5 * (x + 1.0)[None, :]).ravel()
        weights = np.tile(0.5 * w, self.L)
        return _readonly(nodes), _readonly(weights)

    @cached_property
    def metric(self) -> np.ndarray:
        """Metric matrix ``𝓑 = (1/L) ∫ B Bᵀ ds``, shape (Nq, Nq), symmetric positive definite."""
        s, w = self._quadrature
        B = self.basis(s)
        return _readonly((B.T * w) @ B / self.L)

    @cached_property
    def U(self) -> np.ndarray:
        """``𝒰 = diag(𝓑, 𝓑)``, shape (2 Nq, 2 Nq)."""
        N = self.n_ctrl
        out = np.zeros((2 * N, 2 * N))
        out[:N, :N] = self.metric
        out[N:, N:] = self.metric
        return _readonly(out)

    @cached_property
    def mean_weights(self) -> np.ndarray:
        """``(1/L) ∫ B(s) ds``, shape (Nq,): the parameter-mean of a curve is ``wᵀQx, wᵀQy``."""
        s, w = self._quadrature
        return _readonly(w @ self.basis(s) / self.L)

    @cached_property
    def area_matrix(self) -> np.ndarray:
        """Antisymmetric ``K`` with signed area ``A = ½ Qxᵀ K Qy`` (closed curves), shape (Nq, Nq).

        ``K = G − Gᵀ`` with ``G = ∫ B(s) B'(s)ᵀ ds``, from ``A = ½ ∮ (x y' − y x') ds``.
        """
        s, w = self._quadrature
        G = (self.basis(s).T * w) @ self.basis_derivative(s, 1)
        return _readonly(G - G.T)

    def _dense_sampler(self, n: int) -> CurveSampler:
        """The sampler of :func:`dense_polygon` with ``n`` points, made once per ``n`` (it is
        drawn for every frame's outline)."""
        made = self.__dict__.setdefault("_dense_samplers", {})
        if n not in made:
            s = np.arange(n) * (self.L / n) if self.closed else np.linspace(0.0, self.L, n)
            made[n] = CurveSampler(self, s)
        return made[n]

    @cached_property
    def _quadrature_basis(self) -> tuple[np.ndarray, np.ndarray]:
        """The basis and its derivative at the nodes of :attr:`_quadrature`."""
        s, _ = self._quadrature
        return _readonly(self.basis(s)), _readonly(self.basis_derivative(s, 1))

    def sampler(self, s) -> CurveSampler:
        """A :class:`CurveSampler` at parameters ``s`` (shape (M,))."""
        return CurveSampler(self, s)


def _split(Q, Nq: int) -> tuple[np.ndarray, np.ndarray]:
    Q = np.asarray(Q, dtype=float)
    if Q.ndim < 1 or Q.shape[-1] != 2 * Nq:
        raise DataError(
            f"control vectors must have last dimension 2*Nq = {2 * Nq}, got shape {Q.shape}"
        )
    return Q[..., :Nq], Q[..., Nq:]


def signed_area(Q, basis: SplineBasis) -> np.ndarray:
    """Exact signed area enclosed by closed spline curves.

    Positive when the curve turns from +x towards +y (clockwise on the screen, since
    ``y`` points down).  For an open curve the value is ``½ ∫ (x y' − y x') ds`` along
    the curve alone, without the closing chord.

    Parameters
    ----------
    Q : array_like of shape (..., 2 Nq)

    Returns
    -------
    ndarray of shape (...)
    """
    Qx, Qy = _split(Q, basis.n_ctrl)
    return 0.5 * np.sum((Qx @ basis.area_matrix) * Qy, axis=-1)


@dataclass(frozen=True, eq=False)
class CurveSampler:
    """Precomputed basis matrices for evaluating many curves at fixed parameters.

    Evaluation is a pair of matrix products, batched over any leading axes of ``Q``; this
    is what the particle filter calls for thousands of curves per frame.

    Parameters
    ----------
    basis : SplineBasis
    s : array_like of shape (M,)
        Parameter values (wrapped when closed).

    Attributes
    ----------
    B : ndarray of shape (M, Nq)
        ``B(s_i)ᵀ`` row by row.
    dB : ndarray of shape (M, Nq)
        ``B'(s_i)ᵀ`` row by row.
    """

    basis: SplineBasis
    s: np.ndarray
    B: np.ndarray = field(init=False, repr=False)
    dB: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.basis, SplineBasis):
            raise ConfigError(f"CurveSampler needs a SplineBasis, got {type(self.basis).__name__}")
        s = np.array(self.s, dtype=float)
        if s.ndim != 1 or s.size == 0:
            raise DataError(
                f"sampler parameters must be a non-empty 1-D array, got shape {s.shape}"
            )
        object.__setattr__(self, "s", _readonly(s))
        object.__setattr__(self, "B", _readonly(self.basis.basis(s)))
        object.__setattr__(self, "dB", _readonly(self.basis.basis_derivative(s, 1)))

    @property
    def M(self) -> int:
        """Number of sample points."""
        return self.s.size

    @cached_property
    def _Bt(self) -> np.ndarray:
        return np.ascontiguousarray(self.B.T)

    @cached_property
    def _dBt(self) -> np.ndarray:
        return np.ascontiguousarray(self.dB.T)

    def points(self, Q) -> np.ndarray:
        """Curve points ``r(s_i)``: ``Q`` (..., 2 Nq) → (..., M, 2)."""
        Qx, Qy = _split(Q, self.basis.n_ctrl)
        return np.stack((Qx @ self.B.T, Qy @ self.B.T), axis=-1)

    def tangents(self, Q) -> np.ndarray:
        """Unnormalised tangents ``dr/ds`` at ``s_i``: (..., 2 Nq) → (..., M, 2)."""
        Qx, Qy = _split(Q, self.basis.n_ctrl)
        return np.stack((Qx @ self.dB.T, Qy @ self.dB.T), axis=-1)

    def normals(self, Q) -> np.ndarray:
        """Unit normals at ``s_i``: (..., 2 Nq) → (..., M, 2).

        Outward for closed curves, to the left of the direction of travel (on screen) for
        open curves; see the module docstring.  Where the tangent vanishes (coincident
        control points) the normal is the zero vector.
        """
        Qx, Qy = _split(Q, self.basis.n_ctrl)
        tx = Qx @ self.dB.T
        ty = Qy @ self.dB.T
        norm = np.hypot(tx, ty)
        inv = np.divide(1.0, norm, out=np.zeros_like(norm), where=norm > 0)
        if self.basis.closed:
            area = 0.5 * np.sum((Qx @ self.basis.area_matrix) * Qy, axis=-1)
            inv = inv * np.where(area >= 0, 1.0, -1.0)[..., None]
        return np.stack((ty * inv, -tx * inv), axis=-1)

    def points_normals(self, Q) -> tuple[np.ndarray, np.ndarray]:
        """``(points(Q), normals(Q))``, each of shape (..., M, 2).

        Computed by a compiled loop that releases the GIL (:func:`_points_normals`): the
        particle filter calls it for every block of samples in its scoring threads, where
        the dozen numpy passes of :meth:`points` and :meth:`normals` would hold the GIL.
        """
        Q = np.asarray(Q, dtype=float)
        _split(Q, self.basis.n_ctrl)  # checks the last dimension
        lead = Q.shape[:-1]
        flat = np.ascontiguousarray(Q.reshape(-1, 2 * self.basis.n_ctrl))
        pts = np.empty((flat.shape[0], self.M, 2))
        nrm = np.empty((flat.shape[0], self.M, 2))
        area = self.basis.area_matrix if self.basis.closed else np.zeros((0, 0))
        _points_normals(flat, self._Bt, self._dBt, area, pts, nrm)
        return pts.reshape(lead + (self.M, 2)), nrm.reshape(lead + (self.M, 2))


@njit(cache=True, nogil=True)
def _points_normals(Q, Bt, dBt, area, pts, nrm):  # pragma: no cover - compiled
    """:meth:`CurveSampler.points` and :meth:`CurveSampler.normals` of K curves, into ``pts``
    and ``nrm`` (K, M, 2); ``Bt`` and ``dBt`` are the basis matrices transposed, (Nq, M);
    ``area`` is the closed basis's area matrix, (0, 0) when open."""
    n, m_pts = Bt.shape
    px = np.empty(m_pts)
    py = np.empty(m_pts)
    tx = np.empty(m_pts)
    ty = np.empty(m_pts)
    row = np.empty(n)
    for k in range(Q.shape[0]):
        sign = 1.0
        if area.shape[0]:  # closed: outward normals, whichever way the curve runs
            row[:] = 0.0
            for j in range(n):  # Qxᵀ K, a row at a time
                qx = Q[k, j]
                for i in range(n):
                    row[i] += qx * area[j, i]
            a = 0.0
            for i in range(n):
                a += row[i] * Q[k, n + i]
            sign = 1.0 if 0.5 * a >= 0.0 else -1.0
        px[:] = 0.0
        py[:] = 0.0
        tx[:] = 0.0
        ty[:] = 0.0
        for j in range(n):  # one control point at a time: independent sums over the points
            qx = Q[k, j]
            qy = Q[k, n + j]
            for m in range(m_pts):
                px[m] += qx * Bt[j, m]
                py[m] += qy * Bt[j, m]
                tx[m] += qx * dBt[j, m]
                ty[m] += qy * dBt[j, m]
        for m in range(m_pts):
            norm = math.sqrt(tx[m] * tx[m] + ty[m] * ty[m])  # no overflow at image coordinates
            inv = (1.0 / norm if norm > 0.0 else 0.0) * sign
            pts[k, m, 0] = px[m]
            pts[k, m, 1] = py[m]
            nrm[k, m, 0] = ty[m] * inv
            nrm[k, m, 1] = -tx[m] * inv


def dense_polygon(Q, basis: SplineBasis, n: int | None = None) -> np.ndarray:
    """Points densely along curves, for drawing and masks.

    Parameters
    ----------
    Q : array_like of shape (..., 2 Nq)
    basis : SplineBasis
    n : int, optional
        Number of points; default ``max(64, 16 L)``.  Closed curves get ``n`` points at
        ``s = i L / n`` (the first point is not repeated at the end); open curves get ``n``
        points from ``s = 0`` to ``s = L`` inclusive.

    Returns
    -------
    ndarray of shape (..., n, 2)
    """
    if n is None:
        n = max(64, 16 * basis.L)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ConfigError(f"dense polygon needs an integer n >= 2, got {n!r}")
    return basis._dense_sampler(int(n)).points(Q)


def polygon_area_centroid(points) -> tuple[np.ndarray, np.ndarray]:
    """Signed area and area centroid of closed polygons (shoelace formula).

    Parameters
    ----------
    points : array_like of shape (..., P, 2)
        Vertices in order; the polygon closes from the last back to the first.

    Returns
    -------
    area : ndarray of shape (...)
        Signed area, positive when the vertices turn from +x towards +y.
    centroid : ndarray of shape (..., 2)
        Area centroid; the vertex mean where the area is zero (degenerate polygons).
    """
    p = np.asarray(points, dtype=float)
    if p.ndim < 2 or p.shape[-1] != 2 or p.shape[-2] < 1:
        raise DataError(f"polygon points must have shape (..., P, 2), got {p.shape}")
    x, y = p[..., 0], p[..., 1]
    # Subtract the vertex mean first: same result, far less cancellation.
    mean = p.mean(axis=-2)
    x = x - mean[..., None, 0]
    y = y - mean[..., None, 1]
    xn, yn = np.roll(x, -1, axis=-1), np.roll(y, -1, axis=-1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum(axis=-1)
    cx = ((x + xn) * cross).sum(axis=-1)
    cy = ((y + yn) * cross).sum(axis=-1)
    size2 = np.max(x * x + y * y, axis=-1)
    ok = np.abs(area) > 1e-12 * np.maximum(size2, 1e-300)
    denom = np.where(ok, 6.0 * area, 1.0)
    centroid = np.stack(
        (np.where(ok, cx / denom, 0.0), np.where(ok, cy / denom, 0.0)), axis=-1
    ) + mean
    return area, centroid


def curve_area_centroid(Q, basis: SplineBasis) -> tuple[np.ndarray, np.ndarray]:
    """Exact signed area and area centroid of closed spline curves.

    Uses ``A = ½ ∮ (x y' − y x') ds`` and ``c = (1 / 3A) ∮ r (x y' − y x') ds`` (Green's
    theorem), integrated exactly span by span.  Where the area vanishes the centroid falls
    back to the parameter-mean of the curve (:func:`curve_centre` of an open curve).

    Parameters
    ----------
    Q : array_like of shape (..., 2 Nq)

    Returns
    -------
    area : ndarray of shape (...)
    centroid : ndarray of shape (..., 2)
    """
    Qx, Qy = _split(Q, basis.n_ctrl)
    s, w = basis._quadrature
    B, dB = basis._quadrature_basis
    mx = Qx @ basis.mean_weights
    my = Qy @ basis.mean_weights
    x = Qx @ B.T - mx[..., None]
    y = Qy @ B.T - my[..., None]
    cross = x * (Qy @ dB.T) - y * (Qx @ dB.T)
    area = 0.5 * (cross @ w)
    size2 = np.max(x**2 + y**2, axis=-1)
    ok = np.abs(area) > 1e-12 * np.maximum(size2, 1e-300)
    denom = np.where(ok, 3.0 * area, 1.0)
    cx = np.where(ok, ((x * cross) @ w) / denom, 0.0) + mx
    cy = np.where(ok, ((y * cross) @ w) / denom, 0.0) + my
    return area, np.stack((cx, cy), axis=-1)


def curve_centre(Q, basis: SplineBasis) -> np.ndarray:
    """A natural anchor point of each curve, shape (..., 2).

    Closed curves: the exact area centroid (:func:`curve_area_centroid`).  Open curves:
    the parameter-mean ``(1/L) ∫ r(s) ds``.  Both move with the curve under any affine map,
    so a shape-space built about this point rotates and scales the object about itself.
    """
    if basis.closed:
        return curve_area_centroid(Q, basis)[1]
    Qx, Qy = _split(Q, basis.n_ctrl)
    return np.stack((Qx @ basis.mean_weights, Qy @ basis.mean_weights), axis=-1)
