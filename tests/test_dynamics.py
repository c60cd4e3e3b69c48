"""Tests of trackcli.dynamics.ar2: AR(2) state form, steady state, sampling, modes, defaults."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.dynamics.ar2 import AR2, symmetric_sqrt
from trackcli.dynamics.handset import SubspaceModel, h_orthogonal_projector, oscillator_coefficients, partitioned
from trackcli.errors import ConfigError, DataError, ModelError

TAU = 0.04  # 25 frames per second


def metric_6() -> np.ndarray:
    """A fixed, well-conditioned 6x6 symmetric positive definite metric (affine-like)."""
    rng = np.random.default_rng(11)
    M = rng.standard_normal((6, 6))
    return M @ M.T + 2.0 * np.eye(6)


def random_stable(rng: np.random.Generator, nx: int, radius: float) -> AR2:
    """A random model whose state matrix has spectral radius ``radius``."""
    A2 = rng.standard_normal((nx, nx))
    A1 = rng.standard_normal((nx, nx))
    model = AR2(A2, A1, np.eye(nx), np.zeros(nx), TAU)
    s = radius / model.spectral_radius()
    B0 = rng.standard_normal((nx, nx))
    return AR2(s * s * A2, s * A1, B0, rng.standard_normal(nx), TAU)


def lyapunov_residual(model: AR2, P: np.ndarray) -> float:
    A, B = model.state_matrices()
    return float(np.abs(A @ P @ A.T + B @ B.T - P).max() / np.abs(P).max())


# ---------------------------------------------------------------------------------------------
# state form


def test_state_matrices_have_companion_form():
    rng = np.random.default_rng(0)
    model = random_stable(rng, 3, 0.9)
    A, B = model.state_matrices()
    assert A.shape == (6, 6) and B.shape == (6, 3)
    np.testing.assert_array_equal(A[:3, :3], 0)
    np.testing.assert_array_equal(A[:3, 3:], np.eye(3))
    np.testing.assert_array_equal(A[3:, :3], model.A2)
    np.testing.assert_array_equal(A[3:, 3:], model.A1)
    np.testing.assert_array_equal(B[:3], 0)
    np.testing.assert_array_equal(B[3:], model.B0)
    np.testing.assert_array_equal(model.state_mean(), np.concatenate([model.mean, model.mean]))


def test_predict_equals_state_space_step():
    """One vectorised predict step is the first-order state equation (AC eq 9.17)."""
    rng = np.random.default_rng(1)
    model = random_stable(rng, 3, 0.95)
    prev = rng.standard_normal((50, 3))
    cur = rng.standard_normal((50, 3))
    new = model.predict(prev, cur, np.random.default_rng(7))
    A, B = model.state_matrices()
    w = np.random.default_rng(7).standard_normal((50, 3))
    state = np.hstack([prev, cur])
    expected = model.state_mean() + (state - model.state_mean()) @ A.T + w @ B.T
    np.testing.assert_allclose(expected[:, :3], cur, atol=1e-12)
    np.testing.assert_allclose(new, expected[:, 3:], atol=1e-12)
    one = model.predict(prev[0], cur[0], np.random.default_rng(7))
    np.testing.assert_allclose(one, new[0], atol=1e-12)


def test_predict_rejects_mismatched_shapes():
    model = random_stable(np.random.default_rng(2), 2, 0.9)
    with pytest.raises(DataError, match="shape"):
        model.predict(np.zeros((4, 2)), np.zeros((4, 3)), np.random.default_rng(0))


def test_construction_validates_shapes_and_values():
    with pytest.raises(ModelError, match=r"A1 must have shape \(2, 2\)"):
        AR2(np.eye(2), np.eye(3), np.eye(2), np.zeros(2), TAU)
    with pytest.raises(ModelError, match="non-finite"):
        AR2(np.eye(2), np.eye(2), np.full((2, 2), np.nan), np.zeros(2), TAU)
    with pytest.raises(ModelError, match="tau"):
        AR2(np.eye(2), np.eye(2), np.eye(2), np.zeros(2), 0.0)
    with pytest.raises(ModelError, match="mean"):
        AR2(np.eye(2), np.eye(2), np.eye(2), np.zeros((2, 1)), TAU)


def test_arrays_are_read_only_copies():
    A1 = np.eye(2)
    model = AR2(np.zeros((2, 2)), A1, np.eye(2), np.zeros(2), TAU)
    A1[0, 0] = 5.0
    assert model.A1[0, 0] == 1.0
    with pytest.raises(ValueError):
        model.A1[0, 0] = 3.0


# ---------------------------------------------------------------------------------------------
# steady state


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), nx=st.integers(1, 4), radius=st.floats(0.05, 0.995))
def test_steady_state_is_fixed_point_of_covariance_recursion(seed, nx, radius):
    model = random_stable(np.random.default_rng(seed), nx, radius)
    P = model.steady_state_covariance()
    assert P.shape == (2 * nx, 2 * nx)
    np.testing.assert_array_equal(P, P.T)
    assert lyapunov_residual(model, P) < 1e-8
    # the two diagonal blocks are the covariance of X at consecutive frames: equal
    np.testing.assert_allclose(P[:nx, :nx], P[nx:, nx:], rtol=1e-7, atol=1e-9 * np.abs(P).max())


def test_steady_state_agrees_with_iterating_the_recursion():
    model = random_stable(np.random.default_rng(3), 2, 0.8)
    A, B = model.state_matrices()
    P = np.zeros((4, 4))
    for _ in range(400):
        P = A @ P @ A.T + B @ B.T
    np.testing.assert_allclose(model.steady_state_covariance(), P, rtol=1e-9)


def test_unstable_model_has_no_steady_state():
    cv = AR2(-np.eye(2), 2 * np.eye(2), np.eye(2), np.zeros(2), TAU)
    assert cv.spectral_radius() == pytest.approx(1.0)
    assert not cv.is_stable()
    with pytest.raises(DataError, match="spectral radius"):
        cv.steady_state_covariance()


def test_isotropic_model_matches_eq_9_29():
    """One subspace spanning everything: P∞ = (ρ²/Nx) H⁻¹ and RMS displacement ρ (AC eq 9.29)."""
    H = metric_6()
    rho = 12.0
    model = partitioned(H, [SubspaceModel.oscillator(np.eye(6), 0.7, 3.0, rho, TAU)], np.zeros(6), TAU)
    P = model.steady_state_covariance()[6:, 6:]
    np.testing.assert_allclose(P, rho**2 / 6 * np.linalg.inv(H), rtol=1e-9)
    assert model.rms_displacement(H) == pytest.approx(rho, rel=1e-10)


# ---------------------------------------------------------------------------------------------
# hand-set oscillators (AC §9.6)


@settings(max_examples=60, deadline=None)
@given(fps=st.sampled_from([25.0, 30.0, 50.0, 60.0]), beta=st.floats(0.05, 20.0),
       f_frac=st.floats(0.0, 0.98), rho=st.floats(0.1, 500.0))
def test_oscillator_eigenvalues_and_steady_variance(fps, beta, f_frac, rho):
    tau = 1.0 / fps
    f = f_frac / (2 * tau)
    a1, a2, b0 = oscillator_coefficients(f, beta, rho, tau)
    # eigenvalues exp(-βτ ± 2πifτ) (AC eq 9.25 and its derivation)
    lam = np.linalg.eigvals(np.array([[0.0, 1.0], [a2, a1]]))
    target = np.exp(-beta * tau + 2j * np.pi * f * tau)
    assert np.allclose(np.sort_complex(lam), np.sort_complex(np.array([target, np.conj(target)])), atol=1e-6)
    # steady-state variance rho² (AC eq 9.26 solves eq 9.23)
    model = AR2([[a2]], [[a1]], [[b0]], [0.0], tau)
    assert model.steady_state_covariance()[1, 1] == pytest.approx(rho**2, rel=1e-7)
    # and b0 agrees with eq 9.26 as printed, where that form is not cancelling badly
    if beta * tau > 1e-2:
        printed = rho * math.sqrt(1 - a2**2 - a1**2 - 2 * a2 * a1**2 / (1 - a2))
        assert b0 == pytest.approx(printed, rel=1e-9)


def test_constant_velocity_uses_gamma0():
    a1, a2, b0 = oscillator_coefficients(0.0, 0.0, None, 0.04, gamma0=35.0)
    assert (a1, a2) == (2.0, -1.0)
    assert b0 == pytest.approx(35.0 * 0.04**1.5)


def test_constant_velocity_growth_is_semicubical():
    """From a known position and velocity, E‖X_n‖² = b0² Σ_{m<=n} m² (AC eq 9.28's growth)."""
    tau, gamma0, n_steps, n_paths = 0.04, 35.0, 25, 4000
    H = np.eye(2)  # translation space, metric I
    part = SubspaceModel.oscillator(np.eye(2), 0.0, 0.0, None, tau, gamma0=gamma0)
    model = partitioned(H, [part], np.zeros(2), tau)
    rng = np.random.default_rng(4)
    prev = np.zeros((n_paths, 2))
    cur = np.zeros((n_paths, 2))
    for _ in range(n_steps):
        prev, cur = cur, model.predict(prev, cur, rng)
    mean_square = float(np.mean(np.einsum("ni,ij,nj->n", cur, H, cur)))
    expected = part.b0**2 * sum(m * m for m in range(1, n_steps + 1))
    # ‖X‖² is expected/2 times a chi-square with 2 degrees of freedom: relative sd 1/sqrt(N)
    assert abs(mean_square / expected - 1) < 4 / math.sqrt(n_paths)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(f=1.0, beta=-1.0, rho=1.0, tau=0.04), "beta"),
        (dict(f=13.0, beta=1.0, rho=1.0, tau=0.04), "Nyquist"),
        (dict(f=-0.1, beta=1.0, rho=1.0, tau=0.04), "Nyquist"),
        (dict(f=1.0, beta=0.0, rho=1.0, tau=0.04), "undamped"),
        (dict(f=0.0, beta=0.0, rho=1.0, tau=0.04), "gamma0"),
        (dict(f=0.0, beta=1.0, rho=None, tau=0.04), "rho"),
        (dict(f=0.0, beta=1.0, rho=-2.0, tau=0.04), "rho"),
        (dict(f=0.0, beta=1.0, rho=2.0, tau=0.0), "tau"),
        (dict(f="fast", beta=1.0, rho=2.0, tau=0.04), "f must be a number"),
    ],
)
def test_oscillator_rejects_bad_settings(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        oscillator_coefficients(**kwargs)


# ---------------------------------------------------------------------------------------------
# partitioned defaults (AC eq 9.30)


def affine_partition(H, tau):
    Es = h_orthogonal_projector(H, np.eye(6)[:, :2])
    Ed = np.eye(6) - Es
    parts = [SubspaceModel.oscillator(Es, 0.5, 4.0, 10.0, tau),
             SubspaceModel.oscillator(Ed, 0.0, 6.0, 3.0, tau)]
    return Es, Ed, parts


def test_projector_is_h_orthogonal():
    H = metric_6()
    Es = h_orthogonal_projector(H, np.eye(6)[:, :2])
    np.testing.assert_allclose(Es @ Es, Es, atol=1e-12)
    np.testing.assert_allclose(H @ Es, (H @ Es).T, atol=1e-12)
    assert np.trace(Es) == pytest.approx(2.0)


def test_partitioned_rms_per_subspace_from_steady_state():
    H = metric_6()
    Es, Ed, parts = affine_partition(H, TAU)
    assert [p.rank for p in parts] == [2, 4]
    model = partitioned(H, parts, np.zeros(6), TAU)
    assert model.rms_displacement(H, Es) == pytest.approx(10.0, rel=1e-9)
    assert model.rms_displacement(H, Ed) == pytest.approx(3.0, rel=1e-9)
    # variances add across H-orthogonal subspaces (AC eq 9.31)
    assert model.rms_displacement(H) == pytest.approx(math.hypot(10.0, 3.0), rel=1e-9)
    # the subspace dynamics are those of the designed oscillators
    A, _ = model.state_matrices()
    lam = np.linalg.eigvals(A)
    expected = {complex(np.exp(-4.0 * TAU + 2j * np.pi * 0.5 * TAU)), complex(np.exp(-6.0 * TAU))}
    for target in expected:
        assert np.min(np.abs(lam - target)) < 1e-6


def _mean_square_sd(model: AR2, K: np.ndarray, n_frames: int, max_lag: int = 400) -> float:
    """Standard deviation of the time average of Xᵀ K X over a stationary path."""
    n = model.nx
    A, _ = model.state_matrices()
    P = model.steady_state_covariance()
    total = 0.0
    Gl = P.copy()  # Cov(𝒳_{k+l}, 𝒳_k) = A^l P
    for lag in range(max_lag):
        G = Gl[n:, n:]
        cov = 2.0 * np.trace(K @ G @ K @ G.T)  # Cov(q_k, q_{k+l}) for Gaussian X
        total += cov if lag == 0 else 2.0 * cov
        Gl = A @ Gl
    return math.sqrt(total / n_frames)


def test_partitioned_rms_per_subspace_from_long_simulation():
    H = metric_6()
    Es, Ed, parts = affine_partition(H, TAU)
    model = partitioned(H, parts, np.full(6, 3.0), TAU)
    n_frames = 40000
    X = model.simulate(n_frames, np.random.default_rng(5), burn_in=300) - model.mean
    for E, rho in ((Es, 10.0), (Ed, 3.0)):
        K = E.T @ H @ E
        ms = float(np.mean(np.einsum("ni,ij,nj->n", X, K, X)))
        sd = _mean_square_sd(model, K, n_frames)
        assert abs(ms - rho**2) < 4 * sd, (ms, rho**2, sd)
        assert sd < 0.05 * rho**2  # the check is tight enough to mean something


def test_partitioned_validates_projectors():
    H = metric_6()
    Es, Ed, parts = affine_partition(H, TAU)
    with pytest.raises(DataError, match="sum to the identity"):
        partitioned(H, parts[:1], np.zeros(6), TAU)
    plain = np.diag([1.0, 1, 0, 0, 0, 0])  # orthogonal in the Euclidean sense only
    bad = [SubspaceModel(plain, 1.0, -0.5, 1.0), SubspaceModel(np.eye(6) - plain, 1.0, -0.5, 1.0)]
    with pytest.raises(DataError, match="H-orthogonal"):
        partitioned(H, bad, np.zeros(6), TAU)
    with pytest.raises(DataError, match="not a projector"):
        partitioned(H, [SubspaceModel(2 * np.eye(6), 1.0, -0.5, 1.0)], np.zeros(6), TAU)
    with pytest.raises(DataError, match="positive definite"):
        partitioned(-np.eye(6), parts, np.zeros(6), TAU)


def test_symmetric_sqrt():
    rng = np.random.default_rng(6)
    M = rng.standard_normal((4, 4))
    C = M @ M.T
    S = symmetric_sqrt(C)
    np.testing.assert_allclose(S, S.T)
    np.testing.assert_allclose(S @ S, C, atol=1e-10)
    np.testing.assert_allclose(symmetric_sqrt(C, inverse=True) @ S, np.eye(4), atol=1e-8)
    # a covariance with a tiny negative eigenvalue from rounding still has a real root
    v = rng.standard_normal(4)
    nearly = np.outer(v, v) - 1e-15 * np.eye(4)
    assert np.all(np.isfinite(symmetric_sqrt(nearly)))


# ---------------------------------------------------------------------------------------------
# simulation


def test_simulate_deterministic_constant_velocity():
    model = AR2(-np.eye(2), 2 * np.eye(2), np.zeros((2, 2)), np.zeros(2), TAU)
    path = model.simulate(6, np.random.default_rng(0), x0=[0.0, 1.0], x1=[1.0, 1.5])
    expected = np.array([[k, 1.0 + 0.5 * k] for k in range(6)])
    np.testing.assert_allclose(path, expected, atol=1e-12)


def test_simulate_starts_at_mean_and_burn_in_drops_frames():
    model = random_stable(np.random.default_rng(7), 3, 0.9)
    path = model.simulate(50, np.random.default_rng(8))
    assert path.shape == (50, 3)
    np.testing.assert_array_equal(path[0], model.mean)
    np.testing.assert_array_equal(path[1], model.mean)
    long = model.simulate(70, np.random.default_rng(8), burn_in=0)
    burnt = model.simulate(50, np.random.default_rng(8), burn_in=20)
    np.testing.assert_allclose(burnt, long[20:], atol=1e-12)
    assert model.simulate(1, np.random.default_rng(0)).shape == (1, 3)
    with pytest.raises(DataError):
        model.simulate(0, np.random.default_rng(0))
    with pytest.raises(DataError, match="x0"):
        model.simulate(5, np.random.default_rng(0), x0=np.zeros(2))


def test_simulate_is_reproducible():
    model = random_stable(np.random.default_rng(9), 2, 0.9)
    a = model.simulate(30, np.random.default_rng(123))
    b = model.simulate(30, np.random.default_rng(123))
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------------------------------
# modal analysis (AC §11.3)


def test_modes_match_worked_examples_in_the_book():
    """AC §11.3, τ = 1/50 s: λ = 0.99 gives β = 0.50/s; λ = 0.95 + 0.24i gives β = 1.02/s, f = 1.97 Hz."""
    tau = 1 / 50
    real = AR2([[-0.99 * 0.5]], [[0.99 + 0.5]], [[1.0]], [0.0], tau)  # eigenvalues 0.99 and 0.5
    slow = real.modes()[0]
    assert slow.eigenvalue == pytest.approx(0.99)
    assert round(slow.beta, 2) == 0.50 and round(slow.decay_time, 1) == 2.0
    assert slow.frequency == 0 and slow.period == math.inf and not slow.oscillatory
    lam = 0.95 + 0.24j
    osc = AR2([[-abs(lam) ** 2]], [[2 * lam.real]], [[1.0]], [0.0], tau).modes()
    assert len(osc) == 1 and osc[0].oscillatory
    assert round(osc[0].beta, 2) == 1.02
    assert round(osc[0].frequency, 2) == 1.97
    assert round(osc[0].period, 2) == 0.51


def test_real_negative_eigenvalue_is_at_nyquist():
    model = AR2([[0.25]], [[0.0]], [[1.0]], [0.0], TAU)  # eigenvalues ±0.5
    modes = model.modes()
    assert sorted(m.frequency for m in modes) == [0.0, pytest.approx(1 / (2 * TAU))]
    for m in modes:
        assert m.beta == pytest.approx(math.log(2) / TAU)
        assert m.stable


def test_modes_recover_designed_dancer_model():
    """AC Fig 9.14: horizontal β = 0.2/s, f = 0.2 Hz; vertical β = 0.5/s, f = 1 Hz."""
    tau = 1 / 50
    H = np.eye(2)
    Ex, Ey = np.diag([1.0, 0.0]), np.diag([0.0, 1.0])
    model = partitioned(H, [SubspaceModel.oscillator(Ex, 0.2, 0.2, 300.0, tau),
                            SubspaceModel.oscillator(Ey, 1.0, 0.5, 100.0, tau)], np.zeros(2), tau)
    modes = model.modes()
    assert len(modes) == 2 and all(m.oscillatory and m.stable for m in modes)
    horizontal, vertical = modes  # slowest decay first
    assert horizontal.beta == pytest.approx(0.2, rel=1e-9)
    assert horizontal.frequency == pytest.approx(0.2, rel=1e-9)
    assert vertical.beta == pytest.approx(0.5, rel=1e-9)
    assert vertical.frequency == pytest.approx(1.0, rel=1e-9)
    assert horizontal.dominant(1) == [(0, pytest.approx(1.0))]
    assert vertical.dominant(1) == [(1, pytest.approx(1.0))]
    assert model.rms_displacement(H, Ex) == pytest.approx(300.0, rel=1e-9)


def test_mode_shape_is_eigenvector_upper_half():
    model = random_stable(np.random.default_rng(10), 3, 0.97)
    A, _ = model.state_matrices()
    for mode in model.modes():
        assert np.linalg.norm(mode.shape) == pytest.approx(1.0)
        assert mode.weights.sum() == pytest.approx(1.0)
        v = np.concatenate([mode.shape, mode.eigenvalue * mode.shape])  # (X; λX), AC eq 11.11
        np.testing.assert_allclose(A @ v, mode.eigenvalue * v, atol=1e-9)
        top = mode.dominant(1)[0][0]
        assert abs(mode.shape[top].imag) < 1e-12 and mode.shape[top].real > 0
        assert "|λ|" in mode.summary()
    n_eig = sum(2 if m.oscillatory else 1 for m in model.modes())
    assert n_eig == 6


@settings(max_examples=40, deadline=None)
@given(beta=st.floats(0.1, 15.0), f_frac=st.floats(0.01, 0.95))
def test_modes_invert_oscillator_design(beta, f_frac):
    f = f_frac / (2 * TAU)
    a1, a2, b0 = oscillator_coefficients(f, beta, 1.0, TAU)
    (mode,) = AR2([[a2]], [[a1]], [[b0]], [0.0], TAU).modes()
    assert mode.beta == pytest.approx(beta, rel=1e-6)
    assert mode.frequency == pytest.approx(f, rel=1e-6)


# ---------------------------------------------------------------------------------------------
# files


finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=30, deadline=None)
@given(data=st.data(), nx=st.integers(1, 4))
def test_dict_round_trip_through_yaml(data, nx):
    mats = [np.array(data.draw(st.lists(st.lists(finite, min_size=nx, max_size=nx), min_size=nx, max_size=nx)))
            for _ in range(3)]
    mean = np.array(data.draw(st.lists(finite, min_size=nx, max_size=nx)))
    tau = data.draw(st.floats(1e-4, 10.0))
    model = AR2(mats[0], mats[1], mats[2], mean, tau)
    back = AR2.from_dict(yaml.safe_load(yaml.safe_dump(model.to_dict())))
    for name in ("A2", "A1", "B0", "mean"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
    assert back.tau == model.tau


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda d: d.pop("B0"), "missing B0"),
        (lambda d: d.update(A1=[[1.0, 2.0]]), r"A1 must have shape \(2, 2\)"),
        (lambda d: d.update(A2="identity"), "A2: expected a list of rows"),
        (lambda d: d.update(mean=[[0.0, 0.0]]), "mean: expected a list of numbers"),
        (lambda d: d.update(B0=[[1.0, "x"], [0.0, 1.0]]), "B0"),
        (lambda d: d.update(tau=-0.04), "tau"),
        (lambda d: d.update(tau="25fps"), "tau"),
        (lambda d: d.update(A1=[[float("nan"), 0.0], [0.0, 1.0]]), "non-finite"),
        (lambda d: d.update(order=2), "unknown key"),
    ],
)
def test_from_dict_rejects_malformed(change, match):
    d = AR2(np.zeros((2, 2)), np.eye(2), np.eye(2), np.zeros(2), TAU).to_dict()
    change(d)
    with pytest.raises(ModelError, match=match) as info:
        AR2.from_dict(d, where="model.dynamics")
    assert str(info.value).startswith("model.dynamics")


def test_from_dict_rejects_non_mapping():
    with pytest.raises(ModelError, match="expected a mapping"):
        AR2.from_dict([1, 2, 3])


def test_repeated_roots_are_read_without_their_rounding():
    """Constant velocity (a double root 1) and critical damping (a double root 0.92), mixed by
    a change of coordinates, come out of eig as pairs like 1 ± 3e-8 i: the modes show them
    without spurious growth, damping, oscillation or period."""
    rng = np.random.default_rng(0)
    S = rng.normal(size=(3, 3))
    d = np.array([1.0, 1.0, 0.92])
    model = AR2(S @ np.diag(-d**2) @ np.linalg.inv(S), S @ np.diag(2 * d) @ np.linalg.inv(S), np.eye(3),
                np.zeros(3), TAU)
    assert np.abs(model.eigenvalues().imag).max() > 0  # the rounding this is about
    modes = model.modes()
    assert len(modes) == 6
    for m in modes:
        assert m.eigenvalue.imag == 0 and m.frequency == 0 and m.period == math.inf
    ones = [m for m in modes if m.modulus == 1.0]
    assert len(ones) == 4
    assert all(m.beta == 0.0 and m.decay_time == math.inf and not m.stable for m in ones)
    assert "marginal" in ones[0].summary()
    rest = [m for m in modes if m.modulus < 1.0]
    assert all(m.stable and m.beta == pytest.approx(-math.log(0.92) / TAU, rel=1e-4) for m in rest)
    assert model.stability() == "marginal"
    assert AR2([[-0.81]], [[1.8]], [[1.0]], [0.0], TAU).stability() == "stable"
    assert AR2([[-1.0]], [[2.1]], [[1.0]], [0.0], TAU).stability() == "UNSTABLE"
