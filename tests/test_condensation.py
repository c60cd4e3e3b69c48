"""Tests of the CONDENSATION steps: weights, resampling, prediction, estimates, start-up."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.trackers import condensation as cond
from trackcli.errors import ConfigError, DataError

# A stable, oscillatory 1-D AR(2) model: poles 0.8 +- 0.245i, |pole| = 0.837.
A1, A2, B0, MEAN = 1.6, -0.7, 1.0, 2.0
R_OBS = 1.5


def ar2(a1=A1, a2=A2, b0=B0, mean=MEAN) -> SimpleNamespace:
    return SimpleNamespace(A1=np.array([[a1]]), A2=np.array([[a2]]), B0=np.array([[b0]]), mean=np.array([mean]))


# ---------------------------------------------------------------------------------------------
# (a) CONDENSATION tends to the exact Kalman filter on a linear-Gaussian problem


def kalman_reference(z: np.ndarray, m0: float, p0: float) -> tuple[float, float]:
    """Exact filter for the state (x_{k-1}, x_k): mean and variance of x_T given z_1..z_T.

    The initial state has x_{-1} = x_0 ~ N(m0, p0) (a sample set started at rest).
    """
    f = np.array([[0.0, 1.0], [A2, A1]])
    d = np.array([0.0, (1 - A1 - A2) * MEAN])
    q = np.array([[0.0, 0.0], [0.0, B0**2]])
    hrow = np.array([0.0, 1.0])
    mean = np.array([m0, m0])
    cov = p0 * np.ones((2, 2))
    for zk in z:
        mean = f @ mean + d
        cov = f @ cov @ f.T + q
        s = hrow @ cov @ hrow + R_OBS**2
        gain = cov @ hrow / s
        mean = mean + gain * (zk - hrow @ mean)
        cov = cov - np.outer(gain, hrow @ cov)
    return float(mean[1]), float(cov[1, 1])


def simulate_observations(rng: np.random.Generator, steps: int, x0: float) -> np.ndarray:
    prev = cur = x0
    z = []
    for _ in range(steps):
        prev, cur = cur, MEAN + A2 * (prev - MEAN) + A1 * (cur - MEAN) + B0 * rng.standard_normal()
        z.append(cur + R_OBS * rng.standard_normal())
    return np.array(z)


def particle_estimate(z: np.ndarray, n: int, m0: float, p0: float, rng: np.random.Generator, scheme: str = "multinomial"):
    dyn = ar2()
    particles = cond.init_gaussian(np.array([m0]), np.array([[p0]]), n, rng)
    for zk in z:
        particles, _ = cond.step(particles, dyn, lambda x, zk=zk: -0.5 * ((zk - x[:, 0]) / R_OBS) ** 2, rng, scheme=scheme)
    mean = cond.weighted_mean(particles)[0]
    var = float(particles.weights @ (particles.cur[:, 0] - mean) ** 2)
    return float(mean), var


M0, P0, STEPS = 1.0, 4.0, 8


@pytest.fixture(scope="module")
def observations():
    z = simulate_observations(np.random.default_rng(10), STEPS, M0)
    return z, kalman_reference(z, M0, P0)


def test_particle_mean_converges_to_kalman_mean(observations):
    z, (k_mean, k_var) = observations
    mean, var = particle_estimate(z, 200_000, M0, P0, np.random.default_rng(11))
    # Monte Carlo standard error is about sqrt(k_var / N) ~ 0.002.
    assert mean == pytest.approx(k_mean, abs=0.02)
    assert var == pytest.approx(k_var, rel=0.03)


@pytest.mark.parametrize("scheme", ["systematic", "stratified"])
def test_other_schemes_converge_too(observations, scheme):
    z, (k_mean, k_var) = observations
    mean, var = particle_estimate(z, 50_000, M0, P0, np.random.default_rng(12), scheme)
    assert mean == pytest.approx(k_mean, abs=0.03)
    assert var == pytest.approx(k_var, rel=0.05)


def test_error_shrinks_as_one_over_root_n(observations):
    z, (k_mean, _) = observations
    rms = {}
    for n in (100, 10_000):
        errs = [particle_estimate(z, n, M0, P0, np.random.default_rng(1000 + seed))[0] - k_mean for seed in range(60)]
        rms[n] = math.sqrt(np.mean(np.square(errs)))
    # sqrt(10 000 / 100) = 10; with 60 seeds the ratio of RMS errors is known to within ~20 %.
    assert 6.5 < rms[100] / rms[10_000] < 15


# ---------------------------------------------------------------------------------------------
# (b) Resampling is unbiased


weight_lists = st.lists(st.floats(0.0, 10.0, allow_nan=False), min_size=1, max_size=12).filter(lambda w: sum(w) > 1e-3)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(weights=weight_lists, factor=st.sampled_from([1, 2]))
def test_resampling_schemes_are_unbiased(weights, factor):
    w = np.array(weights)
    p = w / w.sum()
    n_out = factor * len(w)
    draws = 1500
    rng = np.random.default_rng(20)
    for scheme in cond.RESAMPLERS:
        counts = np.zeros((draws, len(w)))
        for i in range(draws):
            idx = cond.resample(w, n_out, rng, scheme)
            assert idx.shape == (n_out,) and idx.min() >= 0 and idx.max() < len(w)
            assert np.all(np.diff(idx) >= 0)
            counts[i] = np.bincount(idx, minlength=len(w))
        expected = n_out * p
        # Five standard errors of the multinomial mean count (the others vary less).
        tol = 5 * np.sqrt(n_out * p * (1 - p) / draws) + 1e-9
        assert np.all(np.abs(counts.mean(axis=0) - expected) <= tol), scheme
        assert np.all(counts[:, p == 0] == 0), scheme
        if scheme == "systematic":
            assert np.all(counts >= np.floor(expected - 1e-9)) and np.all(counts <= np.ceil(expected + 1e-9))


def test_resample_rejects_unknown_scheme_and_bad_weights():
    rng = np.random.default_rng(21)
    with pytest.raises(ConfigError, match="multinomial, systematic, stratified"):
        cond.resample(np.ones(3), 3, rng, "residual")
    with pytest.raises(DataError, match="zero"):
        cond.resample(np.zeros(3), 3, rng)
    with pytest.raises(DataError, match="non-negative"):
        cond.resample(np.array([1.0, -1.0]), 3, rng)
    with pytest.raises(ConfigError, match="n_out"):
        cond.resample(np.ones(3), 0, rng)


def test_multinomial_uses_cumulative_weights_with_last_entry_one():
    # Weights whose cumulative sum rounds above or below 1 still select valid indices.
    w = np.full(10, 0.1)
    idx = cond.resample(w, 100_000, np.random.default_rng(22), "multinomial")
    assert idx.max() == 9 and idx.min() == 0
    assert np.all(np.abs(np.bincount(idx) / 100_000 - 0.1) < 0.005)


# ---------------------------------------------------------------------------------------------
# (c) Weights never become NaN


@pytest.mark.parametrize("value", [-1e6, -np.inf, np.nan])
def test_normalise_never_gives_nan(value):
    w, degenerate = cond.normalise_log_weights(np.full(5, value))
    np.testing.assert_allclose(w, 0.2)
    assert degenerate == (value != -1e6)


def test_normalise_handles_huge_magnitudes():
    w, degenerate = cond.normalise_log_weights(np.array([-1e6, -1e6 - 1, -np.inf, -1e6 - 800]))
    assert not degenerate
    np.testing.assert_allclose(w[:2], np.array([1, math.exp(-1)]) / (1 + math.exp(-1)))
    assert w[2] == 0 and w[3] < 1e-300
    w, _ = cond.normalise_log_weights(np.array([np.inf, 0.0, np.inf]))
    np.testing.assert_array_equal(w, [0.5, 0.0, 0.5])


def test_step_survives_underflowing_likelihoods():
    rng = np.random.default_rng(30)
    particles = cond.init_gaussian(np.zeros(1), np.eye(1), 50, rng)
    for loglik in (lambda x: np.full(len(x), -1e6), lambda x: np.full(len(x), -np.inf), lambda x: np.full(len(x), np.nan)):
        out, info = cond.step(particles, ar2(), loglik, rng)
        assert np.all(np.isfinite(out.weights)) and out.weights.sum() == pytest.approx(1)
        assert info.ess == pytest.approx(50)
        assert info.degenerate == (loglik(np.zeros((1, 1)))[0] != -1e6)
        # The next step starts from uniform weights and carries on.
        out2, info2 = cond.step(out, ar2(), lambda x: -0.5 * x[:, 0] ** 2, rng)
        assert not info2.degenerate and np.isfinite(cond.weighted_mean(out2)).all()


# ---------------------------------------------------------------------------------------------
# Steps, estimates and initialisation


def test_effective_sample_size():
    assert cond.effective_sample_size(np.ones(8)) == pytest.approx(8)
    assert cond.effective_sample_size(np.array([0, 0, 3.0, 0])) == pytest.approx(1)
    assert cond.effective_sample_size(np.array([1.0, 1.0, 2.0])) == pytest.approx(16 / 6)


def test_step_is_reproducible_and_tracks_parents():
    dyn = SimpleNamespace(A1=np.eye(2), A2=np.zeros((2, 2)), B0=np.zeros((2, 2)), mean=np.zeros(2))
    start = cond.ParticleSet(prev=np.zeros((4, 2)), cur=np.arange(8.0).reshape(4, 2), log_w=np.log([0.1, 0.2, 0.3, 0.4]))
    a, info_a = cond.step(start, dyn, lambda x: np.zeros(len(x)), np.random.default_rng(40), n_out=6)
    b, _ = cond.step(start, dyn, lambda x: np.zeros(len(x)), np.random.default_rng(40), n_out=6)
    np.testing.assert_array_equal(a.cur, b.cur)
    assert a.n == 6 and info_a.resampled
    # With A1 = I, A2 = 0 and no noise, each new sample repeats its parent, and prev = parent.
    np.testing.assert_array_equal(a.cur, a.prev)
    assert {tuple(r) for r in a.cur} <= {tuple(r) for r in start.cur}


def test_step_keeps_weights_when_ess_is_high():
    rng = np.random.default_rng(41)
    start = cond.init_gaussian(np.zeros(1), np.eye(1), 200, rng)
    start = cond.ParticleSet(start.prev, start.cur, -0.01 * start.cur[:, 0] ** 2)  # ESS/N close to 1
    kept, info = cond.step(start, ar2(mean=0.0), lambda x: np.zeros(len(x)), rng, ess_threshold=0.5)
    assert not info.resampled
    np.testing.assert_array_equal(kept.prev, start.cur)  # every sample propagated in order
    np.testing.assert_allclose(kept.weights, start.weights)
    skewed = cond.ParticleSet(start.prev, start.cur, -50 * start.cur[:, 0] ** 2)
    _, info = cond.step(skewed, ar2(mean=0.0), lambda x: np.zeros(len(x)), rng, ess_threshold=0.5)
    assert info.resampled and info.ess_before < 100


def test_predict_matches_the_ar2_equation():
    rng = np.random.default_rng(42)
    nx = 3
    dyn = SimpleNamespace(
        A1=rng.normal(size=(nx, nx)) * 0.3,
        A2=rng.normal(size=(nx, nx)) * 0.2,
        B0=rng.normal(size=(nx, 2)),
        mean=rng.normal(size=nx),
    )
    prev, cur = rng.normal(size=(5, nx)), rng.normal(size=(5, nx))
    got = cond.predict(prev, cur, dyn, np.random.default_rng(7))
    w = np.random.default_rng(7).standard_normal((5, 2))
    for i in range(5):
        ref = dyn.mean + dyn.A2 @ (prev[i] - dyn.mean) + dyn.A1 @ (cur[i] - dyn.mean) + dyn.B0 @ w[i]
        np.testing.assert_allclose(got[i], ref)
    with pytest.raises(ConfigError, match="A1"):
        cond.predict(prev, cur, SimpleNamespace(A1=np.eye(2), A2=np.eye(3), B0=np.eye(3), mean=np.zeros(3)), rng)


def test_estimates_mean_best_and_histogram():
    cur = np.array([[1.0, 0.0], [2.0, 5.0], [3.0, 1.0], [10.0, 0.0]])
    p = cond.ParticleSet(prev=cur, cur=cur, log_w=np.log([0.1, 0.5, 0.4, 1e-30]))
    np.testing.assert_allclose(cond.weighted_mean(p), [0.1 + 1.0 + 1.2, 2.5 + 0.4], rtol=1e-12)
    np.testing.assert_array_equal(cond.best_sample(p), [2.0, 5.0])
    hist = cond.weighted_histogram(p, np.array([0.0, 1.5, 2.5, 5.0]), component=0)
    np.testing.assert_allclose(hist, [0.1, 0.5, 0.4])
    assert cond.weighted_histogram(p, np.array([0.0, 2.5]), component=1).sum() == pytest.approx(0.5)
    with pytest.raises(ConfigError, match="increasing"):
        cond.weighted_histogram(p, np.array([1.0, 0.0]))


def test_init_gaussian_moments_and_velocity():
    rng = np.random.default_rng(43)
    cov = np.array([[4.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 0.0]])  # singular is allowed
    p = cond.init_gaussian(np.array([1.0, -2.0, 3.0]), cov, 40_000, rng)
    np.testing.assert_array_equal(p.prev, p.cur)
    np.testing.assert_allclose(p.cur.mean(axis=0), [1, -2, 3], atol=0.05)
    np.testing.assert_allclose(np.cov(p.cur.T), cov, atol=0.1)
    moving = cond.init_gaussian(np.zeros(3), cov, 10, rng, velocity=np.array([1.0, 0.0, -2.0]))
    np.testing.assert_allclose(moving.cur - moving.prev, np.tile([1.0, 0.0, -2.0], (10, 1)))
    with pytest.raises(DataError, match="semi-definite"):
        cond.init_gaussian(np.zeros(2), np.diag([1.0, -1.0]), 10, rng)


def test_init_steady_state_reaches_the_stationary_covariance():
    dyn = ar2()
    # Stationary covariance of the state (x_{k-1}, x_k): P = F P F^T + G G^T (AC eq 9.23).
    f = np.array([[0.0, 1.0], [A2, A1]])
    p_inf = scipy.linalg.solve_discrete_lyapunov(f, np.diag([0.0, B0**2]))
    p = cond.init_steady_state(dyn, 40_000, np.random.default_rng(44))
    state = np.column_stack([p.prev[:, 0], p.cur[:, 0]])
    np.testing.assert_allclose(state.mean(axis=0), [MEAN, MEAN], atol=0.08)
    np.testing.assert_allclose(np.cov(state.T), p_inf, rtol=0.04)


def test_init_steady_state_refuses_models_without_one():
    constant_velocity = ar2(a1=2.0, a2=-1.0)
    with pytest.raises(DataError, match="not stable"):
        cond.init_steady_state(constant_velocity, 10, np.random.default_rng(45))


def test_sample_size_schedule():
    size = cond.sample_size_schedule()
    assert [size(k) for k in range(7)] == [1500, 1250, 1000, 750, 500, 500, 500]
    assert cond.sample_size_schedule(100, 100, 0)(0) == 100
    with pytest.raises(ConfigError):
        size(-1)
    with pytest.raises(ConfigError, match="start"):
        cond.sample_size_schedule(0, 10, 3)


def test_particle_set_validates_shapes():
    with pytest.raises(DataError, match="prev"):
        cond.ParticleSet(prev=np.zeros((3, 2)), cur=np.zeros((3, 3)), log_w=np.zeros(3))
    with pytest.raises(DataError, match="log_w"):
        cond.ParticleSet(prev=np.zeros((3, 2)), cur=np.zeros((3, 2)), log_w=np.zeros(4))
    with pytest.raises(DataError, match="loglik"):
        cond.step(cond.init_gaussian(np.zeros(1), np.eye(1), 5, np.random.default_rng(46)), ar2(), lambda x: np.zeros(3),
                  np.random.default_rng(47))


def test_step_evaluates_loglik_in_blocks_and_reassembles_them():
    rng = np.random.default_rng(48)
    n = 2 * cond.LOGLIK_BLOCK + 17
    start = cond.init_gaussian(np.zeros(2), np.eye(2), n, rng)
    sizes = []

    def loglik(x):
        sizes.append(len(x))
        return -0.5 * np.sum((x - [0.5, -0.3]) ** 2, axis=1)

    out, _ = cond.step(start, SimpleNamespace(A1=np.eye(2), A2=np.zeros((2, 2)), B0=np.eye(2), mean=np.zeros(2)), loglik, rng)
    assert sizes == [cond.LOGLIK_BLOCK, cond.LOGLIK_BLOCK, 17]
    expected, _ = cond.normalise_log_weights(loglik(out.cur))
    np.testing.assert_allclose(out.weights, expected, rtol=1e-12)


def test_a_jump_of_the_motion_prior_is_an_impulse():
    """A jumped sample moves by the jump and keeps it as velocity; the others are untouched."""
    from trackcli.trackers.condensation_tracker import translation_jumps

    rng = np.random.default_rng(4)
    prev = rng.normal(size=(2000, 4))
    new = prev + rng.normal(size=(2000, 4))
    propose = translation_jumps(0.25, 3.0)
    out_prev, out, corr = propose(prev, new, np.random.default_rng(9))
    np.testing.assert_array_equal(out_prev, prev)  # X_{k-1} stays: the velocity changes with the position
    np.testing.assert_array_equal(corr, 0.0)  # the mixture prior is sampled as it is
    moved = np.any(out != new, axis=1)
    np.testing.assert_array_equal(out[:, 2:], new[:, 2:])  # translation only
    assert 0.2 < moved.mean() < 0.3
    jumps = (out - new)[moved, :2]
    assert np.std(jumps) == pytest.approx(3.0, rel=0.1)
    assert translation_jumps(0.0, 3.0) is None and translation_jumps(0.1, 0.0) is None


def test_a_braking_jump_slows_stops_or_turns_back_the_predicted_velocity():
    """A braking jump is -u v (v the predicted velocity, u uniform in [0, 2]) plus a small
    isotropic part; it is an impulse too, and it comes on top of the isotropic jumps."""
    from trackcli.trackers.condensation_tracker import BRAKE_SPREAD, translation_jumps

    rng = np.random.default_rng(5)
    n = 20000
    prev = rng.normal(size=(n, 4))
    v = np.zeros((n, 4))
    v[:, :2] = 40.0 * rng.normal(size=(n, 2))  # fast: the braking dominates the isotropic part
    new = prev + v
    rms = 1.0
    out_prev, out, corr = translation_jumps(0.0, rms, brake=0.5)(prev, new, np.random.default_rng(1))
    np.testing.assert_array_equal(out_prev, prev)
    np.testing.assert_array_equal(corr, 0.0)
    np.testing.assert_array_equal(out[:, 2:], new[:, 2:])
    moved = np.any(out != new, axis=1)
    assert 0.48 < moved.mean() < 0.52
    jump, vel = (out - new)[moved, :2], v[moved, :2]
    u = -np.sum(jump * vel, axis=1) / np.sum(vel * vel, axis=1)  # the share of v taken off
    assert u.min() > -0.1 and u.max() < 2.1
    assert np.mean(u) == pytest.approx(1.0, abs=0.03) and np.std(u) == pytest.approx(2 / np.sqrt(12), abs=0.03)
    # what is left across the velocity is the isotropic part, BRAKE_SPREAD * rms per axis
    across = (jump[:, 0] * vel[:, 1] - jump[:, 1] * vel[:, 0]) / np.hypot(vel[:, 0], vel[:, 1])
    assert np.std(across) == pytest.approx(BRAKE_SPREAD * rms, rel=0.05)
    # both kinds together: shares add up, and a sample at rest only gets the small part
    both = translation_jumps(0.1, rms, brake=0.05)(prev, new, np.random.default_rng(2))[1]
    assert 0.14 < np.any(both != new, axis=1).mean() < 0.16
    assert translation_jumps(0.0, 3.0, brake=0.0) is None and translation_jumps(0.0, 3.0, brake=0.1) is not None
    with pytest.raises(ConfigError, match="together at most 1"):
        translation_jumps(0.9, 3.0, brake=0.2)


@pytest.mark.parametrize("threads", [2, 3])
def test_weigh_in_threads_gives_every_thread_an_equal_share_and_the_same_result(threads):
    """Blocks are cut into equal shares, one per thread, and the caller scores one of them; the
    weights are those of one thread to the bit; an error in any block reaches the caller."""
    rng = np.random.default_rng(2)
    x = rng.normal(size=(5 * cond.LOGLIK_BLOCK + 11, 3))
    import threading

    seen: dict[str, int] = {}

    def loglik(block):
        name = threading.current_thread().name
        seen[name] = seen.get(name, 0) + len(block)
        return -0.5 * np.sum(block**2, axis=1)

    ll1, w1, _ = cond.weigh(x, loglik, threads=1)
    seen.clear()
    ll, w, _ = cond.weigh(x, loglik, threads=threads)
    np.testing.assert_array_equal(ll, ll1)
    np.testing.assert_array_equal(w, w1)
    # the caller scores its share (a pool thread may take more than one share when it is free)
    assert seen[threading.current_thread().name] == pytest.approx(x.shape[0] / threads, rel=0.001)
    assert sum(seen.values()) == x.shape[0]
    for bad_start in (0, x.shape[0] - 1):  # the caller's share, the pool's last block
        def failing(block, bad=x[bad_start]):
            if np.any(np.all(block == bad, axis=1)):
                raise DataError("scoring failed")
            return np.zeros(len(block))

        with pytest.raises(DataError, match="scoring failed"):
            cond.weigh(x, failing, threads=threads)


# ---------------------------------------------------------------------------------------------
# A tempered likelihood (power < 1)


@settings(max_examples=40, deadline=None)
@given(power=st.floats(0.05, 1.0), seed=st.integers(0, 2**31 - 1))
def test_the_weights_take_the_likelihood_to_the_power_and_report_it_unscaled(power, seed):
    rng = np.random.default_rng(seed)
    samples = rng.normal(size=(40, 2))
    base = rng.normal(size=40)

    def loglik(x):
        return -3.0 * (x * x).sum(axis=1)

    ll, log_w, degenerate = cond.weigh(samples, loglik, base, power=power)
    np.testing.assert_allclose(ll, loglik(samples))
    expected = base + power * loglik(samples)
    expected = expected - expected.max()
    expected = expected - np.log(np.exp(expected).sum())
    np.testing.assert_allclose(log_w, expected, atol=1e-12)
    assert not degenerate


def test_a_tempered_step_is_the_step_with_a_scaled_likelihood_and_keeps_its_spread():
    """power p weighs as the likelihood scaled by p would (same draws); the posterior of a
    Gaussian likelihood is then wider by 1/sqrt(p) about a flat prior."""
    start = cond.init_gaussian(np.zeros(1), np.eye(1) * 25.0, 4000, np.random.default_rng(3))

    def loglik(x):
        return -0.5 * (x[:, 0] - 1.0) ** 2

    a, info_a = cond.step(start, ar2(b0=0.0, mean=0.0, a1=1.0, a2=0.0), loglik, np.random.default_rng(7), power=0.25)
    b, info_b = cond.step(start, ar2(b0=0.0, mean=0.0, a1=1.0, a2=0.0), lambda x: 0.25 * loglik(x),
                          np.random.default_rng(7))
    np.testing.assert_array_equal(a.cur, b.cur)
    np.testing.assert_allclose(a.log_w, b.log_w, atol=1e-12)
    np.testing.assert_allclose(info_a.loglik, loglik(a.cur))  # the likelihood itself
    # about a prior of sd 5, the tempered posterior is N(.., 1 / (1/25 + 0.25)): sd 1.86, not 0.98
    w = a.weights
    mean = float(w @ a.cur[:, 0])
    sd = math.sqrt(float(w @ (a.cur[:, 0] - mean) ** 2))
    assert sd == pytest.approx(1.0 / math.sqrt(1 / 25 + 0.25), rel=0.1)


@pytest.mark.parametrize("power", [0.0, -0.5, 1.5, float("nan")])
def test_step_rejects_a_power_outside_zero_to_one(power):
    start = cond.init_gaussian(np.zeros(1), np.eye(1), 10, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="power"):
        cond.step(start, ar2(), lambda x: np.zeros(len(x)), np.random.default_rng(0), power=power)
