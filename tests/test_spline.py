"""Tests for trackcli.shapes.spline (basis, evaluation, normals, metric) and trackcli.shapes.fit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.errors import ConfigError, DataError
from trackcli.shapes.fit import fit
from trackcli.shapes.spline import (
    CurveSampler,
    SplineBasis,
    curve_area_centroid,
    curve_centre,
    dense_polygon,
    polygon_area_centroid,
    signed_area,
)

FAST = settings(max_examples=40, deadline=None)

bases = st.builds(
    lambda degree, extra, closed: SplineBasis(degree + 1 + extra, degree, closed),
    st.integers(1, 4),
    st.integers(0, 8),
    st.booleans(),
)


def blob(n: int, rng: np.random.Generator, centre=(120.0, 80.0), radius=40.0) -> np.ndarray:
    """Control vector of a star-shaped, non-symmetric closed curve."""
    th = np.arange(n) / n * 2 * np.pi
    r = radius * (1 + 0.15 * rng.standard_normal(n))
    return np.concatenate([centre[0] + r * np.cos(th), centre[1] + 0.7 * r * np.sin(th)])


def ellipse_ctrl(n, a, b, phi, clockwise, centre=(0.0, 0.0)) -> np.ndarray:
    th = np.arange(n) / n * 2 * np.pi
    if clockwise:
        th = -th
    x, y = a * np.cos(th), b * np.sin(th)
    c, s = np.cos(phi), np.sin(phi)
    return np.concatenate([centre[0] + c * x - s * y, centre[1] + s * x + c * y])


# ----------------------------------------------------------------------- basis
@FAST
@given(bases, st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20))
def test_partition_of_unity_and_nonnegative(basis, fractions):
    s = np.array(fractions) * basis.L
    B = basis.basis(s)
    assert B.shape == (len(s), basis.n_ctrl)
    np.testing.assert_allclose(B.sum(axis=1), 1.0, atol=1e-12)
    assert B.min() >= -1e-14
    # at most degree + 1 functions are non-zero anywhere
    assert np.all((np.abs(B) > 1e-14).sum(axis=1) <= basis.degree + 1)
    np.testing.assert_allclose(basis.basis_derivative(s).sum(axis=1), 0.0, atol=1e-10)


@FAST
@given(
    st.integers(1, 4),
    st.integers(0, 6),
    st.lists(st.floats(-30.0, 30.0), min_size=1, max_size=10),
    st.integers(-3, 3),
)
def test_closed_basis_is_periodic(degree, extra, s, shift):
    basis = SplineBasis(degree + 1 + extra, degree, closed=True)
    s = np.array(s)
    np.testing.assert_allclose(basis.basis(s), basis.basis(s + shift * basis.L), atol=1e-10)
    # a degree-1 spline's derivative jumps at the knots (the integers): a knot moved by a
    # period lands on either side of it in floating point, so those points are left out
    smooth = np.abs(s - np.round(s)) > 1e-6 if degree == 1 else np.ones(s.shape, bool)
    np.testing.assert_allclose(
        basis.basis_derivative(s[smooth]), basis.basis_derivative(s[smooth] + shift * basis.L), atol=1e-9
    )


def test_closed_curve_points_repeat_after_one_period():
    rng = np.random.default_rng(0)
    basis = SplineBasis(9)
    Q = blob(9, rng)
    s = rng.uniform(0, basis.L, 25)
    a = CurveSampler(basis, s).points(Q)
    b = CurveSampler(basis, s + basis.L).points(Q)
    np.testing.assert_allclose(a, b, atol=1e-10)


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
@pytest.mark.parametrize("closed", [True, False])
def test_smoothness_across_knots(degree, closed):
    """A degree-d spline is C^(d-1) at the knots."""
    rng = np.random.default_rng(degree)
    basis = SplineBasis(degree + 5, degree, closed)
    Q = rng.normal(size=2 * basis.n_ctrl)
    knots = np.arange(1, basis.L, dtype=float)
    eps = 1e-9
    for nu in range(degree):
        left = basis.basis_derivative(knots - eps, nu) @ Q[: basis.n_ctrl]
        right = basis.basis_derivative(knots + eps, nu) @ Q[: basis.n_ctrl]
        np.testing.assert_allclose(left, right, atol=1e-6)


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
@pytest.mark.parametrize("closed", [True, False])
def test_derivative_matches_finite_difference(degree, closed):
    basis = SplineBasis(degree + 4, degree, closed)
    s = np.linspace(0.05, basis.L - 0.05, 37) + 0.013  # avoid knots
    s = s[s < basis.L - 1e-3]
    h = 1e-6
    fd = (basis.basis(s + h) - basis.basis(s - h)) / (2 * h)
    np.testing.assert_allclose(basis.basis_derivative(s), fd, atol=1e-6)


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
def test_open_curve_interpolates_end_control_points(degree):
    rng = np.random.default_rng(10 + degree)
    basis = SplineBasis(degree + 3, degree, closed=False)
    assert basis.L == 3
    Q = rng.normal(size=2 * basis.n_ctrl) * 50
    N = basis.n_ctrl
    ends = CurveSampler(basis, [0.0, basis.L]).points(Q)
    np.testing.assert_allclose(ends[0], [Q[0], Q[N]], atol=1e-10)
    np.testing.assert_allclose(ends[1], [Q[N - 1], Q[2 * N - 1]], atol=1e-10)
    # and leaves along the first leg of the control polygon
    t0 = CurveSampler(basis, [0.0]).tangents(Q)[0]
    leg = np.array([Q[1] - Q[0], Q[N + 1] - Q[N]])
    assert abs(t0[0] * leg[1] - t0[1] * leg[0]) < 1e-8 * np.linalg.norm(t0) * np.linalg.norm(leg)
    assert t0 @ leg > 0


def test_open_parameter_out_of_range_is_rejected():
    basis = SplineBasis(6, 2, closed=False)
    with pytest.raises(DataError, match=r"\[0, 4\]"):
        basis.basis([0.5, 4.5])


@pytest.mark.parametrize(
    "args, match",
    [((2, 2, True), "at least 3 control points"), ((5, 0, True), "degree must be at least 1"),
     ((4.0, 2, True), "integer"), ((4, 2, "yes"), "true or false")],
)
def test_invalid_basis_raises_config_error(args, match):
    with pytest.raises(ConfigError, match=match):
        SplineBasis(*args)


def test_basis_derivative_order_validated():
    with pytest.raises(ConfigError, match=r"\[0, 2\]"):
        SplineBasis(5).basis_derivative([0.0], 3)


@pytest.mark.parametrize("closed", [True, False])
@pytest.mark.parametrize("degree", [1, 2, 3, 4])
def test_basis_and_derivatives_agree_with_scipy_bspline(degree, closed):
    """The Cox–de Boor basis is scipy's B-spline of the same knots, at every order of
    derivative, on random parameters, at every knot and at the open curve's right end."""
    from scipy.interpolate import BSpline

    rng = np.random.default_rng(degree)
    for n in (degree + 1, degree + 3, 12):
        basis = SplineBasis(n, degree=degree, closed=closed)
        knots, fold = basis._knots
        spline = BSpline(knots, fold, degree, extrapolate=True)
        s = np.concatenate([rng.uniform(0, basis.L, 100), np.arange(basis.L + 1.0)])
        for nu in range(degree + 1):
            want = (spline if nu == 0 else spline.derivative(nu))(basis._wrap(s))
            np.testing.assert_allclose(basis.basis_derivative(s, nu), want, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------- metric
@pytest.mark.parametrize("n", [3, 5, 8, 12])
def test_closed_quadratic_metric_pinned(n):
    """Periodic quadratic: the Gram entries of the cardinal B-spline are 11/20, 13/60, 1/120."""
    row = np.zeros(n)
    row[0] += 11 / 20
    row[1 % n] += 13 / 60
    row[-1 % n] += 13 / 60
    row[2 % n] += 1 / 120
    row[-2 % n] += 1 / 120
    expected = np.array([np.roll(row, i) for i in range(n)]) / n
    np.testing.assert_allclose(SplineBasis(n).metric, expected, atol=1e-14)


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
@pytest.mark.parametrize("closed", [True, False])
def test_metric_matches_dense_trapezoid(degree, closed):
    basis = SplineBasis(degree + 5, degree, closed)
    s = np.linspace(0.0, basis.L, 40001)
    B = basis.basis(s)
    brute = np.trapezoid(B[:, :, None] * B[:, None, :], s, axis=0) / basis.L
    np.testing.assert_allclose(basis.metric, brute, atol=1e-8)
    np.testing.assert_allclose(basis.metric, basis.metric.T)
    assert np.linalg.eigvalsh(basis.metric).min() > 0
    N = basis.n_ctrl
    assert basis.U.shape == (2 * N, 2 * N)
    np.testing.assert_array_equal(basis.U[:N, :N], basis.metric)
    np.testing.assert_array_equal(basis.U[N:, N:], basis.metric)
    np.testing.assert_array_equal(basis.U[:N, N:], 0.0)


@FAST
@given(bases, st.integers(0, 2**32 - 1))
def test_U_norm_is_mean_square_distance_along_curve(basis, seed):
    rng = np.random.default_rng(seed)
    Q1 = rng.normal(size=2 * basis.n_ctrl) * 20
    Q2 = rng.normal(size=2 * basis.n_ctrl) * 20
    s = np.linspace(0.0, basis.L, 20001)
    d = CurveSampler(basis, s).points(Q1) - CurveSampler(basis, s).points(Q2)
    mean_sq = np.trapezoid(np.sum(d * d, axis=1), s) / basis.L
    dQ = Q1 - Q2
    np.testing.assert_allclose(dQ @ basis.U @ dQ, mean_sq, rtol=1e-6)
    # the mean weights give the parameter-mean of the curve
    pm = np.trapezoid(CurveSampler(basis, s).points(Q1), s, axis=0) / basis.L
    N = basis.n_ctrl
    np.testing.assert_allclose(
        [Q1[:N] @ basis.mean_weights, Q1[N:] @ basis.mean_weights], pm, atol=1e-6
    )
    if not basis.closed:
        np.testing.assert_allclose(curve_centre(Q1, basis), pm, atol=1e-6)


# ---------------------------------------------------------- sampler & normals
def test_sampler_batched_equals_one_by_one():
    rng = np.random.default_rng(3)
    basis = SplineBasis(7)
    sampler = basis.sampler(basis.measurement_params(18))
    Q = rng.normal(size=(4, 5, 14)) * 30 + 100
    P, Nrm = sampler.points_normals(Q)
    assert P.shape == Nrm.shape == (4, 5, 18, 2)
    for i in range(4):
        for j in range(5):
            np.testing.assert_allclose(sampler.points(Q[i, j]), P[i, j], atol=1e-12)
            np.testing.assert_allclose(sampler.normals(Q[i, j]), Nrm[i, j], atol=1e-12)
    # direct evaluation r(s) = U(s) Q
    B = basis.basis(sampler.s)
    np.testing.assert_allclose(P[1, 2, :, 0], B @ Q[1, 2, :7])
    np.testing.assert_allclose(P[1, 2, :, 1], B @ Q[1, 2, 7:])


@pytest.mark.parametrize("closed", [True, False])
@pytest.mark.parametrize("degree", [1, 2, 3])
def test_compiled_points_normals_are_the_numpy_ones(degree, closed):
    """The compiled evaluation the tracker uses is :meth:`points` and :meth:`normals`: curves
    running either way round (the outward sign), a single curve, and a curve whose control
    points coincide (zero tangent, zero normal)."""
    rng = np.random.default_rng(degree)
    basis = SplineBasis(9, degree=degree, closed=closed)
    sampler = basis.sampler(basis.measurement_params(20))
    Q = rng.normal(size=(3, 40, 18)) * 40 + 200
    Q[0, 1] = 0.0  # all control points at the origin
    ang = np.linspace(0, 2 * np.pi, 9, endpoint=False)
    Q[1, 0] = np.concatenate([50 * np.cos(ang), 30 * np.sin(ang)])  # an ellipse one way ...
    Q[1, 1] = np.concatenate([50 * np.cos(-ang), 30 * np.sin(-ang)])  # ... and the other
    P, N = sampler.points_normals(Q)
    np.testing.assert_allclose(P, sampler.points(Q), rtol=0, atol=1e-9)
    np.testing.assert_allclose(N, sampler.normals(Q), rtol=0, atol=1e-12)
    assert (N[0, 1] == 0).all()
    if closed:  # both ellipses' normals point outward
        assert (np.sum(N[1, :2] * P[1, :2], axis=-1) > 0).all()
    p1, n1 = sampler.points_normals(Q[2, 3])
    assert p1.shape == n1.shape == (20, 2)
    np.testing.assert_allclose(n1, N[2, 3], rtol=0, atol=1e-15)


def test_sampler_rejects_wrong_control_length():
    sampler = SplineBasis(6).sampler([0.0, 1.0])
    with pytest.raises(DataError, match="2\\*Nq = 12"):
        sampler.points(np.zeros(10))


@FAST
@given(
    st.integers(5, 14),
    st.integers(2, 3),
    st.floats(10.0, 80.0),
    st.floats(0.5, 1.0),
    st.floats(-np.pi, np.pi),
    st.booleans(),
)
def test_closed_normals_unit_orthogonal_and_outward(n, degree, a, ratio, phi, clockwise):
    basis = SplineBasis(n, degree, closed=True)
    Q = ellipse_ctrl(n, a, a * ratio, phi, clockwise, centre=(300.0, 200.0))
    sampler = basis.sampler(basis.measurement_params(23))
    p, nrm = sampler.points_normals(Q)
    t = sampler.tangents(Q)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(nrm * t, axis=-1), 0.0, atol=1e-9 * a)
    c = curve_centre(Q, basis)
    assert np.all(np.sum((p - c) * nrm, axis=-1) > 0)
    # reversing the control polygon flips tangents but not the normals
    N = n
    Qr = np.concatenate([Q[:N][::-1], Q[N:][::-1]])
    pr = sampler.points(Qr)
    assert np.all(np.sum((pr - c) * sampler.normals(Qr), axis=-1) > 0)


def test_open_normals_point_left_of_travel_on_screen():
    basis = SplineBasis(5, 2, closed=False)
    # a straight line running left to right along y = 50
    Q = np.concatenate([np.linspace(0, 100, 5), np.full(5, 50.0)])
    n = basis.sampler(basis.measurement_params(6)).normals(Q)
    np.testing.assert_allclose(n, np.tile([0.0, -1.0], (6, 1)), atol=1e-12)
    # reversing the direction flips them
    Qr = np.concatenate([Q[:5][::-1], Q[5:]])
    np.testing.assert_allclose(basis.sampler([1.0]).normals(Qr), [[0.0, 1.0]], atol=1e-12)


def test_degenerate_curve_gives_zero_normals_without_warnings():
    basis = SplineBasis(5)
    Q = np.concatenate([np.full(5, 3.0), np.full(5, 4.0)])
    with np.errstate(all="raise"):
        n = basis.sampler([0.0, 1.5]).normals(Q)
    np.testing.assert_array_equal(n, 0.0)


def test_measurement_params():
    closed = SplineBasis(8)
    np.testing.assert_allclose(closed.measurement_params(4), [0, 2, 4, 6])
    opened = SplineBasis(6, 2, closed=False)
    np.testing.assert_allclose(opened.measurement_params(4), [0.5, 1.5, 2.5, 3.5])
    with pytest.raises(ConfigError, match="positive integer"):
        closed.measurement_params(0)


# ---------------------------------------------------------- area & centroid
def test_polygon_area_centroid_known_shapes():
    square = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
    area, c = polygon_area_centroid(square)
    assert area == pytest.approx(4.0)
    np.testing.assert_allclose(c, [1, 1])
    area, c = polygon_area_centroid(square[::-1])
    assert area == pytest.approx(-4.0)
    np.testing.assert_allclose(c, [1, 1])
    tri = np.array([[0, 0], [3, 0], [0, 3]], float) + 1000
    area, c = polygon_area_centroid(tri)
    assert area == pytest.approx(4.5)
    np.testing.assert_allclose(c, [1001, 1001])
    # a batch, and a degenerate (collinear) polygon falling back to the vertex mean
    areas, cs = polygon_area_centroid(np.stack([square, [[0, 0], [1, 1], [2, 2], [3, 3]]]))
    np.testing.assert_allclose(areas, [4, 0])
    np.testing.assert_allclose(cs, [[1, 1], [1.5, 1.5]])


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_curve_area_centroid_exact_and_affine_equivariant(degree):
    rng = np.random.default_rng(20 + degree)
    basis = SplineBasis(9, degree)
    Q = blob(9, rng)
    area, c = curve_area_centroid(Q, basis)
    pa, pc = polygon_area_centroid(dense_polygon(Q, basis, 20000))
    assert area == pytest.approx(pa, rel=1e-6)
    np.testing.assert_allclose(c, pc, atol=1e-5)
    assert signed_area(Q, basis) == pytest.approx(area, rel=1e-12)
    A = np.array([[1.3, 0.4], [-0.2, 0.8]])
    t = np.array([-50.0, 17.0])
    N = basis.n_ctrl
    xy = A @ np.stack([Q[:N], Q[N:]]) + t[:, None]
    area2, c2 = curve_area_centroid(xy.ravel(), basis)
    assert area2 == pytest.approx(np.linalg.det(A) * area, rel=1e-10)
    np.testing.assert_allclose(c2, A @ c + t, atol=1e-9)


def test_dense_polygon_shapes_and_ends():
    closed = SplineBasis(6)
    assert dense_polygon(np.zeros(12), closed).shape == (96, 2)
    assert dense_polygon(np.zeros((3, 12)), closed, 10).shape == (3, 10, 2)
    opened = SplineBasis(6, 2, closed=False)
    Q = np.arange(12.0)
    pts = dense_polygon(Q, opened, 11)
    np.testing.assert_allclose(pts[[0, -1]], [[0, 6], [5, 11]])


# -------------------------------------------------------------------- fitting
@pytest.mark.parametrize("degree", [2, 3])
def test_fit_recovers_known_closed_spline(degree):
    rng = np.random.default_rng(30 + degree)
    basis = SplineBasis(8, degree)
    Q = blob(8, rng)
    # samples equally spaced in s: chord length alone would be biased
    pts = dense_polygon(Q, basis, 120)
    Qf = fit(pts, 8, degree=degree)
    np.testing.assert_allclose(Qf, Q, atol=1e-3)  # on a curve ~80 px across
    np.testing.assert_allclose(
        dense_polygon(Qf, basis, 500), dense_polygon(Q, basis, 500), atol=1e-4
    )
    assert np.abs(fit(pts, 8, degree=degree, refine=0) - Q).max() > 0.1


def test_fit_recovers_known_open_spline():
    basis = SplineBasis(7, 2, closed=False)
    Q = np.concatenate([np.arange(7) * 20.0, 30 * np.sin(np.arange(7.0))])
    pts = dense_polygon(Q, basis, 80)
    np.testing.assert_allclose(fit(pts, 7, closed=False), Q, atol=1e-4)


def test_fit_closed_handles_repeated_first_point_and_noise():
    rng = np.random.default_rng(5)
    basis = SplineBasis(10)
    Q = blob(10, rng)
    pts = dense_polygon(Q, basis, 200)
    noisy = pts + rng.normal(scale=0.5, size=pts.shape)
    Qf = fit(np.vstack([noisy, noisy[:1]]), 10)
    # the true curve lies close to the fitted one (noise sigma = 0.5 px)
    dense = dense_polygon(Qf, basis, 4000)
    dist = np.min(np.linalg.norm(pts[:, None] - dense[None], axis=-1), axis=1)
    assert np.sqrt(np.mean(dist**2)) < 0.25
    assert dist.max() < 0.8


@pytest.mark.parametrize(
    "points, kwargs, error, match",
    [
        (np.zeros((10, 3)), {}, DataError, r"shape \(P, 2\)"),
        (np.array([[0, 0], [1, 0], [np.nan, 1], [0, 1], [2, 2]]), {}, DataError, "NaN"),
        (np.array([[0, 0], [1, 0], [1, 1]]), {}, DataError, "at least 5 distinct"),
        (np.ones((20, 2)), {}, DataError, "at least 5 distinct"),
        (np.random.default_rng(0).normal(size=(20, 2)), {"degree": 4, "n_ctrl": 4},
         ConfigError, "at least 5 control points"),
        (np.random.default_rng(0).normal(size=(20, 2)), {"refine": -1}, ConfigError, "refine"),
    ],
)
def test_fit_errors(points, kwargs, error, match):
    kwargs = {"n_ctrl": 5, **kwargs}
    n_ctrl = kwargs.pop("n_ctrl")
    with pytest.raises(error, match=match):
        fit(points, n_ctrl, **kwargs)


def _pixel_outline_of_ellipse(cx, cy, a, b, angle=0.0):
    """The pixel boundary of a filled ellipse, as a segmentation mask gives it."""
    import cv2

    from trackcli.shapes.draw import canonical_start
    from trackcli.segment.masks import mask_outline

    m = np.zeros((int(cy + b + a + 20), int(cx + a + b + 20)), np.uint8)
    cv2.ellipse(m, ((cx, cy), (2 * a, 2 * b), angle), 255, -1)
    return canonical_start(mask_outline(m).astype(float))


def _curve_to_polygon(Q, n_ctrl, polygon):
    """Largest distance from the fitted curve to the closed polygon (px)."""
    import cv2

    curve = dense_polygon(Q, SplineBasis(n_ctrl), 2000)
    contour = polygon.astype(np.float32).reshape(-1, 1, 2)
    return max(abs(cv2.pointPolygonTest(contour, (float(x), float(y)), True)) for x, y in curve)


def _runs_against(Q, n_ctrl, polygon):
    """How many dense curve points run more than 120 degrees against the polygon's direction
    at the nearest polygon point (a fold or a loop of the curve)."""
    basis = SplineBasis(n_ctrl)
    s = np.linspace(0, basis.L, 1000, endpoint=False)
    C = np.stack((Q[:n_ctrl], Q[n_ctrl:]), axis=1)
    c, t = basis.basis(s) @ C, basis.basis_derivative(s, 1) @ C
    along = np.roll(polygon, -2, axis=0) - np.roll(polygon, 2, axis=0)
    near = np.argmin(np.linalg.norm(c[:, None] - polygon[None], axis=-1), axis=1)
    cos = np.sum(t * along[near], axis=1) / (np.linalg.norm(t, axis=1) * np.linalg.norm(along[near], axis=1))
    return int(np.count_nonzero(cos < -0.5))


@pytest.mark.parametrize("n_ctrl", [12, 16, 24, 32])
@pytest.mark.parametrize("a, b, angle", [(8.5, 25, 0.0), (7, 18, 0.0), (40, 12, 30.0), (60, 45, 0.0)])
def test_strict_fit_of_a_pixel_outline_stays_on_it(n_ctrl, a, b, angle):
    # Without strict the refinement slides control points along such outlines until the
    # curve folds back or throws out loops: 12 control points on the 17 x 50 px ellipse
    # ended 30 px off it.
    outline = _pixel_outline_of_ellipse(100.0, 100.0, a, b, angle)
    Q = fit(outline, n_ctrl, strict=True)
    assert _curve_to_polygon(Q, n_ctrl, outline) < 1.5
    assert _runs_against(Q, n_ctrl, outline) == 0
    # and the refinement does not end farther from the points than the chord-length fit
    Q0 = fit(outline, n_ctrl, refine=0)
    assert _curve_to_polygon(Q, n_ctrl, outline) <= _curve_to_polygon(Q0, n_ctrl, outline) + 0.5


def test_plain_fit_of_a_pixel_outline_can_fold():
    # what strict is for: the plain refinement folds the curve back along this ellipse's sides
    outline = _pixel_outline_of_ellipse(100.0, 100.0, 40, 12, 30.0)
    assert _runs_against(fit(outline, 12), 12, outline) > 0
    assert _runs_against(fit(outline, 12, strict=True), 12, outline) == 0

