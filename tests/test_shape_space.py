"""Tests for trackcli.shapes.shape_space: constructive and learned shape-spaces."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import subspace_angles

from trackcli.errors import ConfigError, DataError, ModelError
from trackcli.shapes.shape_space import (
    ShapeSpace,
    affine,
    explained_fraction,
    keyframes,
    pca,
    residual_pca,
    similarity,
    translation,
)
from trackcli.shapes.spline import CurveSampler, SplineBasis, curve_area_centroid, curve_centre

FAST = settings(max_examples=40, deadline=None)
NQ = 10
BASIS = SplineBasis(NQ)


def template(seed: int = 0, n: int = NQ) -> np.ndarray:
    rng = np.random.default_rng(seed)
    th = np.arange(n) / n * 2 * np.pi
    r = 40 * (1 + 0.15 * rng.standard_normal(n))
    return np.concatenate([220 + r * np.cos(th), 140 + 0.6 * r * np.sin(th)])


def map_affine(Q: np.ndarray, A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Apply p -> A p + t (about the image origin) to every control point."""
    N = Q.size // 2
    return (A @ np.stack([Q[:N], Q[N:]]) + np.asarray(t)[:, None]).ravel()


def l2_mean_square(space: ShapeSpace, X1, X2) -> float:
    s = np.linspace(0.0, space.basis.L, 20001)
    samp = CurveSampler(space.basis, s)
    d = space.points(X1, samp) - space.points(X2, samp)
    return np.trapezoid(np.sum(d * d, axis=-1), s) / space.basis.L


# ------------------------------------------------------------- constructive
@pytest.mark.parametrize(
    "make, nx, names",
    [
        (translation, 2, ("tx", "ty")),
        (similarity, 4, ("tx", "ty", "scos_m1", "ssin")),
        (affine, 6, ("tx", "ty", "a11_m1", "a22_m1", "a21", "a12")),
    ],
)
def test_constructive_spaces_shapes_and_template(make, nx, names):
    Q0 = template()
    S = make(BASIS, Q0)
    assert S.W.shape == (2 * NQ, nx) and S.Nx == nx and S.names == names
    assert S.kind == make.__name__
    np.testing.assert_allclose(S.to_control(np.zeros(nx)), Q0)
    np.testing.assert_allclose(S.origin, curve_area_centroid(Q0, BASIS)[1])
    assert S.H.shape == (nx, nx)
    np.testing.assert_allclose(S.H, S.W.T @ BASIS.U @ S.W, atol=1e-10)
    with pytest.raises(ValueError):  # arrays are read-only
        S.W[0, 0] = 1.0


@FAST
@given(
    st.lists(st.floats(-0.4, 0.4), min_size=4, max_size=4),
    st.floats(-80, 80),
    st.floats(-80, 80),
)
def test_translation_is_displacement_of_the_area_centroid(deform, tx, ty):
    """Affine maps carry area centroids along, so (tx, ty) moves the anchor exactly."""
    S = affine(BASIS, template(1))
    X = np.array([tx, ty, *deform])
    if abs((1 + X[2]) * (1 + X[3]) - X[4] * X[5]) < 0.05:
        return  # nearly collapsed curve: centroid ill-defined
    _, c = curve_area_centroid(S.to_control(X), BASIS)
    np.testing.assert_allclose(c, S.origin + [tx, ty], atol=1e-8)


@FAST
@given(st.floats(-3.0, 3.0), st.floats(0.3, 3.0), st.floats(-200, 200), st.floats(-200, 200))
def test_similarity_map_recovered_exactly_with_pose(theta, scale, tx, ty):
    Q0 = template(2)
    S = similarity(BASIS, Q0)
    R = scale * np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    t = np.array([tx, ty])
    Q = map_affine(Q0, R, t)
    X = S.project(Q)
    o = S.origin
    t_anchor = R @ o + t - o  # where the anchor went
    expected = [*t_anchor, scale * np.cos(theta) - 1, scale * np.sin(theta)]
    np.testing.assert_allclose(X, expected, atol=1e-8)
    np.testing.assert_allclose(S.to_control(X), Q, atol=1e-8)
    np.testing.assert_allclose(S.pose(X), [*t_anchor, theta, scale], atol=1e-9)
    # the affine space reads back the same pose
    Sa = affine(BASIS, Q0)
    np.testing.assert_allclose(Sa.pose(Sa.project(Q)), [*t_anchor, theta, scale], atol=1e-9)


@FAST
@given(st.floats(-3.0, 3.0), st.floats(0.3, 3.0), st.floats(-200, 200), st.floats(-200, 200), st.floats(0.25, 4.0))
def test_scaled_multiplies_the_scale_and_keeps_position_and_rotation(theta, scale, tx, ty, factor):
    Q0 = template(4)
    R = scale * np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    Q = map_affine(Q0, R, [tx, ty])
    for make in (similarity, affine):
        S = make(BASIS, Q0)
        X = S.project(Q)
        Y = S.scaled(np.stack([X, X]), np.array([factor, 1.0]))
        pose = S.pose(X)
        np.testing.assert_allclose(S.pose(Y[0]), [*pose[:3], scale * factor], atol=1e-8)
        np.testing.assert_allclose(Y[1], X, atol=1e-9)
        # the curve itself is the old one scaled about its anchor
        c = S.origin + X[:2]
        expected = np.concatenate([c[0] + factor * (Q[:NQ] - c[0]), c[1] + factor * (Q[NQ:] - c[1])])
        np.testing.assert_allclose(S.to_control(Y[0]), expected, atol=1e-7)
    # without scale in the space the curves come back unchanged
    T = translation(BASIS, Q0)
    np.testing.assert_allclose(T.scaled(np.array([tx, ty]), 2.0), [tx, ty], atol=1e-9)


def test_known_affine_map_recovered_exactly():
    Q0 = template(3)
    S = affine(BASIS, Q0)
    A = np.array([[1.25, -0.3], [0.45, 0.85]])
    t = np.array([12.0, -40.0])
    X = S.project(map_affine(Q0, A, t))
    o = S.origin
    ta = A @ o + t - o
    expected = [ta[0], ta[1], A[0, 0] - 1, A[1, 1] - 1, A[1, 0], A[0, 1]]
    np.testing.assert_allclose(X, expected, atol=1e-9)
    tx, ty, angle, scale = S.pose(X)
    assert angle == pytest.approx(np.arctan2(A[1, 0] - A[0, 1], A[0, 0] + A[1, 1]))
    assert scale == pytest.approx(np.sqrt(np.linalg.det(A)))
    # batched pose
    assert S.pose(np.stack([X, X, X])).shape == (3, 4)
    np.testing.assert_allclose(translation(BASIS, Q0).pose(X[:2]), [ta[0], ta[1], 0.0, 1.0])


def test_projection_idempotent_and_orthogonal():
    rng = np.random.default_rng(4)
    S = affine(BASIS, template(4))
    Q = template(4) + rng.normal(scale=5.0, size=(7, 2 * NQ))
    X = S.project(Q)
    np.testing.assert_allclose(S.project(S.to_control(X)), X, atol=1e-9)
    residual = Q - S.to_control(X)
    np.testing.assert_allclose(S.W.T @ BASIS.U @ residual.T, 0.0, atol=1e-9)
    # curves inside the space are reproduced exactly
    X2 = rng.normal(size=(3, 6)) * [10, 10, 0.1, 0.1, 0.1, 0.1]
    np.testing.assert_allclose(S.project(S.to_control(X2)), X2, atol=1e-10)


def test_H_norm_is_mean_square_displacement_along_curve():
    rng = np.random.default_rng(5)
    S = affine(BASIS, template(5))
    X1 = rng.normal(size=6) * [5, 5, 0.2, 0.2, 0.2, 0.2]
    X2 = rng.normal(size=6) * [5, 5, 0.2, 0.2, 0.2, 0.2]
    d = X1 - X2
    assert d @ S.H @ d == pytest.approx(l2_mean_square(S, X1, X2), rel=1e-6)


def test_points_normals_and_measurement_vectors():
    rng = np.random.default_rng(6)
    S = affine(BASIS, template(6))
    sampler = BASIS.sampler(BASIS.measurement_params(20))
    X = rng.normal(size=(5, 6)) * [3, 3, 0.05, 0.05, 0.05, 0.05]
    p, n = S.points_normals(X, sampler)
    assert p.shape == n.shape == (5, 20, 2)
    np.testing.assert_allclose(p, sampler.points(S.to_control(X)))
    np.testing.assert_allclose(n, S.normals(X, sampler))
    h = S.measurement_vectors(X, sampler)
    assert h.shape == (5, 20, 6)
    # h_i . dX is the displacement of r(s_i) along the (fixed) normal n(s_i)
    dX = rng.normal(size=6) * [2, 2, 0.1, 0.1, 0.1, 0.1]
    moved = S.points(X + dX, sampler) - p
    np.testing.assert_allclose(h @ dX, np.sum(moved * n, axis=-1), atol=1e-9)
    np.testing.assert_allclose(S.measurement_vectors(X[0], sampler, normals=n[0]), h[0])
    # translation along x moves every point by n_x
    np.testing.assert_allclose(h[..., 0], n[..., 0], atol=1e-12)


def test_wrong_inputs_are_rejected():
    S = similarity(BASIS, template())
    with pytest.raises(DataError, match="Nx = 4"):
        S.to_control(np.zeros(6))
    with pytest.raises(DataError, match="2\\*Nq = 20"):
        S.project(np.zeros(12))
    other = SplineBasis(8).sampler([0.0, 1.0])
    with pytest.raises(ConfigError, match="CurveSampler over"):
        S.points(np.zeros(4), other)
    with pytest.raises(DataError, match="shape \\(2\\*Nq, Nx\\)"):
        ShapeSpace(np.zeros((18, 2)), template(), BASIS, "custom", ("a", "b"), [0, 0])
    with pytest.raises(ConfigError, match="2 non-empty parameter names"):
        ShapeSpace(S.W[:, :2], template(), BASIS, "custom", ("a",), [0, 0])
    with pytest.raises(DataError, match="linearly dependent"):
        ShapeSpace(np.column_stack([S.W, S.W[:, :1] * 2]), template(), BASIS, "custom",
                   ("a", "b", "c", "d", "e"), [0, 0])


# --------------------------------------------------------------- projectors
@pytest.mark.parametrize("make", [translation, similarity, affine])
def test_translation_projector_is_H_orthogonal(make):
    S = make(BASIS, template(7))
    Es = S.translation_projector()
    Ed = S.deformation_projector()
    np.testing.assert_allclose(Es + Ed, np.eye(S.Nx))
    np.testing.assert_allclose(Es @ Es, Es, atol=1e-10)
    # kept and removed parts are orthogonal as curve displacements
    np.testing.assert_allclose(Es.T @ S.H @ Ed, 0.0, atol=1e-8)
    np.testing.assert_allclose(S.H @ Es, (S.H @ Es).T, atol=1e-8)
    # pure translations are kept, and Es equals the projector onto the tx, ty axes
    t = np.zeros(S.Nx)
    t[:2] = [3.0, -4.0]
    np.testing.assert_allclose(Es @ t, t, atol=1e-12)
    np.testing.assert_allclose(Ed @ t, 0.0, atol=1e-12)
    np.testing.assert_allclose(Es, S.projector([0, 1]), atol=1e-10)


def test_projector_for_any_partition():
    S = affine(BASIS, template(8))
    E = S.projector([2, 3])
    rng = np.random.default_rng(8)
    X = rng.normal(size=6)
    Y = E @ X
    np.testing.assert_allclose(Y[[0, 1, 4, 5]], 0.0, atol=1e-12)
    # E X is the H-closest point of the subspace: the remainder is H-orthogonal to it
    basis_vectors = np.eye(6)[:, [2, 3]]
    np.testing.assert_allclose(basis_vectors.T @ S.H @ (X - Y), 0.0, atol=1e-9)
    with pytest.raises(ConfigError, match=r"\[0, 5\]"):
        S.projector([1, 9])
    with pytest.raises(ConfigError, match="distinct"):
        S.projector([1, 1])


# ------------------------------------------------------------ serialisation
def test_dict_round_trip_through_yaml():
    S = keyframes(similarity(BASIS, template(9)), [template(10)])
    text = yaml.safe_dump(S.to_dict())
    S2 = ShapeSpace.from_dict(yaml.safe_load(text))
    np.testing.assert_array_equal(S2.W, S.W)
    np.testing.assert_array_equal(S2.Q0, S.Q0)
    np.testing.assert_array_equal(S2.origin, S.origin)
    assert (S2.kind, S2.names, S2.basis) == (S.kind, S.names, S.basis)


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda d: d.pop("W"), "missing key.*W"),
        (lambda d: d.update(W=[row[:-1] for row in d["W"]][:-1]), r"W: expected shape \(20, Nx\)"),
        (lambda d: d.update(Q0=d["Q0"][:-2]), r"Q0: expected shape \(20,\)"),
        (lambda d: d.update(origin=[1.0, float("nan")]), "origin: contains NaN"),
        (lambda d: d.update(W="abc"), "W: expected numbers"),
        (lambda d: d.update(basis={"n_ctrl": 1}), "basis: .*at least 3 control points"),
        (lambda d: d.update(names=["a", "b"]), "4 non-empty parameter names"),
        (lambda d: d.update(names="tx"), "names: expected a list"),
    ],
)
def test_from_dict_rejects_malformed(change, match):
    d = similarity(BASIS, template()).to_dict()
    change(d)
    with pytest.raises(ModelError, match=match):
        ShapeSpace.from_dict(d, where="model.shape_space")
    with pytest.raises(ModelError, match="expected a mapping"):
        ShapeSpace.from_dict([1, 2])


# --------------------------------------------------------------- key-frames
def test_keyframes_append_columns():
    Q0 = template(11)
    base = similarity(BASIS, Q0)
    k1, k2 = template(12), template(13)
    S = keyframes(base, [k1, k2])
    assert S.Nx == 6 and S.names[-2:] == ("k1", "k2") and S.kind == "similarity+keyframes"
    np.testing.assert_allclose(S.to_control([0, 0, 0, 0, 1, 0]), k1)
    np.testing.assert_allclose(S.to_control([0, 0, 0, 0, 0, 1]), k2)
    np.testing.assert_array_equal(S.origin, base.origin)
    S3 = keyframes(S, template(14))
    assert S3.names[-1] == "k3" and S3.kind == "similarity+keyframes"
    # pose still reads the similarity columns
    np.testing.assert_allclose(S.pose([1, 2, 0, 0, 0.3, 0.1]), [1, 2, 0, 1])
    # a key-frame that is just the template moved adds no new direction
    with pytest.raises(DataError, match="linearly dependent"):
        keyframes(base, [Q0 + np.repeat([5.0, 2.0], NQ)])


# -------------------------------------------------------------------- PCA
def test_pca_recovers_planted_subspace():
    rng = np.random.default_rng(15)
    space = affine(BASIS, template(15))
    V = rng.normal(size=(6, 2)) * [[5], [5], [0.1], [0.1], [0.1], [0.1]]
    mean = np.array([3.0, -2.0, 0.05, 0.0, 0.02, -0.01])
    T = 300
    X = mean + (rng.normal(size=(T, 2)) * [3.0, 1.0]) @ V.T
    S, explained = pca(space, X, 2)
    assert S.kind == "pca" and S.names == ("pc1", "pc2") and S.Nx == 2
    # the learned columns span the planted curve subspace
    angles = subspace_angles(S.W, space.W @ V)
    assert np.max(angles) < 1e-8
    np.testing.assert_allclose(S.Q0, space.to_control(X.mean(axis=0)), atol=1e-9)
    np.testing.assert_allclose(S.H, np.eye(2), atol=1e-9)  # modes are L2-orthonormal
    np.testing.assert_allclose(explained.sum(), 1.0, atol=1e-10)  # rank-2 data
    assert explained[0] >= explained[1]
    # the training curves are reproduced exactly by the learned space
    Q = space.to_control(X)
    np.testing.assert_allclose(S.to_control(S.project(Q)), Q, atol=1e-8)
    assert explained_fraction(S, Q) == pytest.approx(1.0, abs=1e-10)


def test_pca_explained_is_eigenvalues_of_PH():
    rng = np.random.default_rng(16)
    space = affine(BASIS, template(16))
    X = rng.normal(size=(50, 6)) * [4, 3, 0.05, 0.08, 0.03, 0.02]
    _, full = pca(space, X, 6)
    np.testing.assert_allclose(full.sum(), 1.0, atol=1e-12)
    assert np.all(np.diff(full) <= 1e-15)
    D = X - X.mean(axis=0)
    P = D.T @ D / len(X)
    lam = np.sort(np.linalg.eigvals(P @ space.H).real)[::-1]
    np.testing.assert_allclose(full, lam / np.trace(P @ space.H), rtol=1e-8)
    _, first3 = pca(space, X, 3)
    np.testing.assert_allclose(first3, full[:3])


def test_pca_uses_the_curve_norm_not_the_euclidean_one():
    """tx varies by 10 px (L2 variance 100); a11 by 0.5 — tiny in X, large along the curve."""
    rng = np.random.default_rng(17)
    space = affine(BASIS, template(17))
    X = np.zeros((400, 6))
    X[:, 0] = 10.0 * rng.standard_normal(400)
    X[:, 2] = 0.5 * rng.standard_normal(400)
    assert 0.25 * space.H[2, 2] > 100  # the a11 mode moves the curve more
    S, explained = pca(space, X, 1)
    d = space.project(S.to_control([1.0])) - space.project(S.to_control([0.0]))
    e = np.eye(6)[2]
    # cosine, as curve displacements, between the first mode and the a11 axis
    cos = (e @ space.H @ d) / np.sqrt((e @ space.H @ e) * (d @ space.H @ d))
    assert abs(cos) > 0.99
    assert explained[0] > 0.5
    # whereas Euclidean PCA of X would pick tx
    assert np.argmax(np.abs(np.linalg.eigh(np.cov(X.T))[1][:, -1])) == 0


def test_pca_errors():
    space = translation(BASIS, template())
    with pytest.raises(DataError, match="at least 2 samples"):
        pca(space, np.zeros((1, 2)), 1)
    with pytest.raises(DataError, match=r"shape \(T, 2\)"):
        pca(space, np.zeros((5, 3)), 1)
    with pytest.raises(ConfigError, match=r"\[1, 2\]"):
        pca(space, np.ones((5, 2)), 3)
    with pytest.raises(DataError, match="do not vary"):
        pca(space, np.ones((5, 2)), 1)


def test_pca_space_pose_via_affine_projection():
    rng = np.random.default_rng(18)
    space = affine(BASIS, template(18))
    X = rng.normal(size=(40, 6)) * [4, 4, 0.05, 0.05, 0.05, 0.05]
    S, _ = pca(space, X, 6)  # full rank: the PCA space is the affine space again
    R = 1.2 * np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    c = curve_centre(S.Q0, BASIS)
    Q = map_affine(S.Q0, R, c - R @ c + [4.0, -6.0])  # rotate and scale about c, then shift
    np.testing.assert_allclose(S.pose(S.project(Q)), [4.0, -6.0, 0.3, 1.2], atol=1e-8)


# ----------------------------------------------------------- residual PCA
def _residual_training_set(seed: int, T: int = 200):
    rng = np.random.default_rng(seed)
    Q0 = template(seed)
    base = similarity(BASIS, Q0)
    modes = rng.normal(size=(2, 2 * NQ)) * 3.0
    Xs = rng.normal(size=(T, 4)) * [6, 6, 0.05, 0.05]
    Q = base.to_control(Xs) + (rng.normal(size=(T, 2)) * [2.0, 1.0] + [0.5, -0.3]) @ modes
    return base, Q


def test_residual_pca_columns_are_H_orthogonal_to_base():
    base, Q = _residual_training_set(19)
    S, explained = residual_pca(base, Q, 2)
    assert S.Nx == 6 and S.names == base.names + ("r1", "r2")
    assert S.kind == "similarity+pca"
    np.testing.assert_array_equal(S.W[:, :4], base.W)
    np.testing.assert_allclose(S.H[:4, 4:], 0.0, atol=1e-8)
    np.testing.assert_allclose(S.H[4:, 4:], np.eye(2), atol=1e-9)
    # base coordinates are unchanged by the augmentation
    np.testing.assert_allclose(S.project(Q)[:, :4], base.project(Q), atol=1e-8)
    # the planted rank-2 residual is fully covered
    assert explained_fraction(base, Q) < 0.99
    assert explained_fraction(S, Q) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(S.to_control(S.project(Q)), Q, atol=1e-7)
    # fractions: base share plus residual shares make the whole
    base_share = explained_fraction(base, Q)
    assert base_share + explained.sum() == pytest.approx(1.0, abs=1e-9)
    # pose still reads the similarity part
    np.testing.assert_allclose(S.pose(S.project(Q))[:, :2], base.pose(base.project(Q))[:, :2])


def test_residual_pca_errors():
    base, Q = _residual_training_set(20)
    with pytest.raises(DataError, match="only 2 direction"):
        residual_pca(base, Q, 3)
    with pytest.raises(ConfigError, match=r"\[1, 16\]"):
        residual_pca(base, Q, 17)
    with pytest.raises(DataError, match=r"shape \(T, 20\)"):
        residual_pca(base, Q[:, :10], 1)
