"""Tests of trackcli.dynamics.learning: maximum-likelihood AR(2) from pooled sequences (AC Fig 11.6)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.handset import oscillator_coefficients
from trackcli.errors import DataError
from trackcli.dynamics.learning import AR2Statistics, fit_ar2, stabilise

TAU = 0.04


def coupled_model() -> AR2:
    """Nx = 3: three designed oscillators mixed by a rotation, so every coefficient is coupled."""
    rng = np.random.default_rng(100)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    coeffs = [oscillator_coefficients(f, beta, 1.0, TAU) for f, beta in ((0.5, 2.0), (1.5, 4.0), (0.0, 3.0))]
    A1 = Q @ np.diag([c[0] for c in coeffs]) @ Q.T
    A2 = Q @ np.diag([c[1] for c in coeffs]) @ Q.T
    B0 = np.array([[0.5, 0.1, 0.0], [0.1, 0.4, 0.05], [0.0, 0.05, 0.3]])  # symmetric positive definite
    return AR2(A2, A1, B0, np.array([10.0, -5.0, 2.0]), TAU)


def stacked_least_squares(sequences):
    """Independent reference: regress X_k on (X_{k-2}, X_{k-1}, 1) over the triples of every sequence."""
    rows, targets = [], []
    for X in sequences:
        rows.append(np.hstack([X[:-2], X[1:-1], np.ones((len(X) - 2, 1))]))
        targets.append(X[2:])
    Z, Y = np.vstack(rows), np.vstack(targets)
    theta, *_ = np.linalg.lstsq(Z, Y, rcond=None)
    nx = Y.shape[1]
    resid = Y - Z @ theta
    return theta[:nx].T, theta[nx:2 * nx].T, theta[-1], resid.T @ resid / len(Y)


# ---------------------------------------------------------------------------------------------
# (a) recovery of known parameters


def test_recovers_known_model_from_pooled_sequences():
    truth = coupled_model()
    rng = np.random.default_rng(1)
    sequences = [truth.simulate(3000, rng, burn_in=300) for _ in range(4)]
    model, report = fit_ar2(sequences, TAU)
    n = report.n_triples
    assert (report.n_sequences, report.n_frames, n) == (4, 12000, 4 * 2998)

    # asymptotic standard errors: Cov(row i of [A2 A1]) = C_ii P∞⁻¹ / n, with P∞ the
    # steady-state covariance of the regressor (X_{k-2}; X_{k-1})
    C = truth.noise_covariance()
    P = truth.steady_state_covariance()
    se_coef = np.sqrt(np.outer(np.diag(C), np.diag(np.linalg.inv(P))) / n)
    coef_true = np.hstack([truth.A2, truth.A1])
    coef_hat = np.hstack([model.A2, model.A1])
    z = (coef_hat - coef_true) / se_coef
    assert np.abs(z).max() < 4.5, z
    assert se_coef.max() < 0.05  # enough data for the check to bite

    # mean: long-run covariance (I - A2 - A1)⁻¹ C (I - A2 - A1)⁻ᵀ / n
    Minv = np.linalg.inv(np.eye(3) - truth.A2 - truth.A1)
    se_mean = np.sqrt(np.diag(Minv @ C @ Minv.T) / n)
    assert np.abs((model.mean - truth.mean) / se_mean).max() < 4.5
    # noise covariance: Var(Ĉ_ij) = (C_ii C_jj + C_ij²) / n
    se_C = np.sqrt((np.outer(np.diag(C), np.diag(C)) + C**2) / n)
    assert np.abs((model.noise_covariance() - C) / se_C).max() < 4.5
    # B0 is the symmetric root of Ĉ, and the true B0 is symmetric: it comes back too
    np.testing.assert_allclose(model.B0, model.B0.T, atol=1e-12)
    np.testing.assert_allclose(model.B0, truth.B0, atol=0.012)  # about 4 standard errors
    assert report.stable and report.mean_source == "intercept" and report.stabilised == "no"
    assert report.residual_rms == pytest.approx(math.sqrt(np.trace(model.noise_covariance()) / 3))


# ---------------------------------------------------------------------------------------------
# (b) agreement with statsmodels


def test_single_sequence_matches_statsmodels_var():
    from statsmodels.tsa.api import VAR

    truth = coupled_model()
    X = truth.simulate(500, np.random.default_rng(2), burn_in=100)
    ref = VAR(X).fit(maxlags=2, trend="c")
    model, report = fit_ar2(X, TAU)
    # the book's Ĉ divides by the number of triples M - 2, as sigma_u_mle does (no count factor)
    np.testing.assert_allclose(model.A1, ref.coefs[0], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(model.A2, ref.coefs[1], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(report.intercept, ref.intercept, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(model.noise_covariance(), ref.sigma_u_mle, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(model.mean, np.linalg.solve(np.eye(3) - model.A2 - model.A1, ref.intercept),
                               rtol=1e-8)
    assert report.log_likelihood == pytest.approx(ref.llf, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# (c) pooling, not concatenating


def test_pooling_equals_stacked_least_squares_and_differs_from_concatenation():
    truth = coupled_model()
    rng = np.random.default_rng(3)
    first = truth.simulate(600, rng, burn_in=100)
    # the second clip starts far from where the first ends: a join would look like a jump
    second = truth.simulate(400, rng, x0=truth.mean + 30.0)
    pooled_stats = AR2Statistics.from_sequence(first) + AR2Statistics.from_sequence(second)
    model, report = fit_ar2(pooled_stats, TAU)
    A2, A1, D, C = stacked_least_squares([first, second])
    np.testing.assert_allclose(model.A2, A2, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(model.A1, A1, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(report.intercept, D, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(model.noise_covariance(), C, rtol=1e-9, atol=1e-12)
    assert report.n_triples == 598 + 398

    # a list of sequences is pooled the same way
    listed, _ = fit_ar2([first, second], TAU)
    np.testing.assert_allclose(listed.A1, model.A1, rtol=1e-12)

    joined, joined_report = fit_ar2(np.vstack([first, second]), TAU)
    assert joined_report.n_triples == report.n_triples + 2
    assert np.abs(joined.A1 - model.A1).max() > 1e-3
    # the spurious jump at the join is taken for driving noise
    assert np.trace(joined.noise_covariance()) > 1.2 * np.trace(model.noise_covariance())


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), lengths=st.lists(st.integers(0, 30), min_size=1, max_size=4),
       nx=st.integers(1, 3))
def test_statistics_add_like_their_sums(seed, lengths, nx):
    rng = np.random.default_rng(seed)
    seqs = [rng.standard_normal((m, nx)) * 5 + 2 for m in lengths]
    stats = [AR2Statistics.from_sequence(s) for s in seqs]
    total = sum(stats)
    assert total.count == sum(max(m - 2, 0) for m in lengths)
    assert total.n_sequences == len(lengths) and total.n_frames == sum(lengths)
    for i in range(3):
        ref = sum((s[2 - i: len(s) - i].sum(axis=0) for s in seqs if len(s) > 2), np.zeros(nx))
        np.testing.assert_allclose(total.R(i), ref, atol=1e-9)
        for j in range(3):
            ref = sum((s[2 - i: len(s) - i].T @ s[2 - j: len(s) - j] for s in seqs if len(s) > 2),
                      np.zeros((nx, nx)))
            np.testing.assert_allclose(total.Rij(i, j), ref, atol=1e-8)
    reverse = sum(reversed(stats))
    np.testing.assert_allclose(reverse.products, total.products, atol=1e-8)


def test_rprime_is_centred_product():
    X = np.random.default_rng(4).standard_normal((40, 2)) + 7.0
    s = AR2Statistics.from_sequence(X)
    lag0, lag1 = X[2:], X[1:-1]
    expected = (lag0 - lag0.mean(axis=0)).T @ (lag1 - lag1.mean(axis=0))
    np.testing.assert_allclose(s.Rprime(0, 1), expected, atol=1e-9)


def test_statistics_of_different_dimensions_do_not_pool():
    a = AR2Statistics.from_sequence(np.zeros((5, 2)))
    b = AR2Statistics.from_sequence(np.zeros((5, 3)))
    with pytest.raises(DataError, match="pool"):
        a + b


# ---------------------------------------------------------------------------------------------
# (d) the univariate algorithms


def univariate_signal(n: int, seed: int) -> np.ndarray:
    a1, a2, b0 = oscillator_coefficients(1.0, 3.0, 2.0, 1 / 50)  # lip-like: about 1 Hz
    model = AR2([[a2]], [[a1]], [[b0]], [0.0], 1 / 50)
    return model.simulate(n, np.random.default_rng(seed), burn_in=200)[:, 0]


def test_univariate_known_mean_matches_fig_11_2():
    x = univariate_signal(1500, 5)
    m = len(x)
    r = {(i, j): float(np.sum(x[2 - i: m - i] * x[2 - j: m - j])) for i in range(3) for j in range(3)}
    # step 2 of AC Fig 11.2, solved by Cramer's rule
    det = r[2, 2] * r[1, 1] - r[1, 2] * r[2, 1]
    a2 = (r[0, 2] * r[1, 1] - r[0, 1] * r[1, 2]) / det
    a1 = (r[0, 1] * r[2, 2] - r[0, 2] * r[2, 1]) / det
    b0_sq = (r[0, 0] - a2 * r[2, 0] - a1 * r[1, 0]) / (m - 2)  # step 3
    model, report = fit_ar2(x, 1 / 50, mean=[0.0])
    assert model.A2[0, 0] == pytest.approx(a2, rel=1e-10)
    assert model.A1[0, 0] == pytest.approx(a1, rel=1e-10)
    assert model.B0[0, 0] ** 2 == pytest.approx(b0_sq, rel=1e-10)
    assert report.mean_source == "given" and model.mean[0] == 0.0


def test_univariate_unknown_mean_matches_scalar_fig_11_6():
    x = univariate_signal(800, 6) + 40.0
    m = len(x)
    R = {i: float(np.sum(x[2 - i: m - i])) for i in range(3)}
    Rij = {(i, j): float(np.sum(x[2 - i: m - i] * x[2 - j: m - j])) for i in range(3) for j in range(3)}
    Rp = {k: Rij[k] - R[k[0]] * R[k[1]] / (m - 2) for k in Rij}
    a2 = (Rp[0, 2] - Rp[0, 1] * Rp[1, 2] / Rp[1, 1]) / (Rp[2, 2] - Rp[2, 1] * Rp[1, 2] / Rp[1, 1])
    a1 = (Rp[0, 1] - a2 * Rp[2, 1]) / Rp[1, 1]
    d = (R[0] - a2 * R[2] - a1 * R[1]) / (m - 2)
    c = (Rij[0, 0] - a2 * Rij[2, 0] - a1 * Rij[1, 0] - d * R[0]) / (m - 2)
    model, report = fit_ar2(x, 1 / 50)
    assert model.A2[0, 0] == pytest.approx(a2, rel=1e-8)
    assert model.A1[0, 0] == pytest.approx(a1, rel=1e-8)
    assert report.intercept[0] == pytest.approx(d, rel=1e-8)
    assert model.mean[0] == pytest.approx(d / (1 - a2 - a1), rel=1e-8)
    assert model.noise_covariance()[0, 0] == pytest.approx(c, rel=1e-7)


def test_learned_modes_recover_designed_frequency_and_damping():
    """AC §11.1: relative error in β and f is of order 1/sqrt(βT) for a training set of T seconds."""
    tau, f, beta = 1 / 50, 1.0, 3.0
    x = univariate_signal(15000, 7)
    model, _ = fit_ar2(x, tau)
    (mode,) = model.modes()
    order = 1 / math.sqrt(beta * (len(x) - 2) * tau)  # ≈ 0.033
    assert abs(mode.beta / beta - 1) < 3 * order
    assert abs(mode.frequency - f) / beta < 3 * order


# ---------------------------------------------------------------------------------------------
# errors and awkward data


def test_too_few_frames():
    X = np.random.default_rng(8).standard_normal((9, 3))  # 7 triples = 2·Nx + 1: not enough
    with pytest.raises(DataError, match=r"must exceed 2·Nx\+1 = 7, got 7") as info:
        fit_ar2(X, TAU)
    assert "frame triples" in str(info.value)
    X = np.random.default_rng(8).standard_normal((10, 3))
    model, report = fit_ar2(X, TAU)
    assert report.n_triples == 8 and np.all(np.isfinite(model.A1))


def test_too_few_frames_counts_triples_per_sequence():
    rng = np.random.default_rng(9)
    pieces = [rng.standard_normal((4, 2)) for _ in range(2)]  # 2 + 2 triples, though 8 frames
    with pytest.raises(DataError, match="got 4 from 2 sequence"):
        fit_ar2(pieces, TAU)


def test_constant_component_is_singular():
    rng = np.random.default_rng(10)
    X = rng.standard_normal((200, 3))
    X[:, 1] = 312.5  # a component that never moves
    with pytest.raises(DataError, match=r"X\[1\] never change"):
        fit_ar2(X, TAU)


def test_dependent_components_are_singular():
    rng = np.random.default_rng(11)
    X = rng.standard_normal((200, 2)).cumsum(axis=0)
    X = np.hstack([X, X[:, :1] * 2.0 - X[:, 1:] + 4.0])  # third is a fixed combination
    with pytest.raises(DataError, match="linearly dependent"):
        fit_ar2(X, TAU)


def test_non_finite_frames_are_rejected():
    X = np.random.default_rng(12).standard_normal((50, 2))
    X[17, 0] = np.nan
    with pytest.raises(DataError, match="frame.s. 17"):
        fit_ar2(X, TAU)


def test_bad_arguments():
    X = np.random.default_rng(13).standard_normal((50, 2))
    with pytest.raises(DataError, match="tau"):
        fit_ar2(X, 0.0)
    with pytest.raises(DataError, match="max_spectral_radius"):
        fit_ar2(X, TAU, enforce_stability=True, max_spectral_radius=1.2)
    with pytest.raises(DataError, match="mean"):
        fit_ar2(X, TAU, mean=[0.0])
    with pytest.raises(DataError, match="no training sequences"):
        fit_ar2([], TAU)


def test_constant_acceleration_has_no_mean():
    """x_k = k² satisfies x_k - 2x_{k-1} + x_{k-2} = 2 exactly: I - Â2 - Â1 = 0 and X̄ is undefined."""
    x = np.arange(60.0) ** 2 / 100.0
    model, report = fit_ar2(x, TAU)
    assert model.A1[0, 0] == pytest.approx(2.0, abs=1e-6)
    assert model.A2[0, 0] == pytest.approx(-1.0, abs=1e-6)
    assert report.mean_source == "data"
    assert model.mean[0] == pytest.approx(np.mean(x[2:]), rel=1e-9)
    # the constant second difference 0.02 cannot be expressed with a mean; it becomes noise
    assert report.dropped_drift == pytest.approx(0.02, rel=1e-4)
    assert model.B0[0, 0] == pytest.approx(0.02, rel=1e-3)
    assert report.intercept[0] == pytest.approx(0.0, abs=1e-9)


# ---------------------------------------------------------------------------------------------
# stability enforcement


def drifting_and_oscillating(rng: np.random.Generator, n: int) -> np.ndarray:
    """Component 0: a random walk with drift (unit root); component 1: a stable oscillator."""
    a1, a2, b0 = oscillator_coefficients(1.0, 4.0, 3.0, TAU)
    osc = AR2([[a2]], [[a1]], [[b0]], [0.0], TAU).simulate(n, rng, burn_in=100)[:, 0]
    walk = np.cumsum(0.3 + rng.standard_normal(n))
    return np.column_stack([walk, osc])


def test_enforce_stability_pulls_in_only_the_offending_modes():
    X = drifting_and_oscillating(np.random.default_rng(14), 3000)
    free, free_report = fit_ar2(X, TAU)
    assert free_report.spectral_radius > 0.99
    model, report = fit_ar2(X, TAU, enforce_stability=True, max_spectral_radius=0.99)
    assert report.stabilised == "modes"
    assert report.unconstrained_spectral_radius == pytest.approx(free_report.spectral_radius)
    assert report.spectral_radius == pytest.approx(0.99, abs=1e-9) and report.stable
    after = model.modes()
    for mode in after:
        old = min(free.modes(), key=lambda m: abs(m.frequency - mode.frequency) + abs(m.modulus - mode.modulus))
        if old.modulus <= 0.99:  # untouched modes keep their eigenvalues and shapes
            assert mode.eigenvalue == pytest.approx(old.eigenvalue, abs=1e-8)
            np.testing.assert_allclose(np.abs(mode.shape), np.abs(old.shape), atol=1e-6)
    assert any(m.modulus == pytest.approx(0.99, abs=1e-9) for m in after)
    # D and C are the conditional maximum-likelihood values for the new A2, A1
    resid = X[2:] - X[:-2] @ model.A2.T - X[1:-1] @ model.A1.T
    D = resid.mean(axis=0)
    np.testing.assert_allclose(report.intercept, D, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(model.noise_covariance(), (resid - D).T @ (resid - D) / len(resid), rtol=1e-8)
    np.testing.assert_allclose((np.eye(2) - model.A2 - model.A1) @ model.mean, D, rtol=1e-8, atol=1e-10)
    # a stationary model fits a drifting walk worse: the likelihood must drop
    assert report.log_likelihood < free_report.log_likelihood


def test_enforce_stability_leaves_stable_fits_alone():
    truth = coupled_model()
    X = truth.simulate(800, np.random.default_rng(15), burn_in=100)
    free, _ = fit_ar2(X, TAU)
    model, report = fit_ar2(X, TAU, enforce_stability=True, max_spectral_radius=0.99)
    assert report.stabilised == "no"
    np.testing.assert_array_equal(model.A1, free.A1)
    np.testing.assert_array_equal(model.B0, free.B0)


def test_stabilise_scales_a_defective_model():
    """Constant velocity has a repeated, defective eigenvalue 1: all eigenvalues are scaled."""
    A2, A1, how = stabilise(-np.eye(2), 2 * np.eye(2), 0.95)
    assert how == "scaled"
    np.testing.assert_allclose(A1, 2 * 0.95 * np.eye(2))
    np.testing.assert_allclose(A2, -(0.95**2) * np.eye(2))
    model = AR2(A2, A1, np.eye(2), np.zeros(2), TAU)
    assert model.spectral_radius() == pytest.approx(0.95)
