"""EM learning of AR(2) dynamics from noisy measurements (trackcli.dynamics.em).

Evidence: on a known AR(2) model with a coherent oscillation observed with noise, EM
recovers frequency, damping and B0 closer to the truth than maximum likelihood on the same
noisy shapes, and its log-likelihood never decreases.
"""

from __future__ import annotations

import numpy as np
import pytest

from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.handset import oscillator_coefficients
from trackcli.dynamics.em import InformationSequence, expected_statistics, fit_ar2_em
from trackcli.errors import DataError
from trackcli.dynamics.learning import AR2Statistics, fit_ar2
from trackcli.dynamics.rts import filter_information, smooth_filtered

TAU = 0.04
F_TRUE, BETA_TRUE, RHO_TRUE = 1.0, 0.5, 10.0
SIGMA = 2.0


def _truth() -> AR2:
    a1, a2, b0 = oscillator_coefficients(F_TRUE, BETA_TRUE, RHO_TRUE, TAU)
    return AR2(a2 * np.eye(2), a1 * np.eye(2), b0 * np.eye(2), np.array([120.0, 80.0]), TAU)


def _noisy(seed: int, n_seq: int = 2, frames: int = 250):
    """Paths of the true model (stationary start) and the same paths with N(0, SIGMA²) noise."""
    rng = np.random.default_rng(seed)
    truth = _truth()
    clean = [truth.simulate(frames, rng, burn_in=200) for _ in range(n_seq)]
    noisy = [X + SIGMA * rng.standard_normal(X.shape) for X in clean]
    return clean, noisy


def _mode_errors(model: AR2) -> tuple[float, float]:
    """Largest frequency and damping errors over the model's modes, against the truth."""
    modes = model.modes()
    return (max(abs(m.frequency - F_TRUE) for m in modes), max(abs(m.beta - BETA_TRUE) for m in modes))


@pytest.mark.parametrize("seed", [0, 1])
def test_em_recovers_a_coherent_oscillation_better_than_mle(seed):
    _, noisy = _noisy(seed)
    truth = _truth()
    mle, _ = fit_ar2(noisy, TAU)
    seqs = [InformationSequence.from_shapes(Y, np.full(Y.shape, SIGMA)) for Y in noisy]
    em, report, info = fit_ar2_em(seqs, TAU)

    f_mle, beta_mle = _mode_errors(mle)
    f_em, beta_em = _mode_errors(em)
    b0_mle = np.linalg.norm(mle.B0 - truth.B0)
    b0_em = np.linalg.norm(em.B0 - truth.B0)
    assert f_em < f_mle and beta_em < beta_mle and b0_em < b0_mle
    # and close to the truth in absolute terms: every mode a ~1 Hz oscillation, lightly damped
    assert f_em < 0.15 and beta_em < 0.6
    assert b0_em < 0.3 * np.linalg.norm(truth.B0)
    np.testing.assert_allclose(em.mean, truth.mean, atol=5.0)
    assert info.converged and info.iterations >= 2
    assert report.log_likelihood == info.log_likelihood[-1]


@pytest.mark.parametrize("seed", [2, 3])
def test_em_log_likelihood_never_decreases(seed):
    _, noisy = _noisy(seed, n_seq=1, frames=200)
    seqs = [InformationSequence.from_shapes(Y, np.full(Y.shape, SIGMA)) for Y in noisy]
    _, _, info = fit_ar2_em(seqs, TAU, tolerance=1e-7, max_iterations=60)
    path = np.array(info.log_likelihood)
    assert path.size >= 10
    gains = np.diff(path)
    assert np.all(gains >= -1e-9 * np.abs(path[1:])), gains.min()
    assert path[-1] > path[0] + 10.0       # EM moved well away from the MLE start


def test_each_em_step_raises_the_likelihood_of_any_start():
    """Monotone from a poor start too (the hand-set kind: a slow critically damped model)."""
    _, noisy = _noisy(4, n_seq=1, frames=150)
    seqs = [InformationSequence.from_shapes(Y, np.full(Y.shape, SIGMA)) for Y in noisy]
    a1, a2, b0 = oscillator_coefficients(0.0, 2.0, 30.0, TAU)
    start = AR2(a2 * np.eye(2), a1 * np.eye(2), b0 * np.eye(2), noisy[0].mean(axis=0), TAU)
    _, _, info = fit_ar2_em(seqs, TAU, init=start, max_iterations=15, tolerance=1e-9)
    assert np.all(np.diff(info.log_likelihood) >= -1e-9 * np.abs(np.array(info.log_likelihood[1:])))
    assert info.iterations == 15 and not info.converged


def test_expected_statistics_tend_to_the_plain_sums_for_exact_measurements():
    clean, _ = _noisy(5, n_seq=1, frames=80)
    X = clean[0]
    seq = InformationSequence.from_shapes(X, np.full(X.shape, 1e-5))
    filtered, _ = filter_information(_truth(), seq.prior(), seq.z, seq.S)
    stats = expected_statistics(smooth_filtered(_truth(), filtered), seq.frames)
    plain = AR2Statistics.from_sequence(X)
    assert stats.count == plain.count == X.shape[0] - 2
    np.testing.assert_allclose(stats.sums, plain.sums, rtol=1e-7)
    np.testing.assert_allclose(stats.products, plain.products, rtol=1e-7)


def test_lost_frames_carry_no_measurement():
    clean, noisy = _noisy(6, n_seq=1, frames=60)
    lost = np.zeros(60, dtype=bool)
    lost[20:25] = True
    seq = InformationSequence.from_shapes(noisy[0], np.full((60, 2), SIGMA), lost=lost)
    assert not seq.S[20:25].any() and not seq.z[20:25].any()
    np.testing.assert_allclose(seq.S[0], np.eye(2) / SIGMA**2)
    filtered, _ = filter_information(_truth(), seq.prior(), seq.z, seq.S)
    smoothed = smooth_filtered(_truth(), filtered)
    # the gap is bridged by the dynamics: the smoothed shapes there stay near the truth
    assert np.abs(smoothed.X[19:24] - clean[0][20:25]).max() < 6 * SIGMA


def test_from_shapes_refuses_missing_uncertainty():
    X = np.zeros((5, 2))
    std = np.ones((5, 2))
    std[3, 1] = 0.0
    with pytest.raises(DataError, match="row\\(s\\) 3"):
        InformationSequence.from_shapes(X, std)
    # ... unless that frame is lost anyway
    lost = np.zeros(5, dtype=bool)
    lost[3] = True
    assert not InformationSequence.from_shapes(X, std, lost=lost).S[3].any()


def test_em_needs_a_usable_sequence():
    seq = InformationSequence.from_shapes(np.zeros((2, 2)), np.ones((2, 2)))
    with pytest.raises(DataError, match="3 frames"):
        fit_ar2_em([seq], TAU)
