"""Mixed-state CONDENSATION (001 §8): model files, the filter's label posterior, the bounce,
learning from labelled ranges, and the bouncing-ball experiment on the sample clip."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from conftest import REPO, sample_clip
from trackcli.cli import cli
from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.mixed import (check_transitions, learn_mixed, load_mixed, mixed_from_dict, read_label_ranges,
                                     stationary_distribution, transitions_from_labels)
from trackcli.dynamics.mixed_dynamics import Bounce, MixedDynamics, MixedPrediction
from trackcli.errors import ModelError
from trackcli.settings import Settings
from trackcli.run.bounces import detections, match, run_experiment, true_bounces
from trackcli.trackers import condensation as cond

EXAMPLES = REPO / "examples"


def _ball_model(**bounce) -> dict:
    return {"format": 1, "kind": "trackcli-mixed",
            "labels": [{"name": "flight", "dynamics": {"translation": {"f": 0, "beta": 0, "rho": None, "gamma0": 6}}},
                       {"name": "bounce", "bounce": {"base": "flight", "floor": 300, **bounce}}],
            "transitions": [[0.9, 0.1], [1.0, 0.0]]}


# ---------------------------------------------------------------------------------------------
# Model files


@pytest.mark.parametrize("T, message", [
    ([[0.9, 0.2], [1.0, 0.0]], "transitions[0]: the probabilities of leaving label 0 must sum to 1"),
    ([[1.2, -0.2], [1.0, 0.0]], "transitions[0][0]: a probability must lie in [0, 1]"),
    ([[0.5, 0.5]], "transitions: expected 2 rows"),
    ([[0.5, 0.5], [1.0]], "transitions[1]: expected a row of 2 probabilities"),
    ([[0.5, "x"], [1.0, 0.0]], "transitions[0][1]: expected a probability"),
])
def test_a_bad_transition_matrix_is_refused_with_its_key_path(T, message):
    d = _ball_model()
    d["transitions"] = T
    with pytest.raises(ModelError, match=message.replace("[", r"\[").replace("]", r"\]")):
        mixed_from_dict(d)


@pytest.mark.parametrize("change, message", [
    (lambda d: d["labels"][1]["bounce"].update(base="nothing"), r"labels\[1\]\.bounce\.base: 'nothing' is not"),
    (lambda d: d["labels"][1].update(name="flight"), "names must be unique"),
    (lambda d: d["labels"][0].update(bounce={"base": "x", "floor": 1}), r"labels\[0\] \(flight\): give exactly one"),
    (lambda d: d["labels"][0]["dynamics"]["translation"].update(beta=-1),
     r"labels\[0\]\.dynamics\.translation\.beta"),
    (lambda d: d["labels"][1]["bounce"].update(line={"point": [0, 1], "normal": [0, -1]}), "exactly one of floor"),
    (lambda d: d["labels"][1]["bounce"].update(restitution=1.5), r"labels\[1\]\.bounce\.restitution"),
    (lambda d: d["labels"].pop(), "at least two labels"),
    (lambda d: d.update(initial=[0.5, 0.6]), "initial: the probabilities must sum to 1"),
])
def test_a_bad_mixed_model_names_the_key(change, message):
    d = _ball_model()
    change(d)
    with pytest.raises(ModelError, match=message):
        mixed_from_dict(d)


def test_the_cli_refuses_a_bad_model_in_one_line(tmp_path):
    d = _ball_model()
    d["transitions"] = [[0.9, 0.2], [1.0, 0.0]]
    bad = tmp_path / "bad.mixed.yaml"
    bad.write_text(yaml.safe_dump(d))
    res = CliRunner().invoke(cli, ["inspect", str(bad)])
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    assert "transitions[0]" in res.output and len(res.output.strip().splitlines()) == 1


def test_stationary_distribution_of_the_bounce_chain():
    eps = 0.1
    pi = stationary_distribution(np.array([[1 - eps, eps], [1.0, 0.0]]))
    np.testing.assert_allclose(pi, [1 / (1 + eps), eps / (1 + eps)], atol=1e-12)


@given(st.lists(st.integers(0, 2), min_size=2, max_size=60))
def test_transitions_counted_from_labels_are_stochastic_and_reproduce_the_counts(seq):
    T, counts = transitions_from_labels([np.array(seq)], 3)
    np.testing.assert_allclose(T.sum(axis=1), 1.0)
    assert counts.sum() == len(seq) - 1
    for i in range(3):
        if counts[i].sum():
            np.testing.assert_allclose(T[i], counts[i] / counts[i].sum())
    check_transitions(T.tolist(), 3)


def test_label_draws_follow_T():
    T = np.array([[0.7, 0.2, 0.1], [0.0, 0.5, 0.5], [1.0, 0.0, 0.0]])
    ar = AR2(np.zeros((1, 1)), np.eye(1), np.eye(1), np.zeros(1), 0.04)
    dyn = MixedDynamics(("a", "b", "c"), (ar, ar, ar), T, stationary_distribution(T), np.zeros(2), 0.04)
    rng = np.random.default_rng(0)
    n = 40000
    for i in range(3):
        new = dyn.draw_labels(np.full(n, i), rng)
        freq = np.bincount(new, minlength=3) / n
        np.testing.assert_allclose(freq, T[i], atol=4 * math.sqrt(0.25 / n))


def test_the_example_flight_settings_equal_the_flight_label():
    mixed = yaml.safe_load((EXAMPLES / "bouncing_ball.mixed.yaml").read_text())
    single = yaml.safe_load((EXAMPLES / "bouncing_ball.flight.yaml").read_text())
    assert mixed["labels"][0]["name"] == "flight"
    assert mixed["labels"][0]["dynamics"] == single["dynamics"]
    settings = yaml.safe_load((EXAMPLES / "bouncing_ball.settings.yaml").read_text())
    assert settings["jumps"] == single["jumps"]  # only the dynamics differ
    load_mixed(EXAMPLES / "bouncing_ball.mixed.yaml")


# ---------------------------------------------------------------------------------------------
# The bounce


def _bounce(restitution=0.8, noise=0.0, friction=1.0):
    # floor y = 300, outline's lowest point 10 px below the reference point
    return Bounce(0, np.array([0.0, 300.0]), np.array([0.0, -1.0]), restitution, friction, noise, 10.0)


def test_a_step_through_the_floor_is_reflected_with_restitution():
    b = _bounce(restitution=0.8)
    origin = np.array([100.0, 200.0])
    # reference point at y = 280 moving down 20 px/frame and right 2: the free step ends at
    # y = 300, the outline's bottom at 310, 10 px through the floor
    prev = np.array([[-2.0, 60.0]])
    cur = np.array([[0.0, 80.0]])
    prev_out, new, hit = b.predict(prev, cur, cur + [[2.0, 20.0]], np.zeros((1, 2)), origin, np.random.default_rng(0))
    assert hit.tolist() == [True]
    np.testing.assert_allclose(new[0] + origin, [102.0, 300.0 - 1.8 * 10.0])  # mirrored with restitution
    np.testing.assert_allclose(new[0] - prev_out[0], [2.0, -0.8 * 20.0])  # velocity reversed and scaled


def test_a_step_that_does_not_reach_the_floor_is_no_bounce():
    b = _bounce()
    origin = np.zeros(2)
    prev, cur = np.array([[0.0, 100.0]]), np.array([[0.0, 110.0]])
    base = cur + [[0.0, 10.0]]
    prev_out, new, hit = b.predict(prev, cur, base, np.zeros((1, 2)), origin, np.random.default_rng(0))
    assert hit.tolist() == [False]
    # moving up towards nothing, or down short of the floor: the caller gives it zero weight
    prev_up, cur_up = np.array([[0.0, 300.0]]), np.array([[0.0, 285.0]])
    _, _, hit_up = b.predict(prev_up, cur_up, cur_up, np.zeros((1, 2)), origin, np.random.default_rng(0))
    assert hit_up.tolist() == [False]


def test_mixed_prediction_kills_bounces_that_cannot_happen():
    ar = AR2(np.diag([-1.0, -1.0]), np.diag([2.0, 2.0]), np.zeros((2, 2)), np.zeros(2), 0.04)
    dyn = MixedDynamics(("flight", "bounce"), (ar, _bounce()), np.array([[0.0, 1.0], [1.0, 0.0]]),
                        np.array([1.0, 0.0]), np.zeros(2), 0.04)
    prev = np.array([[0.0, 100.0], [0.0, 275.0]])
    cur = np.array([[0.0, 110.0], [0.0, 285.0]])
    _, new, log_w = dyn.predict(prev, cur, np.array([1, 1]), np.random.default_rng(0))
    assert log_w[0] == -np.inf and log_w[1] == 0.0  # the first is 180 px above the floor
    np.testing.assert_allclose(new[1], [0.0, 295.0 - 1.8 * 5.0])  # free step to 295, bottom 5 px through


# ---------------------------------------------------------------------------------------------
# The label posterior against an exact filter


def _switching_models():
    # two AR(1) regimes about -2 and +2 (A2 = 0), observed in unit Gaussian noise
    a, sigma = 0.7, 0.6
    models = tuple(AR2(np.zeros((1, 1)), np.array([[a]]), np.array([[sigma]]), np.array([mu]), 0.04)
                   for mu in (-2.0, 2.0))
    T = np.array([[0.9, 0.1], [0.15, 0.85]])
    return models, T, a, sigma


def _forward(z, models, T, init_label, x_grid, x0_sd, r):
    """Exact filter over (label, discretised x): P(label that moved x_k | z_0..k) per frame."""
    dx = x_grid[1] - x_grid[0]
    kern = []
    for m in models:
        mu, a, s = float(m.mean[0]), float(m.A1[0, 0]), float(m.B0[0, 0])
        mean = mu + a * (x_grid[None, :] - mu)  # from x' (columns) to x (rows)
        kern.append(np.exp(-0.5 * ((x_grid[:, None] - mean) / s) ** 2) / (s * math.sqrt(2 * math.pi)) * dx)
    lik = lambda zk: np.exp(-0.5 * ((zk - x_grid) / r) ** 2)  # noqa: E731
    alpha = init_label[:, None] * np.exp(-0.5 * (x_grid / x0_sd) ** 2)[None, :] * lik(z[0])[None, :]
    alpha /= alpha.sum()
    out = [init_label.copy()]
    for zk in z[1:]:
        pred = np.stack([kern[j] @ (T[:, j] @ alpha) for j in range(len(models))])
        alpha = pred * lik(zk)[None, :]
        alpha /= alpha.sum()
        out.append(alpha.sum(axis=1))
    return np.array(out)


def test_label_posterior_agrees_with_the_exact_discrete_filter():
    models, T, a, sigma = _switching_models()
    rng = np.random.default_rng(11)
    n_frames, r, x0_sd = 40, 0.5, 1.0
    # a path that switches regime: labels by T, x by the label's model
    labels = [0]
    x = [rng.normal(0, x0_sd)]
    for _ in range(1, n_frames):
        labels.append(int(rng.choice(2, p=T[labels[-1]])))
        m = models[labels[-1]]
        x.append(float(m.mean[0] + a * (x[-1] - m.mean[0]) + sigma * rng.standard_normal()))
    z = np.array(x) + r * rng.standard_normal(n_frames)
    init = stationary_distribution(T)
    exact = _forward(z, models, T, init, np.linspace(-9, 9, 1201), x0_sd, r)

    dyn = MixedDynamics(("low", "high"), models, T, init, np.zeros(2), 0.04)
    n = 20000
    prng = np.random.default_rng(5)
    particles = cond.init_gaussian(np.zeros(1), np.eye(1) * x0_sd**2, n, prng)
    motion = MixedPrediction(dyn, n, prng)

    def loglik(X):
        return -0.5 * ((X[:, 0] - zk) / r) ** 2

    zk = z[0]
    particles = cond.ParticleSet(particles.prev, particles.cur, loglik(particles.cur))
    got = [motion.posterior(particles.weights)]
    for zk in z[1:]:
        particles, _ = cond.step(particles, dyn, loglik, prng, motion=motion)
        got.append(motion.posterior(particles.weights))
    got = np.array(got)
    err = np.abs(got[:, 1] - exact[:, 1])
    # sampling error with N = 20 000 (measured: max 0.015, mean 0.003)
    assert err.max() < 0.04, (err.max(), int(err.argmax()))
    assert err.mean() < 0.01
    # the posterior is informative: it follows the true regime most of the time
    assert np.mean((exact[1:, 1] > 0.5) == (np.array(labels[1:]) == 1)) > 0.8


# ---------------------------------------------------------------------------------------------
# Learning from labelled ranges


def test_learn_mixed_recovers_each_labels_dynamics_and_T(tmp_path):
    models, T, a, sigma = _switching_models()
    rng = np.random.default_rng(3)
    # runs of 30-60 frames per regime, alternating
    xs, labs = [0.0, 0.0], [0, 0]
    y = 0
    while len(xs) < 4000:
        for _ in range(int(rng.integers(30, 60))):
            m = models[y]
            xs.append(float(m.mean[0] + a * (xs[-1] - m.mean[0]) + sigma * rng.standard_normal()))
            labs.append(y)
        y = 1 - y
    X, lab = np.array(xs)[:, None], np.array(labs)
    learned, T_hat, report = learn_mixed([X], [lab], ["low", "high"], 0.04)
    for got, mu in zip(learned, (-2.0, 2.0)):
        assert abs(got.A1[0, 0] - a) < 0.08
        assert abs(got.A2[0, 0]) < 0.08
        assert abs(got.mean[0] - mu) < 0.3
        assert abs(got.B0[0, 0] - sigma) < 0.05
    switches = np.count_nonzero(np.diff(lab))
    assert T_hat[0, 1] == pytest.approx(np.count_nonzero((lab[:-1] == 0) & (lab[1:] == 1)) / np.sum(lab[:-1] == 0))
    assert switches > 50 and report["labels"]["low"]["runs"] > 25


def test_label_ranges_file_errors(tmp_path):
    p = tmp_path / "labels.csv"
    p.write_text("start,end,label\n0,10,a\n5,20,b\n")
    with pytest.raises(Exception, match="overlap"):
        read_label_ranges(p)
    p.write_text("0,10,a\nx,20,b\n")
    with pytest.raises(Exception, match="range 2: start and end must be frame numbers"):
        read_label_ranges(p)
    p.write_text("start,end,label\n0,10,a\n11,20,b\n")
    assert read_label_ranges(p) == [(0, 10, "a"), (11, 20, "b")]


# ---------------------------------------------------------------------------------------------
# The bouncing-ball experiment on the sample clip


@pytest.fixture(scope="module")
def ball_runs(tmp_path_factory):
    clip = sample_clip("bouncing_ball")
    out = tmp_path_factory.mktemp("ball")
    runner = CliRunner()
    res = runner.invoke(cli, ["draw", str(clip), "--box", "22,52,36,36", "-o", str(out / "ball.yaml")])
    assert res.exit_code == 0, res.output
    model = yaml.safe_load((EXAMPLES / "bouncing_ball.mixed.yaml").read_text())
    assert model["labels"][1]["bounce"]["floor"] == 318  # the sample clip's floor
    # the single model with the default braking jumps of the motion prior (and no isotropic ones)
    braking = yaml.safe_load((EXAMPLES / "bouncing_ball.flight.yaml").read_text())
    braking["jumps"]["brake"] = Settings().jumps.brake
    (out / "braking.yaml").write_text(yaml.safe_dump(braking))
    runs = {}
    for name, args in (("single", ["-c", str(EXAMPLES / "bouncing_ball.flight.yaml")]),
                       ("braking", ["-c", str(out / "braking.yaml")]),
                       ("mixed", ["-c", str(EXAMPLES / "bouncing_ball.settings.yaml"),
                                  "--model", str(EXAMPLES / "bouncing_ball.mixed.yaml")])):
        res = runner.invoke(cli, ["-q", "track", str(clip), "--template", str(out / "ball.yaml"), *args,
                                  "-o", str(out / name), "--seed", "0"])
        assert res.exit_code == 0, res.output
        runs[name] = out / name / "bouncing_ball.condensation.csv"
    return clip, runs, out


def test_mixed_state_tracks_through_every_bounce_where_one_model_does_not(ball_runs):
    clip, runs, out = ball_runs
    e = run_experiment(runs["single"], runs["mixed"], clip.with_suffix(".truth.csv"), png=out / "bounces.png")
    assert e.bounces.tolist() == [23, 61, 94, 122]
    # the single constant-velocity model overshoots through the floor at the bounces
    assert e.single.max_error > 30 and e.single.mean_error > 5
    # the mixed-state model follows every bounce to within a few pixels
    assert e.mixed.max_error < 5 and e.mixed.mean_error < 1.5
    assert (out / "bounces.png").stat().st_size > 1000


def test_braking_jumps_let_one_model_follow_the_bounces(ball_runs):
    """A few samples whose velocity is slowed, stopped or turned back (the default share,
    jumps.brake) carry the single flight model through each bounce, where without
    them it overshoots through the floor."""
    clip, runs, _ = ball_runs
    assert Settings().jumps.brake > 0
    e = run_experiment(runs["braking"], runs["mixed"], clip.with_suffix(".truth.csv"))
    assert e.single.max_error < 20 and e.single.mean_error < 5


def test_the_bounce_posterior_peaks_at_every_bounce_and_nowhere_else(ball_runs):
    clip, runs, _ = ball_runs
    e = run_experiment(runs["single"], runs["mixed"], clip.with_suffix(".truth.csv"))
    assert e.hits == len(e.bounces) == 4
    assert all(abs(o) <= 1 for o in e.offsets)
    assert e.false == 0


def test_the_mixed_run_writes_label_columns_and_a_label_strip(ball_runs):
    import rrd_utils as ru

    _, runs, _ = ball_runs
    head = runs["mixed"].read_text().splitlines()[0].split(",")
    assert ["p_flight", "p_bounce"] == [h for h in head if h.startswith("p_")]
    rows = [line.split(",") for line in runs["mixed"].read_text().splitlines()[1:]]
    p = np.array([[float(r[head.index("p_flight")]), float(r[head.index("p_bounce")])] for r in rows])
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-5)
    entities = ru.entity_paths(runs["mixed"].with_suffix(".rrd"))
    assert {"series/labels", "labels/posterior_over_time"} <= entities


def test_detection_helpers():
    y = np.array([0, 5, 9, 12, 10, 6, 3, 5, 8, 11, 9.0])
    assert true_bounces(y).tolist() == [3, 9]
    p = np.array([0, 0.1, 0.9, 0.2, 0, 0.6, 0.6, 0.1])
    assert detections(p).tolist() == [2, 5]
    assert match([2, 9], [3, 5, 20]) == (1, 2, [1])


# ---------------------------------------------------------------------------------------------
# The CLI


def test_inspect_and_simulate_a_mixed_model(ball_runs, tmp_path):
    _, _, out = ball_runs
    runner = CliRunner()
    model = str(EXAMPLES / "bouncing_ball.mixed.yaml")
    res = runner.invoke(cli, ["inspect", model, "--template", str(out / "ball.yaml"), "--fps", "25"])
    assert res.exit_code == 0, res.output
    assert "flight" in res.output and "bounce on the floor y = 318 px" in res.output and "0.9000" in res.output
    assert "modes" in res.output
    res = runner.invoke(cli, ["simulate", model, "--template", str(out / "ball.yaml"), "--frames", "300",
                              "--paths", "2", "--seed", "1", "-o", str(tmp_path / "sim.rrd")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "sim.rrd").is_file() and (tmp_path / "sim.png").is_file()
    res = runner.invoke(cli, ["simulate", model, "-o", str(tmp_path / "x.rrd")])
    assert res.exit_code != 0 and "--template" in res.output


def test_simulated_paths_switch_label_by_T():
    models, T, _, _ = _switching_models()
    dyn = MixedDynamics(("low", "high"), models, T, stationary_distribution(T), np.zeros(2), 0.04)
    _, labels = dyn.simulate(20000, np.random.default_rng(2))
    frac_high = float(np.mean(labels == 1))
    assert frac_high == pytest.approx(stationary_distribution(T)[1], abs=0.03)
    stay = np.mean(labels[1:][labels[:-1] == 0] == 0)
    assert stay == pytest.approx(T[0, 0], abs=0.01)


@pytest.mark.parametrize("extra, message", [
    (["--tracker", "kalman"], "only --tracker condensation"),
    (["--smooth"], "--smooth: not available with a mixed-state model"),
])
def test_track_refuses_what_a_mixed_model_cannot_do(ball_runs, tmp_path, extra, message):
    clip, _, out = ball_runs
    res = CliRunner().invoke(cli, ["track", str(clip), "--model", str(EXAMPLES / "bouncing_ball.mixed.yaml"),
                                   "--template", str(out / "ball.yaml"), "-o", str(tmp_path), *extra])
    assert res.exit_code != 0 and message in res.output and "Traceback" not in res.output


def test_learn_with_labels_writes_a_mixed_model_that_tracks(ball_runs, tmp_path):
    clip, runs, out = ball_runs
    labels = tmp_path / "labels.csv"
    labels.write_text("start,end,label\n0,22,fall\n23,43,rise\n44,61,fall\n62,78,rise\n79,94,fall\n95,108,rise\n"
                      "109,122,fall\n")
    model = tmp_path / "learned.mixed.yaml"
    runner = CliRunner()
    res = runner.invoke(cli, ["learn", "--template", str(out / "ball.yaml"), "--from-tracks", str(runs["mixed"]),
                              "--labels", str(labels), "-o", str(model)])
    assert res.exit_code == 0, res.output
    m = load_mixed(model)
    assert m.names == ["fall", "rise"] and m.space is not None
    # fall covers 71 frames (70 with a labelled successor), rise 52; each changes 3 times
    assert m.T[0, 1] == pytest.approx(3 / 70, abs=1e-9)
    assert m.T[1, 0] == pytest.approx(3 / 52, abs=1e-9)
    res = runner.invoke(cli, ["-q", "track", str(clip), "--model", str(model), "--template", str(out / "ball.yaml"),
                              "-o", str(tmp_path / "run"), "--no-rrd", "--seed", "0", "--end", "20"])
    assert res.exit_code == 0, res.output
    head = (tmp_path / "run" / "bouncing_ball.condensation.csv").read_text().splitlines()[0]
    assert "p_fall" in head and "p_rise" in head
    res = runner.invoke(cli, ["learn", "--template", str(out / "ball.yaml"), "--from-tracks", str(runs["mixed"]),
                              "--labels", str(labels), "--labels", str(labels), "-o", str(tmp_path / "x.yaml")])
    assert res.exit_code != 0 and "one labels file per training clip or track" in res.output


def test_a_mixed_model_cannot_start_from_a_steady_state(ball_runs, tmp_path):
    clip, _, out = ball_runs
    cfg = tmp_path / "ss.yaml"
    cfg.write_text("condensation:\n  init: steady_state\n")
    res = CliRunner().invoke(cli, ["track", str(clip), "--model", str(EXAMPLES / "bouncing_ball.mixed.yaml"),
                                   "--template", str(out / "ball.yaml"), "-c", str(cfg), "-o", str(tmp_path / "o")])
    assert res.exit_code != 0 and "steady_state is not available with a mixed-state model" in res.output
    assert not (tmp_path / "o").exists()
