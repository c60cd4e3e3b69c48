"""Tests for the second-order Kalman filter steps (trackcli.dynamics.kalman, AC Fig 10.3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from statsmodels.tsa.statespace.kalman_filter import KalmanFilter

from trackcli.errors import ConfigError, DataError
from trackcli.dynamics.kalman import (
    KalmanState,
    assimilate,
    filter_sequence,
    gate_rho,
    init_known_static,
    init_known_velocity,
    init_unknown,
    predict,
    state_space,
)


@dataclass(frozen=True)
class AR2:
    """Minimal stand-in for the dynamics model: the attributes kalman.py relies on."""

    A1: np.ndarray
    A2: np.ndarray
    B0: np.ndarray
    mean: np.ndarray
    tau: float = 0.02


def random_stable_ar2(rng: np.random.Generator, nx: int, radius: float = 0.95) -> AR2:
    """A random AR(2) model whose state matrix has spectral radius below ``radius``."""
    while True:
        A1 = rng.normal(0.0, 0.5, (nx, nx))
        A2 = rng.normal(0.0, 0.3, (nx, nx))
        model = AR2(
            A1=A1,
            A2=A2,
            B0=np.tril(rng.normal(0.0, 0.3, (nx, nx)), -1) + np.diag(rng.uniform(0.3, 0.8, nx)),
            mean=rng.normal(0.0, 2.0, nx),
        )
        A, _, _ = state_space(model)
        if np.max(np.abs(np.linalg.eigvals(A))) < radius:
            return model


def constant_velocity(nx: int, b0: float = 0.5, tau: float = 0.02) -> AR2:
    eye = np.eye(nx)
    return AR2(A1=2.0 * eye, A2=-eye, B0=b0 * eye, mean=np.zeros(nx), tau=tau)


def harmonic(nx: int, tau: float, beta: float, f: float, rho: float) -> AR2:
    """Damped oscillator in every coordinate, AC §9.6: eqs 9.25 and 9.26."""
    a2 = -np.exp(-2 * beta * tau)
    a1 = 2 * np.exp(-beta * tau) * np.cos(2 * np.pi * f * tau)
    b0 = rho * np.sqrt(1 - a2**2 - a1**2 - 2 * a2 * a1**2 / (1 - a2))
    eye = np.eye(nx)
    return AR2(A1=a1 * eye, A2=a2 * eye, B0=b0 * eye, mean=np.zeros(nx), tau=tau)


def simulate(model: AR2, rng: np.random.Generator, frames: int, start: np.ndarray) -> np.ndarray:
    """True states ``(X_{k-1}; X_k)`` for k = 1..frames, starting from state ``start``."""
    A, B, offset = state_space(model)
    states = np.empty((frames, A.shape[0]))
    state = start
    for k in range(frames):
        state = A @ state + offset + B @ rng.standard_normal(B.shape[1])
        states[k] = state
    return states


def random_measurements(rng, nx, frames, true_states):
    """Per frame: observation matrix h (M, Nx) with M in 0..6 and random rank, noise sd, y."""
    frames_out = []
    for k in range(frames):
        rows = int(rng.integers(0, 7))
        rank = int(rng.integers(0, min(rows, nx) + 1))
        h = rng.normal(size=(rows, rank)) @ rng.normal(size=(rank, nx))
        sd = rng.uniform(0.5, 2.0, rows)
        y = h @ true_states[k, nx:] + sd * rng.standard_normal(rows)
        frames_out.append((h, sd, y))
    return frames_out


def measure_from(h, sd, y):
    """Aggregate (Z, S) with innovations measured from the predicted shape."""

    def measure(predicted: KalmanState):
        weights = 1.0 / sd**2
        innovation = y - h @ predicted.X
        return h.T @ (weights * innovation), (h.T * weights) @ h

    return measure


def textbook_filter(model, init, measurements):
    """Dense filter on the full state: innovation covariance and an explicit inverse."""
    A, B, offset = state_space(model)
    nx = A.shape[0] // 2
    m, P = init.mean.copy(), init.cov.copy()
    out = []
    for h, sd, y in measurements:
        m = A @ m + offset
        P = A @ P @ A.T + B @ B.T
        if len(y):
            C = np.hstack([np.zeros_like(h), h])
            F = C @ P @ C.T + np.diag(sd**2)
            K = P @ C.T @ np.linalg.inv(F)
            m = m + K @ (y - C @ m)
            P = (np.eye(2 * nx) - K @ C) @ P
        out.append((m, P))
    return out


def statsmodels_filter(model, init, measurements):
    """statsmodels' state-space Kalman filter with a time-varying design, NaN = missing."""
    A, B, offset = state_space(model)
    nx = A.shape[0] // 2
    frames = len(measurements)
    width = max(1, max(len(y) for _, _, y in measurements))
    endog = np.full((frames, width), np.nan)
    design = np.zeros((width, 2 * nx, frames))
    obs_cov = np.zeros((width, width, frames))
    for k, (h, sd, y) in enumerate(measurements):
        endog[k, : len(y)] = y
        design[: len(y), nx:, k] = h
        obs_cov[:, :, k] = np.diag(np.concatenate([sd**2, np.ones(width - len(y))]))
    kf = KalmanFilter(k_endog=width, k_states=2 * nx, k_posdef=nx)
    kf.bind(endog)
    kf["design"] = design
    kf["obs_cov"] = obs_cov
    kf["transition"] = A
    kf["state_intercept"] = offset
    kf["selection"] = B
    kf["state_cov"] = np.eye(nx)
    # statsmodels initialises the *predicted* state of its first period.
    kf.initialize_known(A @ init.mean + offset, A @ init.cov @ A.T + B @ B.T)
    result = kf.filter()
    means, covs = result.filtered_state, result.filtered_state_cov
    return [(means[:, k], covs[:, :, k]) for k in range(frames)]


# --------------------------------------------------------------------------------------------
# (a) agreement with reference filters on a linear-Gaussian problem


@pytest.mark.parametrize("kind", ["stable", "constant_velocity"])
def test_matches_statsmodels_and_textbook_filter(kind):
    rng = np.random.default_rng(20240611 if kind == "stable" else 7)
    nx, frames = 3, 80
    if kind == "stable":
        model = random_stable_ar2(rng, nx)
        init = init_unknown(model)
    else:
        model = constant_velocity(nx)
        init = init_known_static(rng.normal(size=nx), model, sigma=1.5)
    true_states = simulate(model, rng, frames, init.mean)
    measurements = random_measurements(rng, nx, frames, true_states)
    rows = [len(y) for _, _, y in measurements]
    ranks = [np.linalg.matrix_rank(h) if len(h) else 0 for h, _, _ in measurements]
    # The draw covers every case: no rows, dependent rows, rank 1..Nx-1, and full rank.
    assert 0 in rows and nx in ranks
    assert any(m > r > 0 for m, r in zip(rows, ranks))
    assert any(0 < r < nx for r in ranks)

    ours = filter_sequence(model, init, [measure_from(*m) for m in measurements])
    assert len(ours) == frames
    for name, reference in [
        ("textbook", textbook_filter(model, init, measurements)),
        ("statsmodels", statsmodels_filter(model, init, measurements)),
    ]:
        for k, (state, (mean, cov)) in enumerate(zip(ours, reference)):
            where = f"{name}, frame {k + 1}"
            np.testing.assert_allclose(state.mean, mean, rtol=1e-8, atol=1e-8, err_msg=where)
            np.testing.assert_allclose(state.cov, cov, rtol=1e-8, atol=1e-8, err_msg=where)


def test_replaying_recorded_observations_gives_the_same_states():
    rng = np.random.default_rng(3)
    nx, frames = 3, 25
    model = random_stable_ar2(rng, nx)
    init = init_unknown(model)
    measurements = random_measurements(rng, nx, frames, simulate(model, rng, frames, init.mean))
    recorded = []

    def recording(measure):
        def wrapped(predicted):
            recorded.append(measure(predicted))
            return recorded[-1]

        return wrapped

    live = filter_sequence(model, init, [recording(measure_from(*m)) for m in measurements])
    replay = filter_sequence(model, init, iter(recorded))
    for a, b in zip(live, replay, strict=True):
        np.testing.assert_array_equal(a.mean, b.mean)
        np.testing.assert_array_equal(a.cov, b.cov)


def test_prediction_matches_block_formulas_of_fig_10_3():
    rng = np.random.default_rng(11)
    nx = 3
    model = random_stable_ar2(rng, nx)
    root = rng.normal(size=(2 * nx, 2 * nx))
    state = KalmanState(rng.normal(size=2 * nx), root @ root.T)
    Ppp, Pc, P = state.P_prev, state.P_cross, state.P
    A1, A2, B0 = model.A1, model.A2, model.B0
    out = predict(state, model)
    np.testing.assert_allclose(out.P_prev, P, rtol=1e-12)
    np.testing.assert_allclose(out.P_cross, A2 @ Pc.T + A1 @ P, rtol=1e-12)
    expected = (
        A2 @ Ppp @ A2.T + A1 @ Pc @ A2.T + A2 @ Pc.T @ A1.T + A1 @ P @ A1.T + B0 @ B0.T
    )
    np.testing.assert_allclose(out.P, expected, rtol=1e-12)
    np.testing.assert_array_equal(out.X_prev, state.X)
    np.testing.assert_allclose(
        out.X, A2 @ state.X_prev + A1 @ state.X + (np.eye(nx) - A2 - A1) @ model.mean, rtol=1e-12
    )
    np.testing.assert_array_equal(out.cov, out.cov.T)


# --------------------------------------------------------------------------------------------
# property tests of the assimilation step


def _psd(rng, n, rank):
    root = rng.normal(size=(n, rank))
    return root @ root.T


@st.composite
def predicted_and_information(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    nx = draw(st.integers(1, 4))
    rank = draw(st.integers(0, nx))
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    rng = np.random.default_rng(seed)
    cov = _psd(rng, 2 * nx, 2 * nx) + 0.1 * np.eye(2 * nx)
    predicted = KalmanState(rng.normal(size=2 * nx), cov)
    S = scale * _psd(rng, nx, rank)
    Z = S @ rng.normal(size=nx)  # information vectors lie in the range of S
    return rng, predicted, Z, S


@settings(max_examples=60, deadline=None)
@given(predicted_and_information())
def test_gain_form_equals_information_form(case):
    """AC eq 10.4 (information form) and eq 10.6 (gain form) give the same posterior."""
    _, predicted, Z, S = case
    nx = predicted.nx
    H = np.hstack([np.zeros((nx, nx)), np.eye(nx)])
    cov = np.linalg.inv(np.linalg.inv(predicted.cov) + H.T @ S @ H)
    mean = predicted.mean + cov @ H.T @ Z
    out = assimilate(predicted, Z, S)
    tol = 1e-7 * max(1.0, np.abs(predicted.cov).max())
    np.testing.assert_allclose(out.cov, cov, atol=tol, rtol=1e-7)
    np.testing.assert_allclose(out.mean, mean, atol=tol, rtol=1e-7)


@settings(max_examples=60, deadline=None)
@given(predicted_and_information())
def test_posterior_covariance_is_psd_and_no_larger_than_prior(case):
    _, predicted, Z, S = case
    out = assimilate(predicted, Z, S)
    np.testing.assert_array_equal(out.cov, out.cov.T)
    scale = np.abs(predicted.cov).max()
    assert np.linalg.eigvalsh(out.cov)[0] >= -1e-10 * scale
    assert np.linalg.eigvalsh(predicted.cov - out.cov)[0] >= -1e-8 * scale


@settings(max_examples=60, deadline=None)
@given(predicted_and_information(), st.integers(0, 4))
def test_assimilating_in_two_parts_equals_assimilating_the_sum(case, rank2):
    """Information adds (AC Fig 8.6): split a frame's normals into two batches."""
    rng, predicted, Z1, S1 = case
    nx = predicted.nx
    S2 = _psd(rng, nx, min(rank2, nx))
    X_true = predicted.X + rng.normal(size=nx)
    Z2 = S2 @ (X_true - predicted.X)
    both = assimilate(predicted, Z1 + Z2, S1 + S2)
    first = assimilate(predicted, Z1, S1)
    # The second batch's innovations are re-measured from the updated shape.
    second = assimilate(first, Z2 - S2 @ (first.X - predicted.X), S2)
    tol = 1e-7 * max(1.0, np.abs(predicted.cov).max())
    np.testing.assert_allclose(second.cov, both.cov, atol=tol, rtol=1e-6)
    np.testing.assert_allclose(second.mean, both.mean, atol=tol, rtol=1e-6)


def test_assimilate_rejects_malformed_information():
    predicted = KalmanState(np.zeros(4), np.eye(4))
    with pytest.raises(DataError, match="shape"):
        assimilate(predicted, np.zeros(3), np.eye(2))
    with pytest.raises(DataError, match="symmetric"):
        assimilate(predicted, np.zeros(2), np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(DataError, match="semi-definite"):
        assimilate(predicted, np.zeros(2), np.diag([1.0, -1.0]))
    with pytest.raises(DataError, match="Z must be zero"):
        assimilate(predicted, np.ones(2), np.zeros((2, 2)))
    with pytest.raises(DataError, match="finite"):
        assimilate(predicted, np.array([np.nan, 0.0]), np.eye(2))
    with pytest.raises(DataError, match="even length"):
        KalmanState(np.zeros(3), np.eye(3))


def test_state_is_an_immutable_value():
    mean = np.arange(4.0)
    state = KalmanState(mean, np.eye(4))
    mean[0] = 99.0
    assert state.mean[0] == 0.0
    with pytest.raises(ValueError):
        state.mean[1] = 5.0
    np.testing.assert_array_equal(state.X, [2.0, 3.0])
    np.testing.assert_array_equal(state.X_prev, [0.0, 1.0])
    np.testing.assert_array_equal(state.velocity, [2.0, 2.0])
    np.testing.assert_array_equal(state.X_std, [1.0, 1.0])


def test_dynamics_shape_mismatch_is_reported():
    model = constant_velocity(2)
    with pytest.raises(ConfigError, match="Nx = 2"):
        predict(KalmanState(np.zeros(6), np.eye(6)), model)
    with pytest.raises(ConfigError, match="'A1'"):
        state_space(object())
    with pytest.raises(ConfigError, match=r"B0.*\(2, 2\)"):
        state_space(AR2(A1=np.eye(2), A2=np.eye(2), B0=np.eye(3), mean=np.zeros(2)))


# --------------------------------------------------------------------------------------------
# (b) loss and recovery of lock


def test_no_features_is_pure_prediction_and_the_gate_grows_then_shrinks():
    rng = np.random.default_rng(5)
    nx = 3
    model = harmonic(nx, tau=0.02, beta=2.0, f=0.5, rho=10.0)
    S_full = _psd(rng, nx, nx) + np.eye(nx)
    X0 = rng.normal(size=nx)
    steady = init_known_static(X0, model, S=S_full)
    h = rng.normal(size=(20, nx))

    state, widths = steady, []
    for _ in range(40):  # every normal fails: S = 0, Z = 0
        predicted = predict(state, model)
        widths.append(gate_rho(predicted, h))
        state = assimilate(predicted, np.zeros(nx), np.zeros((nx, nx)))
        assert state is predicted
    widths = np.array(widths)
    # From the closed-loop steady state the open-loop covariance grows monotonically.
    assert np.all(np.diff(widths, axis=0) >= -1e-12)
    assert np.all(widths[1] > widths[0] + 1e-3)
    assert np.all(widths[-1] > 2.0 * widths[0])
    # ... and regresses towards the open-loop steady state (AC §10.2).
    far = state
    for _ in range(400):
        far = predict(far, model)
    np.testing.assert_allclose(far.cov, init_unknown(model).cov, rtol=1e-6, atol=1e-9)

    # Features return (at the true shape X0): the gate collapses back to its tracking width.
    regained = []
    for _ in range(60):
        predicted = predict(state, model)
        regained.append(gate_rho(predicted, h))
        state = assimilate(predicted, S_full @ (X0 - predicted.X), S_full)
    regained = np.array(regained)
    assert np.all(regained[1] < 0.8 * regained[0])
    tracking = gate_rho(predict(steady, model), h)
    np.testing.assert_allclose(regained[-1], tracking, rtol=1e-6)
    np.testing.assert_allclose(state.cov, steady.cov, rtol=1e-6, atol=1e-12)


def test_constant_velocity_gate_grows_as_t_to_the_three_halves():
    """AC Fig 10.9: with constant-velocity dynamics the gate width grows like t^(3/2)."""
    model = constant_velocity(2, b0=0.3)
    state = init_known_static(np.zeros(2), model, sigma=0.5)
    h = np.array([[1.0, 0.0], [0.6, 0.8]])
    widths = {}
    for k in range(1, 4001):
        state = predict(state, model)
        if k in (2000, 4000):
            widths[k] = gate_rho(state, h)
    slope = np.log(widths[4000] / widths[2000]) / np.log(2.0)
    np.testing.assert_allclose(slope, 1.5, atol=2e-3)


def test_gate_rho_matches_direct_formula():
    rng = np.random.default_rng(2)
    root = rng.normal(size=(6, 6))
    state = KalmanState(np.zeros(6), root @ root.T)
    h = rng.normal(size=(5, 3))
    expected = [np.sqrt(row @ state.P @ row) for row in h]
    np.testing.assert_allclose(gate_rho(state, h), expected, rtol=1e-12)
    assert gate_rho(state, np.zeros((0, 3))).shape == (0,)
    with pytest.raises(DataError, match=r"\(M, 3\)"):
        gate_rho(state, np.zeros(3))


# --------------------------------------------------------------------------------------------
# (c) initial conditions (AC §10.1)


@pytest.mark.parametrize("kind", ["stable", "constant_velocity", "stable_rank_deficient"])
def test_known_static_covariance_is_the_closed_loop_fixed_point(kind):
    rng = np.random.default_rng(17)
    nx = 3
    if kind == "constant_velocity":
        model = constant_velocity(nx)
        S = _psd(rng, nx, nx) + 0.5 * np.eye(nx)
    else:
        model = random_stable_ar2(rng, nx)
        S = _psd(rng, nx, 1) if kind == "stable_rank_deficient" else _psd(rng, nx, nx) + np.eye(nx)
    X0 = rng.normal(size=nx)
    start = init_known_static(X0, model, S=S)
    np.testing.assert_array_equal(start.mean, np.concatenate([X0, X0]))

    predicted = predict(start, model)
    again = assimilate(predicted, S @ (X0 - predicted.X), S)
    np.testing.assert_allclose(again.cov, start.cov, rtol=1e-9, atol=1e-12)
    if kind == "constant_velocity":  # no pull towards a model mean: the whole state is fixed
        np.testing.assert_allclose(again.mean, start.mean, rtol=1e-12)

    # The book's recipe, running the tracker on artificial measurements, reaches the same P.
    state = KalmanState(np.concatenate([X0, X0]), np.eye(2 * nx))
    for _ in range(3000):
        predicted = predict(state, model)
        state = assimilate(predicted, S @ (X0 - predicted.X), S)
    np.testing.assert_allclose(state.cov, start.cov, rtol=1e-7, atol=1e-10)


def test_known_static_search_region_for_precise_measurements_follows_eq_10_8():
    """AC eq 10.8: as ρf → 0 the closed-loop predicted covariance tends to B0 B0ᵀ."""
    rng = np.random.default_rng(23)
    model = random_stable_ar2(rng, 3)
    start = init_known_static(np.zeros(3), model, sigma=1e-4)
    predicted = predict(start, model)
    np.testing.assert_allclose(predicted.P, model.B0 @ model.B0.T, atol=1e-6)


def test_known_static_rejects_bad_information():
    model = constant_velocity(2)
    with pytest.raises(ConfigError, match="exactly one"):
        init_known_static(np.zeros(2), model)
    with pytest.raises(ConfigError, match="exactly one"):
        init_known_static(np.zeros(2), model, S=np.eye(2), sigma=1.0)
    with pytest.raises(ConfigError, match="sigma"):
        init_known_static(np.zeros(2), model, sigma=-1.0)
    with pytest.raises(DataError, match="init_unknown"):
        init_known_static(np.zeros(2), model, S=np.zeros((2, 2)))
    # Constant velocity in a direction S never observes has no closed-loop steady state.
    with pytest.raises(DataError, match="steady state"):
        init_known_static(np.zeros(2), model, S=np.diag([1.0, 0.0]))


def test_known_velocity_offsets_the_previous_shape():
    model = constant_velocity(2, tau=0.04)
    X0, V0 = np.array([1.0, -2.0]), np.array([25.0, 5.0])
    start = init_known_velocity(X0, V0, model, sigma=1.0)
    np.testing.assert_allclose(start.X_prev, X0 - V0 * 0.04)
    np.testing.assert_array_equal(start.X, X0)
    np.testing.assert_allclose(start.velocity / model.tau, V0)
    np.testing.assert_array_equal(start.cov, init_known_static(X0, model, sigma=1.0).cov)
    # Constant-velocity prediction carries the motion on.
    np.testing.assert_allclose(predict(start, model).X, X0 + V0 * 0.04)


def test_unknown_position_is_the_open_loop_lyapunov_fixed_point():
    rng = np.random.default_rng(29)
    model = random_stable_ar2(rng, 3)
    start = init_unknown(model)
    np.testing.assert_allclose(start.mean, np.concatenate([model.mean, model.mean]))
    A, B, _ = state_space(model)
    np.testing.assert_allclose(A @ start.cov @ A.T + B @ B.T, start.cov, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(predict(start, model).cov, start.cov, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(predict(start, model).mean, start.mean, rtol=1e-12)


def test_unknown_position_matches_harmonic_steady_state_variance():
    """Scalar damped oscillator: a1, a2 and b0 from AC §9.6 / eq 9.26 give variance ρ²."""
    model = harmonic(2, tau=0.02, beta=2.0, f=1.5, rho=4.0)
    np.testing.assert_allclose(init_unknown(model).P, 16.0 * np.eye(2), rtol=1e-10, atol=1e-12)


def test_unknown_position_rejects_constant_velocity():
    with pytest.raises(DataError, match="known position"):
        init_unknown(constant_velocity(3))
