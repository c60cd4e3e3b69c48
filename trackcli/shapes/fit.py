"""Least-squares fit of a B-spline curve to an ordered list of points (:func:`fit`).

The curve is that of :mod:`trackcli.shapes.spline`, ``r(s) = U(s) Q``; the fit starts from
the chord-length parametrisation and refines control points and parameters together by
Gauss–Newton steps on the point-to-curve distances, optionally refusing steps that fold the
curve or throw out loops (``strict``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from trackcli.errors import ConfigError, DataError
from trackcli.shapes.spline import SplineBasis

__all__ = ["fit"]


def _second_difference(n: int, closed: bool) -> np.ndarray:
    if closed:
        D = -2.0 * np.eye(n) + np.roll(np.eye(n), 1, axis=1) + np.roll(np.eye(n), -1, axis=1)
        return D
    if n < 3:
        return np.zeros((0, n))
    D = np.zeros((n - 2, n))
    i = np.arange(n - 2)
    D[i, i] = 1.0
    D[i, i + 1] = -2.0
    D[i, i + 2] = 1.0
    return D


def fit(
    points,
    n_ctrl: int,
    *,
    degree: int = 2,
    closed: bool = True,
    refine: int = 10,
    smoothing: float = 1e-9,
    strict: bool = False,
) -> np.ndarray:
    """Least-squares B-spline through an ordered list of points.

    The points are first parametrised by chord length (for a closed curve the chord from
    the last point back to the first is included, and a last point equal to the first is
    dropped) and the control points solve the linear least-squares problem
    ``min Σ_p |U(s_p) Q − p|² + λ |D Q|²``.  ``D`` takes second differences of the control
    polygon and ``λ = smoothing · tr(AᵀA) / 2Nq`` is tiny by default: it only keeps the
    problem well posed when some span holds no data.

    Up to ``refine`` Gauss–Newton iterations then minimise the true point-to-curve
    distances, control points and parameters together: each ``s_p`` moves to the foot of
    the perpendicular from its point, and the control points minimise the distances to the
    tangent lines there (plus a light tangential term, weight 1e-3, for conditioning).  The
    ends of an open curve stay pinned to the first and last points.  Steps are halved until
    the distances improve.  This removes the bias of the chord-length guess, so points
    sampled from a spline give back that spline.

    Those steps only ask that every point lie near the curve, not that the curve stay near
    the points: on an outline with long straight runs or sharp turns later steps can slide
    control points along it until the curve folds back on itself or throws out a loop away
    from every point (12 control points on the pixel outline of an ellipse 17 px wide ended
    30 px off it after ten steps, 0.7 px after none; a fit of the same ellipse's convex hull
    ended with three control points doubling back along its sides).  With ``strict`` a step
    is taken only if it also lowers the two-sided cost (the squared distances from the
    points to the curve plus a term for the curve straying from the points) and adds no
    place where the curve runs against the points' direction (:func:`_curve_terms`);
    otherwise it is halved, and after eight halvings the refinement stops.

    Parameters
    ----------
    points : array_like of shape (P, 2)
        Ordered ``(x, y)`` points along the curve; at least ``n_ctrl`` distinct ones.
    n_ctrl : int
        Number of control points ``Nq``.
    degree : int, default 2
    closed : bool, default True
    refine : int, default 10
        Maximum Gauss–Newton iterations (0 keeps the chord-length fit).
    smoothing : float, default 1e-9
        Relative weight of the second-difference regulariser, ``>= 0``.
    strict : bool, default False
        Refine without folds or loops (above).

    Returns
    -------
    Q : ndarray of shape (2 Nq,)
        Stacked control vector ``(Qx; Qy)``.

    Raises
    ------
    ConfigError
        Invalid ``n_ctrl``, ``degree``, ``refine`` or ``smoothing``.
    DataError
        Points of the wrong shape, non-finite, too few, or all coincident.
    """
    basis = SplineBasis(n_ctrl, degree, closed)
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise DataError(f"points to fit must have shape (P, 2), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise DataError("points to fit contain NaN or infinite values")
    if isinstance(refine, bool) or not isinstance(refine, (int, np.integer)) or refine < 0:
        raise ConfigError(f"refine must be a non-negative integer, got {refine!r}")
    if not np.isfinite(smoothing) or smoothing < 0:
        raise ConfigError(f"smoothing must be a finite number >= 0, got {smoothing!r}")
    if closed and len(p) > 1 and np.array_equal(p[0], p[-1]):
        p = p[:-1]
    n_distinct = len(np.unique(p, axis=0))
    if n_distinct < n_ctrl:
        raise DataError(
            f"fitting {n_ctrl} control points needs at least {n_ctrl} distinct points, "
            f"got {n_distinct}"
        )
    closing = p[:1] if closed else p[-1:]
    chords = np.linalg.norm(np.diff(p, axis=0, append=closing), axis=1)
    total = chords.sum()
    if not total > 0:
        raise DataError("points to fit are all coincident")
    L = basis.L
    cum = np.concatenate([[0.0], np.cumsum(chords)])
    s = L * cum[: len(p)] / total
    if not closed:
        s[-1] = L

    D = _second_difference(n_ctrl, closed)
    N = n_ctrl
    R = np.zeros((2 * len(D), 2 * N))
    R[: len(D), :N] = D
    R[len(D) :, N:] = D

    def solve(A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        AtA = A.T @ A
        lam = smoothing * np.trace(AtA) / (2 * N)
        try:
            return np.linalg.solve(AtA + lam * (R.T @ R), A.T @ rhs)
        except np.linalg.LinAlgError:
            raise DataError(
                "the spline fit is singular: the points leave some control points "
                "undetermined; use fewer control points or smoothing > 0"
            ) from None

    # Chord-length start: an ordinary linear least-squares fit.
    B = basis.basis(s)
    zero = np.zeros_like(B)
    A = np.block([[B, zero], [zero, B]])
    Q = solve(A, np.concatenate([p[:, 0], p[:, 1]]))
    s = _foot_points(basis, Q, p, s)
    cost = _fit_cost(basis, Q, p, s)
    check = strict and refine > 0
    if check:
        curve_terms = _curve_terms(basis, p)
        stray, against = curve_terms(Q)
        cost += stray
    # Gauss–Newton on control points and parameters together.  Eliminating each s_p
    # leaves the distance from p to the tangent line at its foot point; a light
    # tangential term keeps the system well posed.  The ends of an open curve are
    # pinned to the first and last points (s = 0 and s = L) with full residuals.
    wt = np.full(len(p), _TANGENT_WEIGHT)
    if not closed:
        wt[[0, -1]] = 1.0
    for _ in range(refine):
        B = basis.basis(s)
        t = basis.basis_derivative(s, 1) @ np.stack((Q[:N], Q[N:]), axis=1)
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)
        n = np.stack((t[:, 1], -t[:, 0]), axis=1)
        rows, rhs = [], []
        for direction, weight in ((n, 1.0), (t, wt)):
            w = np.broadcast_to(weight, (len(p),))[:, None]
            rows.append(w * np.hstack((direction[:, :1] * B, direction[:, 1:] * B)))
            rhs.append(w[:, 0] * np.sum(direction * p, axis=1))
        step = solve(np.vstack(rows), np.concatenate(rhs)) - Q
        for _ in range(8):  # halve the step until the true distances improve, with no new fold
            Q_new = Q + step
            s_new = _foot_points(basis, Q_new, p, s)
            cost_new = _fit_cost(basis, Q_new, p, s_new)
            if not check:
                if cost_new < cost:
                    break
            else:
                stray, against_new = curve_terms(Q_new)
                cost_new += stray
                if cost_new < cost and against_new <= against:
                    break
            step = 0.5 * step
        else:
            break
        converged = cost - cost_new <= 1e-12 * cost
        Q, s, cost = Q_new, s_new, cost_new
        if check:
            against = against_new
        if converged:
            break
    return Q


def _fit_cost(basis: SplineBasis, Q: np.ndarray, p: np.ndarray, s: np.ndarray) -> float:
    N = basis.n_ctrl
    r = basis.basis(s) @ np.stack((Q[:N], Q[N:]), axis=1) - p
    return float(np.sum(r * r))


_TANGENT_WEIGHT = 1e-3
#: points per span of the curve whose distances to the fitted points' polygon enter a strict fit's cost
_CURVE_SAMPLES = 8


def _curve_terms(basis: SplineBasis, p: np.ndarray) -> Callable[[np.ndarray], tuple[float, int]]:
    """``terms(Q)``: how far the curve ``Q`` strays from the points ``p``, and how often it
    runs against them.

    At :data:`_CURVE_SAMPLES` points per span, spread evenly in parameter, the distance to
    the polygon through ``p`` (closed with the curve) less half the polygon's median side
    (the polygon cuts the curve's bends by up to about that much), squared where positive,
    summed and scaled to ``len(p)`` terms; and the number of those points whose tangent is
    more than 120° from the outline's direction (:func:`_outline_direction`) at the nearest
    side of the polygon: the curve folds back or loops there.  What depends only on the
    basis and the points (the basis matrices, the polygon's sides) is computed once.
    """
    N = basis.n_ctrl
    m = _CURVE_SAMPLES * N
    s = np.linspace(0.0, basis.L, m, endpoint=not basis.closed)
    B, dB = basis.basis(s), basis.basis_derivative(s, 1)
    along = _outline_direction(p, basis.closed)
    a = p if basis.closed else p[:-1]
    d = (np.roll(p, -1, axis=0) if basis.closed else p[1:]) - a
    dd = np.maximum(np.sum(d * d, axis=1), 1e-300)
    slack = 0.5 * float(np.median(np.sqrt(dd)))

    def terms(Q: np.ndarray) -> tuple[float, int]:
        C = np.stack((Q[:N], Q[N:]), axis=1)
        c, tangent = B @ C, dB @ C
        best = np.empty(m)
        side = np.empty(m, dtype=np.intp)
        for i in range(0, m, 64):  # in chunks, to bound the memory
            r = c[i:i + 64, None, :] - a[None, :, :]
            u = np.clip(np.sum(r * d[None], axis=2) / dd[None], 0.0, 1.0)
            e = r - u[:, :, None] * d[None]
            e2 = np.sum(e * e, axis=2)
            side[i:i + 64] = np.argmin(e2, axis=1)
            best[i:i + 64] = e2[np.arange(e2.shape[0]), side[i:i + 64]]
        excess = np.maximum(np.sqrt(best) - slack, 0.0)
        way = along[side]
        against = (np.sum(tangent * way, axis=1)
                   < -0.5 * np.linalg.norm(tangent, axis=1) * np.linalg.norm(way, axis=1))
        return float(np.sum(excess * excess) * len(p) / m), int(np.count_nonzero(against))

    return terms


def _outline_direction(p: np.ndarray, closed: bool) -> np.ndarray:
    """The direction of travel along the ordered points at each point (central chords two
    points either side; one-sided at the ends of an open outline)."""
    if closed and len(p) > 4:
        return np.roll(p, -2, axis=0) - np.roll(p, 2, axis=0)
    idx = np.arange(len(p))
    return p[np.minimum(idx + 2, len(p) - 1)] - p[np.maximum(idx - 2, 0)]


def _foot_points(basis: SplineBasis, Q: np.ndarray, p: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Move each ``s_p`` towards the closest point of the curve to ``p`` (Newton steps)."""
    N = basis.n_ctrl
    C = np.stack((Q[:N], Q[N:]), axis=1)
    L = basis.L
    for _ in range(8):
        r = basis.basis(s) @ C - p
        d1 = basis.basis_derivative(s, 1) @ C
        d2 = basis.basis_derivative(s, 2) @ C if basis.degree >= 2 else np.zeros_like(d1)
        gn = np.sum(d1 * d1, axis=1)
        curv = gn + np.sum(r * d2, axis=1)
        curv = np.where(curv > 0.1 * gn, curv, gn)  # fall back to Gauss–Newton
        grad = np.sum(r * d1, axis=1)
        step = np.divide(grad, curv, out=np.zeros_like(grad), where=curv > 0)
        s = s - np.clip(step, -0.5, 0.5)
        s = np.mod(s, L) if basis.closed else np.clip(s, 0.0, L)
        if basis.closed:
            s = np.where(s >= L, 0.0, s)
        else:
            s[0], s[-1] = 0.0, L
    return s
