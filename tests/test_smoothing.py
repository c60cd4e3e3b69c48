"""The Rauch–Tung–Striebel smoother and the information-form forward pass.

References: statsmodels' linear-Gaussian state-space smoother on the same model (agreement to
1e-8), and simulated data (the smoothed error is below the filtered error).
"""

from __future__ import annotations

import numpy as np
import pytest
from statsmodels.tsa.statespace.mlemodel import MLEModel

from trackcli.dynamics import kalman
from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.rts import filter_information, rts_smooth, smooth_filtered


def _oscillator(nx: int = 2) -> AR2:
    """A damped oscillation in every component, lightly coupled (2 nx state dimensions)."""
    rng = np.random.default_rng(5)
    a1 = 2 * 0.97 * np.cos(2 * np.pi * 0.05)
    A1 = a1 * np.eye(nx) + 0.02 * rng.standard_normal((nx, nx))
    A2 = -(0.97**2) * np.eye(nx)
    B0 = np.diag(np.linspace(0.5, 1.0, nx)) + 0.05 * np.ones((nx, nx))
    return AR2(A2, A1, B0, np.linspace(1.0, 2.0, nx), 0.04)


def _simulate(model: AR2, T: int, rng: np.random.Generator) -> np.ndarray:
    nx = model.A1.shape[0]
    X = np.zeros((T, nx))
    X[0] = X[1] = model.mean
    for k in range(2, T):
        X[k] = (model.mean + model.A2 @ (X[k - 2] - model.mean) + model.A1 @ (X[k - 1] - model.mean)
                + model.B0 @ rng.standard_normal(nx))
    return X


def _statsmodels(model: AR2, y: np.ndarray, C: np.ndarray, R: np.ndarray, a1: np.ndarray, P1: np.ndarray):
    """statsmodels' smoother on the state (X_{k-1}; X_k), observed through (0 C) + N(0, R)."""
    A, B, offset = kalman.state_space(model)
    nx = model.A1.shape[0]
    sm = MLEModel(y, k_states=2 * nx, k_posdef=nx)
    design = np.zeros((C.shape[0], 2 * nx))
    design[:, nx:] = C
    sm.ssm["design"] = design
    sm.ssm["obs_cov"] = R
    sm.ssm["transition"] = A
    sm.ssm["state_intercept"] = offset
    sm.ssm["selection"] = B
    sm.ssm["state_cov"] = np.eye(nx)
    sm.ssm.initialize_known(a1, P1)
    return sm.ssm.smooth()


def _information(C: np.ndarray, R: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute information ``(z, S)`` of a measurement ``y = C X + N(0, R)``; NaN rows are missing."""
    seen = ~np.isnan(y)
    Cs, Rs = C[seen], R[np.ix_(seen, seen)]
    Ri = np.linalg.inv(Rs) if seen.any() else np.zeros((0, 0))
    return Cs.T @ Ri @ y[seen], Cs.T @ Ri @ Cs


def _observations(model: AR2, T: int, seed: int, rows: int = 3):
    """Simulated shapes and ``rows`` noisy linear measurements of each, some missing."""
    rng = np.random.default_rng(seed)
    X = _simulate(model, T, rng)
    C = np.array([[1.0, 0.3], [-0.2, 1.0], [0.5, 0.5]])[:rows]
    R = np.diag([0.8, 1.5, 2.0])[:rows, :rows]
    y = X @ C.T + rng.standard_normal((T, rows)) @ np.sqrt(R)
    y[5] = np.nan             # a frame with no measurement
    y[9, 1:] = np.nan         # frames with rank-1 information
    y[12, 0] = np.nan
    return X, C, R, y


def test_rts_matches_statsmodels_smoother():
    model = _oscillator(2)
    T = 40
    _, C, R, y = _observations(model, T, seed=1)
    init = kalman.init_unknown(model)
    ref = _statsmodels(model, y, C, R, init.mean, init.cov)

    filtered, predicted = [], init
    for k in range(T):
        if k:
            predicted = kalman.predict(filtered[-1], model)
        z, S = _information(C, R, y[k])
        filtered.append(kalman.assimilate(predicted, z - S @ predicted.X, S))
    smoothed = rts_smooth(model, filtered)

    for k in range(T):
        np.testing.assert_allclose(filtered[k].mean, ref.filtered_state[:, k], rtol=0, atol=1e-8)
        np.testing.assert_allclose(smoothed.states[k].mean, ref.smoothed_state[:, k], rtol=0, atol=1e-8)
        np.testing.assert_allclose(smoothed.states[k].cov, ref.smoothed_state_cov[:, :, k], rtol=0, atol=1e-8)
    # statsmodels' smoothed_state_autocov[:, :, k] is Cov(state_{k+1}, state_k | all)
    for k in range(T - 1):
        np.testing.assert_allclose(smoothed.cross[k], ref.smoothed_state_autocov[:, :, k], rtol=0, atol=1e-8)


def test_information_filter_matches_statsmodels_likelihood_and_smoother():
    """The forward pass EM uses: a fixed prior on (X_0; X_1), then whitened information."""
    model = _oscillator(2)
    nx, T = 2, 30
    # two measurements of two components: the whitening is then a change of variables
    _, C, R, y = _observations(model, T, seed=2, rows=2)
    prior_mean = np.array([0.5, 1.0, 1.5, 2.5])
    prior_cov = np.diag([4.0, 3.0, 5.0, 2.0])
    prior_cov[0, 2] = prior_cov[2, 0] = 1.0

    zs, Ss = zip(*(_information(C, R, y[k]) for k in range(T)))
    filtered, loglik = filter_information(model, kalman.KalmanState(prior_mean, prior_cov),
                                          np.array(zs), np.array(Ss))
    smoothed = smooth_filtered(model, filtered)

    # statsmodels: the state at time t is (X_t; X_{t+1}) for t = 0 .. T-2; the first one
    # carries the observations of frames 0 and 1, each later one that of its lower block.
    A, B, offset = kalman.state_space(model)
    obs = np.full((T - 1, 4), np.nan)
    obs[0, :2] = y[0]
    obs[:, 2:] = y[1:]
    sm = MLEModel(obs, k_states=2 * nx, k_posdef=nx)
    design = np.zeros((4, 2 * nx))
    design[:2, :nx] = C
    design[2:, nx:] = C
    sm.ssm["design"] = design
    sm.ssm["obs_cov"] = np.kron(np.eye(2), R)
    sm.ssm["transition"] = A
    sm.ssm["state_intercept"] = offset
    sm.ssm["selection"] = B
    sm.ssm["state_cov"] = np.eye(nx)
    sm.ssm.initialize_known(prior_mean, prior_cov)
    ref = sm.ssm.smooth()

    for k in range(T - 1):
        np.testing.assert_allclose(filtered.means[k], ref.filtered_state[:, k], rtol=0, atol=1e-8)
        np.testing.assert_allclose(smoothed.means[k], ref.smoothed_state[:, k], rtol=0, atol=1e-8)
        np.testing.assert_allclose(smoothed.covs[k], ref.smoothed_state_cov[:, :, k], rtol=0, atol=1e-8)
    for k in range(T - 2):
        np.testing.assert_allclose(smoothed.cross[k], ref.smoothed_state_autocov[:, :, k], rtol=0, atol=1e-8)
    # Whitening y -> R^(-1/2) y changes the density by the Jacobian, 0.5 log det R per seen frame.
    jacobian = sum(0.5 * np.linalg.slogdet(R[np.ix_(~np.isnan(row), ~np.isnan(row))])[1]
                   for row in y if (~np.isnan(row)).any())
    assert loglik == pytest.approx(float(np.sum(ref.llf_obs)) + jacobian, abs=1e-8)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_smoothed_error_below_filtered_error(seed):
    model = _oscillator(2)
    T = 300
    X, C, R, y = _observations(model, T, seed=seed)
    init = kalman.init_unknown(model)
    filtered, predicted = [], init
    for k in range(T):
        if k:
            predicted = kalman.predict(filtered[-1], model)
        z, S = _information(C, R, y[k])
        filtered.append(kalman.assimilate(predicted, z - S @ predicted.X, S))
    smoothed = rts_smooth(model, filtered)
    err_f = np.sqrt(np.mean((np.array([s.X for s in filtered]) - X) ** 2))
    err_s = np.sqrt(np.mean((smoothed.X - X) ** 2))
    assert err_s < 0.9 * err_f
    # and the smoothed variances are never above the filtered ones
    for f, s in zip(filtered, smoothed.states):
        assert np.all(np.diag(s.P) <= np.diag(f.P) + 1e-12)


def test_single_frame_is_its_own_smoothing():
    model = _oscillator(2)
    state = kalman.init_unknown(model)
    smoothed = rts_smooth(model, [state])
    np.testing.assert_array_equal(smoothed.states[0].mean, state.mean)
    assert smoothed.cross.shape == (0, 4, 4)


def test_particle_smoother_approaches_the_rts_smoother_on_a_linear_gaussian_model():
    """CONDENSATION with a Gaussian likelihood, then the backward pass, against Kalman + RTS."""
    from trackcli.trackers import condensation as cond
    from trackcli.trackers.smoothing import particle_smoothing_weights

    model = _oscillator(2)
    T, N = 50, 1500
    X, C, R, y = _observations(model, T, seed=7, rows=2)
    y[5] = y[9] = y[12] = y[20]        # no missing rows here: every frame measured
    Ri = np.linalg.inv(R)
    init = kalman.init_unknown(model)

    filtered, predicted = [], init
    for k in range(T):
        if k:
            predicted = kalman.predict(filtered[-1], model)
        z, S = _information(C, R, y[k])
        filtered.append(kalman.assimilate(predicted, z - S @ predicted.X, S))
    rts = rts_smooth(model, filtered).X
    kf = np.array([f.X for f in filtered])

    rng = np.random.default_rng(8)
    draws = rng.multivariate_normal(init.mean, init.cov, size=N)
    particles = cond.ParticleSet(draws[:, :2], draws[:, 2:], np.zeros(N))

    def loglik_at(k):
        def loglik(Xs):
            r = y[k] - Xs @ C.T
            return -0.5 * np.einsum("ni,ij,nj->n", r, Ri, r)
        return loglik

    prev, cur, logw = [], [], []
    for k in range(T):
        if k == 0:
            particles = cond.ParticleSet(particles.prev, particles.cur, loglik_at(0)(particles.cur))
        else:
            particles, _ = cond.step(particles, model, loglik_at(k), rng)
        prev.append(particles.prev)
        cur.append(particles.cur)
        logw.append(particles.log_w)
    weights = particle_smoothing_weights(prev, cur, logw, model)
    pf = np.array([np.exp(lw - lw.max()) / np.exp(lw - lw.max()).sum() @ c for lw, c in zip(logw, cur)])
    ps = np.array([w @ c for w, c in zip(weights, cur)])

    assert all(abs(w.sum() - 1) < 1e-9 and np.all(w >= 0) for w in weights)
    # the particle filter tracks the Kalman filter ...
    assert np.sqrt(np.mean((pf - kf) ** 2)) < 0.3 * np.sqrt(np.mean((kf - rts) ** 2))
    # ... and the particle smoother the RTS smoother, closer than the filters are to it
    # (the rest is Monte-Carlo error, which falls as N grows)
    assert np.sqrt(np.mean((ps - rts) ** 2)) < 0.5 * np.sqrt(np.mean((kf - rts) ** 2))
    # against the truth: as good as RTS, and better than filtering
    err_ps, err_pf, err_rts = (np.sqrt(np.mean((e - X) ** 2)) for e in (ps, pf, rts))
    assert err_ps < 1.1 * err_rts
    assert err_ps < 0.8 * err_pf


def test_particle_smoothing_needs_consecutive_sample_sets():
    from trackcli.trackers.smoothing import particle_smoothing_weights

    model = _oscillator(2)
    cur = [np.zeros((3, 2)), np.ones((3, 2))]
    prev = [np.zeros((3, 2)), np.full((3, 2), 5.0)]   # matches no sample of frame 0
    with pytest.raises(Exception, match="matches no sample"):
        particle_smoothing_weights(prev, cur, [np.zeros(3), np.zeros(3)], model)
