"""The steps of mode-based multiple hypotheses (trackcli.trackers.modes, paper 004)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.errors import ConfigError
from trackcli.dynamics import kalman
from trackcli.trackers import modes
from trackcli.dynamics.kalman import KalmanState

FAST = settings(max_examples=60, deadline=None)


def _state(X: np.ndarray, var: float = 4.0) -> KalmanState:
    nx = X.size
    return KalmanState(np.concatenate([X, X]), var * np.eye(2 * nx) + np.kron(np.ones((2, 2)), np.eye(nx)))


# --------------------------------------------------------------------------------------------- merging


@FAST
@given(
    st.integers(1, 40).flatmap(lambda n: st.tuples(
        st.lists(st.lists(st.floats(-20, 20), min_size=2, max_size=2), min_size=n, max_size=n),
        st.lists(st.floats(-50, 5), min_size=n, max_size=n))),
    st.floats(0.1, 10.0),
    st.integers(1, 6),
)
def test_merging_keeps_the_number_of_modes_bounded_and_apart(data, distance, keep):
    X, log_w = np.array(data[0]), np.array(data[1])
    kept = modes.merge_modes(X, log_w, np.eye(2), distance, keep)
    assert 1 <= kept.size <= keep
    assert kept.size == np.unique(kept).size
    # the heaviest hypothesis is always a mode, and modes come heaviest first
    assert log_w[kept[0]] == log_w.max()
    assert np.all(np.diff(log_w[kept]) <= 0)
    # modes are pairwise at least `distance` apart
    d = np.linalg.norm(X[kept][:, None] - X[kept][None], axis=-1)
    assert np.all(d[~np.eye(kept.size, dtype=bool)] >= distance - 1e-9)
    # while fewer than `keep` modes, every hypothesis lies in the merge radius of one
    if kept.size < keep:
        near = np.linalg.norm(X[:, None] - X[kept][None], axis=-1).min(axis=1)
        assert np.all(near < distance + 1e-9)


def test_merging_uses_the_shape_space_metric():
    X = np.array([[0.0, 0.0], [0.0, 1.0]])
    log_w = np.array([0.0, -1.0])
    # 1 unit of the second coordinate moves the curve by 3 px under this metric
    H = np.diag([1.0, 9.0])
    assert modes.merge_modes(X, log_w, H, 2.0, 5).tolist() == [0, 1]
    assert modes.merge_modes(X, log_w, np.eye(2), 2.0, 5).tolist() == [0]


def test_merge_rejects_bad_settings():
    with pytest.raises(ConfigError, match="merge_distance"):
        modes.merge_modes(np.zeros((2, 2)), np.zeros(2), np.eye(2), 0.0, 3)
    with pytest.raises(ConfigError, match="modes"):
        modes.merge_modes(np.zeros((2, 2)), np.zeros(2), np.eye(2), 1.0, 0)


# --------------------------------------------------------------------------------------------- seeds


def test_seeds_start_at_the_modes_and_stay_in_their_cells():
    means = np.array([[0.0, 0.0], [6.0, 0.0]])
    covs = np.stack([4.0 * np.eye(2), 4.0 * np.eye(2)])
    log_w = np.log([0.7, 0.3])
    seeds, parent = modes.draw_seeds(means, covs, log_w, 400, np.random.default_rng(1))
    assert np.array_equal(seeds[:2], means) and parent[:2].tolist() == [0, 1]
    assert 300 < seeds.shape[0] <= 400
    owner = np.argmax(modes.component_log_density(seeds, means, modes.precisions(covs), log_w), axis=1)
    assert np.array_equal(owner, parent)
    # the heavier mode is chosen more often
    assert np.mean(parent[2:] == 0) > 0.6
    again, _ = modes.draw_seeds(means, covs, log_w, 400, np.random.default_rng(1))
    assert np.array_equal(seeds, again)


def test_seeds_without_truncation_are_all_drawn():
    seeds, parent = modes.draw_seeds(np.zeros((1, 3)), np.eye(3)[None], np.zeros(1), 50, np.random.default_rng(0),
                                     truncate=False, spread=2.0)
    assert seeds.shape == (50, 3) and np.all(parent == 0)
    assert 1.4 < seeds[1:].std() < 2.6


def test_seeds_refuse_fewer_than_the_modes():
    with pytest.raises(ConfigError, match="n >= K"):
        modes.draw_seeds(np.zeros((3, 2)), np.stack([np.eye(2)] * 3), np.zeros(3), 2, np.random.default_rng(0))


# --------------------------------------------------------------------------------------------- refinement


def _linear_measure(target: np.ndarray, info: float):
    """Every coordinate observed directly, the truth at ``target``: Z = S (target - X)."""

    def measure(X, P):
        S = np.broadcast_to(info * np.eye(X.shape[1]), (X.shape[0], X.shape[1], X.shape[1])).copy()
        Z = np.einsum("nij,nj->ni", S, target - X)
        return Z, S

    return measure


def test_one_step_from_the_prediction_is_the_kalman_update():
    prior = _state(np.array([1.0, -2.0]))
    measure = _linear_measure(np.array([3.0, 0.5]), 0.5)
    (state,) = modes.refine([prior], prior.X[None], measure, 1)
    Z, S = measure(prior.X[None], prior.P[None])
    expected = kalman.assimilate(prior, Z[0], S[0])
    assert np.allclose(state.mean, expected.mean) and np.allclose(state.cov, expected.cov)


def test_a_linear_measurement_gives_one_answer_from_any_seed():
    prior = _state(np.array([0.0, 0.0]))
    measure = _linear_measure(np.array([3.0, 1.0]), 0.5)
    seeds = np.array([[0.0, 0.0], [5.0, -4.0], [-3.0, 2.0]])
    out = modes.refine([prior] * 3, seeds, measure, 3)
    X = np.stack([s.X for s in out])
    assert np.allclose(X, X[0])


def test_seeds_climb_to_different_maxima():
    """Two features along one axis, each curve measuring the one nearer to it: two modes."""
    targets = np.array([-5.0, 5.0])

    def measure(X, P):
        nearest = targets[np.argmin(np.abs(X[:, :1] - targets[None]), axis=1)]
        S = np.zeros((X.shape[0], 1, 1))
        S[:] = 4.0
        return 4.0 * (nearest - X[:, 0])[:, None], S

    prior = KalmanState(np.zeros(2), np.diag([100.0, 100.0]))
    out = modes.refine([prior] * 4, np.array([[-3.0], [-1.0], [2.0], [7.0]]), measure, 4)
    X = np.array([s.X[0] for s in out])
    assert np.allclose(X[:2], -5.0, atol=0.1) and np.allclose(X[2:], 5.0, atol=0.1)
    kept = modes.merge_modes(X[:, None], np.zeros(4), np.eye(1), 1.0, 10)
    assert kept.size == 2


def test_weights_are_the_prior_mode_weight_times_the_likelihood():
    w = modes.hypothesis_log_weights(np.array([0, 1, 1]), np.log([0.2, 0.8]), np.array([2.0, 3.0, 1.0]))
    assert np.allclose(w, [np.log(0.2) + 2.0, np.log(0.8) + 3.0, np.log(0.8) + 1.0])
    assert np.isclose(np.exp(modes.normalise_log(w)).sum(), 1.0)
