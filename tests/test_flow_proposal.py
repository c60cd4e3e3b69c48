"""The flow proposal: CONDENSATION keeps an object that moves faster than its AR(2) prior follows.

A synthetic clip (320 x 240, 25 fps): a red-brown oval rests on a cluttered background, then
moves :data:`SPEED` px a frame to the right for :data:`MOVING` frames, and stops.  Tracked from
the frame-0 box with the defaults but for ``condensation.flow_fraction``, the tracker without
the flow proposal is left behind (the prior's noise and jumps cover such a move too thinly), with
it the estimate stays on the oval.  The importance weights are checked apart: drawn from the
mixture of the prior and the flow's proposal, the weighted set is a fair sample of the prior.
"""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from trackcli.cli import cli
from trackcli.observe import flow as F
from trackcli.observe.region import FlowPrior

W, H = 640, 240
N = 20
REST = 8
SPEED = 85.0
MOVING = 5
AXES = (130.0, 160.0)


def centre(k: int) -> tuple[float, float]:
    moved = min(max(k - REST, 0), MOVING)
    return 100.0 + SPEED * moved, 120.0


def background(rng: np.random.Generator) -> np.ndarray:
    img = np.full((H, W, 3), (110, 130, 115), np.float64) + rng.normal(0, 5, (H, W, 3))
    img = np.clip(img, 0, 255).astype(np.uint8)
    for _ in range(140):
        x, y = (int(v) for v in rng.integers(0, [W, H]))
        ang = rng.uniform(0, np.pi)
        L = rng.uniform(10, 40)
        shade = int(rng.choice([50, 200]))
        cv2.line(img, (x, y), (int(x + L * np.cos(ang)), int(y + L * np.sin(ang))), (shade, shade, shade), 1,
                 cv2.LINE_AA)
    return img


def write_clip(path: Path) -> Path:
    bg = background(np.random.default_rng(3))
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (W, H))
    assert writer.isOpened()
    for k in range(N):
        img = bg.copy()
        cv2.ellipse(img, (centre(k), AXES, 0.0), (40, 60, 150), -1, cv2.LINE_AA)
        writer.write(img)
    writer.release()
    return path


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> Path:
    return write_clip(tmp_path_factory.mktemp("flow") / "dash.avi")


def track(clip: Path, out: Path, fraction: float, seed: int, particles: int = 500) -> list[dict]:
    runner = CliRunner()
    c0 = centre(0)
    box = f"{c0[0] - 65},{c0[1] - 80},130,160"
    r = runner.invoke(cli, ["draw", str(clip), "--box", box, "-o", str(out / "t.yaml")], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    (out / "settings.yaml").write_text(f"condensation:\n  flow_fraction: {fraction}\n  particles: {particles}\n")
    r = runner.invoke(cli, ["track", "--template", str(out / "t.yaml"), str(clip), "-o", str(out), "--no-rrd",
                            "--seed", str(seed), "-c", str(out / "settings.yaml")], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    with open(out / "dash.condensation.csv", newline="") as f:
        return list(csv.DictReader(f))


def errors(rows: list[dict]) -> np.ndarray:
    return np.array([np.hypot(float(r["cx"]) - centre(int(r["frame"]))[0], float(r["cy"]) - centre(int(r["frame"]))[1])
                     for r in rows])


# ---------------------------------------------------------------------------------------------
# End to end: a dash faster than the prior follows


#: a small sample set: the prior's jumps put few samples where the dashing oval is, the flow many
PARTICLES = 100
#: how far the estimate may be from the oval while it dashes and still count as held (px; the
#: oval is 130 x 160)
HELD = 20.0


@pytest.fixture(scope="module")
def dash_errors(clip, tmp_path_factory):
    """Each seed's centroid errors (px) while the oval moves, without and with the flow proposal."""
    moving = slice(REST + 1, REST + MOVING + 1)
    out = {}
    for fraction in (0.0, 0.25):
        for seed in (0, 1, 2):
            rows = track(clip, tmp_path_factory.mktemp(f"flow-{fraction}-{seed}"), fraction, seed, PARTICLES)
            out[fraction, seed] = errors(rows)[moving]
    return out


def test_without_the_flow_the_estimate_falls_behind_a_dash(dash_errors):
    for seed in (0, 1, 2):
        assert dash_errors[0.0, seed].max() > 2 * HELD, dash_errors[0.0, seed]


def test_with_the_flow_proposal_the_estimate_stays_on_the_dashing_object(dash_errors):
    for seed in (0, 1, 2):
        assert dash_errors[0.25, seed].max() < HELD, dash_errors[0.25, seed]


# ---------------------------------------------------------------------------------------------
# The importance weights


def test_the_correction_is_zero_when_the_proposal_is_the_prior_or_unused():
    log_f = np.log(np.random.default_rng(0).uniform(0.01, 1.0, 50))
    assert np.allclose(F.mixture_log_correction(log_f, log_f, 0.3), 0.0, atol=1e-12)
    assert np.array_equal(F.mixture_log_correction(log_f, log_f + 5.0, 0.0), np.zeros(50))
    # a sample the prior cannot produce keeps weight 0 whatever the proposal
    assert F.mixture_log_correction(np.array([-np.inf]), np.array([0.0]), 0.5)[0] == -np.inf


def prior_samples(rng: np.random.Generator, n: int, jump_share: float, jump_rms: float) -> np.ndarray:
    """Predicted translations as the motion prior draws them: a Gaussian core, a share jumped."""
    t = np.array([40.0, -10.0]) + 3.0 * rng.standard_normal((n, 2))
    hit = rng.random(n) < jump_share
    t[hit] += jump_rms * rng.standard_normal((int(hit.sum()), 2))
    return t


@pytest.mark.parametrize("centre", [(40.0, -10.0), (52.0, -10.0), (40.0, 14.0)])
def test_the_weighted_set_is_a_fair_sample_of_the_prior(centre):
    """Drawn from the mixture of the prior and the flow's proposal, the weighted samples have the
    prior's distribution (its mean, its spread, the mass in its tail toward the proposal), while
    the same samples unweighted do not when the proposal is elsewhere."""
    rng = np.random.default_rng(1)
    n, share, rms = 40_000, 0.12, 12.0
    t = prior_samples(rng, n, share, rms)
    new = np.column_stack([t, rng.standard_normal((n, 2))])  # other components pass through
    prev = new - 1.0
    propose = F.flow_proposal(np.array(centre), 2.0, 0.3, jump_share=share, jump_rms=rms)
    out_prev, out, log_c = propose(prev, new, rng)
    assert np.array_equal(out_prev, prev)  # the parents stay: the move is the velocity
    assert np.array_equal(out[:, 2:], new[:, 2:])
    assert np.count_nonzero((out[:, :2] != new[:, :2]).any(axis=1)) == round(0.3 * n)
    w = np.exp(log_c - log_c.max())
    w /= w.sum()
    ref = prior_samples(np.random.default_rng(2), n, share, rms)
    mean = w @ out[:, :2]
    sd = np.sqrt(w @ (out[:, :2] - mean) ** 2)
    assert np.allclose(mean, ref.mean(axis=0), atol=0.35), (mean, ref.mean(axis=0))
    assert np.allclose(sd, ref.std(axis=0), rtol=0.1), (sd, ref.std(axis=0))
    far = np.hypot(*(out[:, :2] - centre).T) < 3.0  # about the proposal's centre
    p_ref = float(np.mean(np.hypot(*(ref - centre).T) < 3.0))
    assert abs(float(w[far].sum()) - p_ref) < 0.25 * p_ref + 0.005, (w[far].sum(), p_ref)
    if centre != (40.0, -10.0):  # unweighted, the proposal's samples pile up about its centre
        assert float(np.mean(far)) > 2 * p_ref + 0.05


# ---------------------------------------------------------------------------------------------
# The flow itself


def test_the_shift_of_a_region_is_the_median_flow_over_it():
    back = background(np.random.default_rng(0))
    a, b = back.copy(), back.copy()
    cv2.ellipse(a, ((150.0, 120.0), (60.0, 80.0), 0.0), (40, 60, 150), -1, cv2.LINE_AA)
    cv2.ellipse(b, ((162.0, 116.0), (60.0, 80.0), 0.0), (40, 60, 150), -1, cv2.LINE_AA)  # moved by (12, -4)
    t = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    oval = np.column_stack([150.0 + 34.0 * np.cos(t), 120.0 + 44.0 * np.sin(t)])  # a little larger than the oval
    flow = FlowPrior()
    flow.push(a)
    assert flow.shift(oval) is None  # no flow before a second frame
    flow.push(b)
    d = flow.shift(oval)
    assert np.allclose(d, (12.0, -4.0), atol=1.0), d
    assert np.allclose(flow.shift(oval + (150.0, 0.0)), 0.0, atol=1.0)  # the still background
    assert flow.shift(oval + (1000.0, 0.0)) is None  # out of the frame


def test_the_refinement_shares_the_trackers_flow_and_draws_the_same_outlines():
    """With the tracker's flow (pushed by the tracker before each step) the outline's refinement
    computes no flow of its own, and its outlines are those it draws with its own."""
    import types

    from trackcli.observe import region as R

    settings = types.SimpleNamespace(refine=True, prior_width=0.5, flow=True, colour_rate=0.0, lost_contrast=3.0)
    back = background(np.random.default_rng(0))
    frames, estimates = [], []
    t = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    for k in range(4):
        img = back.copy()
        cx = 150.0 + 6.0 * k
        cv2.ellipse(img, ((cx, 120.0), (60.0, 80.0), 0.0), (40, 60, 150), -1, cv2.LINE_AA)
        frames.append(img)
        estimates.append(np.column_stack([cx + 2.0 + 32.0 * np.cos(t), 120.0 + 42.0 * np.sin(t)]))
    own = R.OutlineRefiner(settings)
    shared_flow = FlowPrior()
    calls = []
    push = shared_flow.push
    shared_flow.push = lambda image: (calls.append(1), push(image))
    shared = R.OutlineRefiner(settings, flow=shared_flow)
    for img, est in zip(frames, estimates):
        a = own(img, est)
        shared_flow.push(img)  # the tracker's step
        b = shared(img, est)
        assert np.array_equal(a.outline, b.outline)
    assert len(calls) == len(frames)  # only the tracker pushed


# ---------------------------------------------------------------------------------------------
# The adaptive share


def test_the_responsibilities_follow_where_the_proposal_put_its_samples():
    """Each sample's responsibility is the chance that the mixture at the reference share drew
    it from the flow's proposal: near 1 where only the proposal reaches, near 0 where only the
    prior does."""
    rng = np.random.default_rng(4)
    n = 4000
    t = np.array([0.0, 0.0]) + 2.0 * rng.standard_normal((n, 2))
    new = np.column_stack([t, np.zeros((n, 2))])
    propose = F.flow_proposal(np.array([30.0, 0.0]), 1.0, 0.2, reference=0.25)
    _, out, _ = propose(new - 1.0, new, rng)
    r = propose.responsibility
    moved = (out[:, :2] != new[:, :2]).any(axis=1)
    assert r.shape == (n,) and np.all((r >= 0) & (r <= 1))
    assert r[moved].min() > 0.99 and r[~moved].max() < 0.01


def test_the_share_follows_the_weight_the_proposals_samples_earn():
    share = F.AdaptiveShare(0.25, 0.02)
    assert share.share == 0.25
    w = np.full(10, 0.1)
    earned_nothing = np.zeros(10)
    assert share.update(w, earned_nothing) == pytest.approx(0.125)  # halfway toward what was earned
    for _ in range(10):
        share.update(w, earned_nothing)
    assert share.share == pytest.approx(0.02)  # never below the least
    earned_all = np.ones(10)
    assert share.update(w, earned_all) == pytest.approx(0.25)  # capped at the largest
    assert share.update(w, None) == pytest.approx(0.25)  # a frame without the proposal: unchanged
    assert share.update(w * 0.0, earned_nothing) == pytest.approx(0.25)  # no distribution: unchanged
    fixed = F.AdaptiveShare(0.25, 0.25)
    assert fixed.update(w, earned_nothing) == 0.25  # least = largest: a fixed share


def test_the_flows_disagreement_over_a_region_is_small_for_one_move_and_large_for_two():
    """Two ovals side by side move 12 px toward each other: over one of them the flow agrees
    with its median; over a region that takes in both it does not (along x)."""
    back = background(np.random.default_rng(0))
    a, b = back.copy(), back.copy()
    for img, dx in ((a, 0.0), (b, 12.0)):
        cv2.ellipse(img, ((110.0 + dx, 120.0), (60.0, 80.0), 0.0), (40, 60, 150), -1, cv2.LINE_AA)
        cv2.ellipse(img, ((210.0 - dx, 120.0), (60.0, 80.0), 0.0), (150, 60, 40), -1, cv2.LINE_AA)
    t = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    flow = FlowPrior()
    flow.push(a)
    flow.push(b)
    d, spread = flow.shift_spread(np.column_stack([110.0 + 26.0 * np.cos(t), 120.0 + 36.0 * np.sin(t)]))
    assert np.allclose(d, (12.0, 0.0), atol=1.5) and np.all(spread < 1.5), (d, spread)
    d, spread = flow.shift_spread(np.column_stack([160.0 + 75.0 * np.cos(t), 120.0 + 36.0 * np.sin(t)]))
    assert spread[0] > 8.0 and spread[1] < 1.5, spread
    assert flow.shift_spread(np.column_stack([1000.0 + 26.0 * np.cos(t), 120.0 + 36.0 * np.sin(t)])) is None


def test_with_labels_a_moved_sample_is_weighed_by_its_own_labels_prior():
    """Mixed-state samples: half labelled 0 about (0, 0), half labelled 1 about (30, 0); the
    proposal sits on label 1's place.  A label-0 sample it moves there is one label 0's prior
    cannot produce, and keeps next to no weight; taken over both labels, the prior would have
    given it label 1's density."""
    rng = np.random.default_rng(5)
    n = 4000
    labels = np.repeat([0, 1], n // 2)
    t = np.where(labels[:, None] == 0, 0.0, [30.0, 0.0]) + 2.0 * rng.standard_normal((n, 2))
    new = np.column_stack([t, np.zeros((n, 2))])

    def moved_label0_mass(groups):
        propose = F.flow_proposal(np.array([30.0, 0.0]), 2.0, 0.25, groups=groups)
        _, out, log_c = propose(new - 1.0, new, np.random.default_rng(6))
        w = np.exp(log_c - log_c.max())
        w /= w.sum()
        there = np.hypot(*(out[:, :2] - [30.0, 0.0]).T) < 6.0
        return float(w[there & (labels == 0)].sum()), float(w[labels == 0].sum())

    with_labels, label0 = moved_label0_mass(lambda: labels)
    assert with_labels < 1e-3
    assert abs(label0 - 0.5) < 0.03  # the labels keep the prior's shares
    without, _ = moved_label0_mass(None)
    assert without > 0.05


def test_the_spread_follows_how_far_off_the_proposals_samples_were_found():
    share = F.AdaptiveShare(0.25, 0.02)
    assert share.error is None
    w = np.full(4, 0.25)
    r = np.array([1.0, 1.0, 0.0, 0.0])  # only the first two are the proposal's
    offsets = np.array([[3.0, 0.0], [-3.0, 4.0], [50.0, 50.0], [-50.0, 50.0]])
    share.update_error(w, r, offsets)
    assert np.allclose(share.error, [3.0, np.sqrt(8.0)])  # the first frame: as found
    share.update_error(w, r, np.zeros((4, 2)))
    assert np.allclose(share.error, [np.sqrt(4.5), 2.0])  # then halfway, in variance
    share.update_error(w, None, offsets)
    share.update_error(w, np.zeros(4), offsets)  # no posterior mass on the proposal: unchanged
    assert np.allclose(share.error, [np.sqrt(4.5), 2.0])
