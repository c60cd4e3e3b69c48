"""CONDENSATION on the committed sample clips: the papers' two tracking experiments, pinned.

- The cluttered clip (AC §12.4, "tracking rapid motions through clutter"; 000 §5.2): a model
  learned on ``train.mp4`` and placed on ``test.mp4`` by a template drawn there.  With the
  settings of ``configs/sample-clutter.yaml`` CONDENSATION keeps lock (centroid error at most
  8 px) on at least 95 % of the frames and is back on the object after the pole has passed;
  the Kalman contour tracker with the same model and measurements loses it.
- The multi-modal clip (000 §5.1, Fig 3; AC Fig 12.10): from the steady state of a motion
  model over the whole frame, the histogram of horizontal translation has a peak at each of
  the three people.
- The same seed gives the same track CSV, byte for byte.

Everything runs through the command line or the library's own functions, on the committed
clips, with the default particle counts of the configs.  A few unit checks of the pieces
added for this (placing a model's dynamics, the truncated likelihood, moving initial
samples) come first.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import CONFIGS, SAMPLE_DATA, sample_clip
from trackcli.observe import likelihoods, measure
from trackcli.cli import cli
from trackcli.settings import load_settings
from trackcli.dynamics.ar2 import AR2
from trackcli.run.evaluate import evaluate, load_track, score_frames
from trackcli.run.evaluate import load_truth as load_eval_truth
from trackcli.dynamics.model import load_model, place_dynamics, translation_split
from trackcli.run.clips import tracking_setup
from trackcli.sample_data import load_truth
from trackcli.shapes.shape_space import similarity
from trackcli.shapes.spline import SplineBasis
from trackcli.trackers.condensation_tracker import track_condensation
from trackcli.io.video import open_video

CLUTTER = CONFIGS / "sample-clutter.yaml"
THREE_HEADS = CONFIGS / "three-heads.yaml"
TRAIN_BOX = "172,91,135,155"  # around the object in frame 0 of train.mp4 (as in the README)
TEST_BOX = "166,104,131,153"  # around the object in frame 0 of test.mp4
LOCK_PX = 8.0


def run(args) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


# ---------------------------------------------------------------------------------------------
# Pieces: placing a learned model, the truncated likelihood, moving initial samples


def _space():
    t = np.linspace(0, 2 * np.pi, 10, endpoint=False)
    Q0 = np.concatenate([100 + 30 * np.cos(t) + 4 * np.sin(2 * t), 80 + 40 * np.sin(t)])
    return similarity(SplineBasis(10, degree=2, closed=True), Q0)


def _coupled_dynamics(rng: np.random.Generator) -> AR2:
    """A stable AR(2) on a similarity space with every block coupled."""
    A1 = 1.8 * np.eye(4) + 0.02 * rng.standard_normal((4, 4))
    A2 = -0.85 * np.eye(4) + 0.02 * rng.standard_normal((4, 4))
    B = 0.3 * rng.standard_normal((4, 4))
    return AR2(A2, A1, B, np.array([5.0, -3.0, 0.01, -0.02]), 0.04)


def test_place_dynamics_without_coupling_keeps_the_blocks_and_scales_the_noise():
    space = _space()
    dyn = _coupled_dynamics(np.random.default_rng(3))
    Es, Ed = translation_split(space)
    np.testing.assert_array_equal(Es, np.diag([1.0, 1.0, 0.0, 0.0]))  # tx, ty are axes here
    X0 = np.array([0.0, 0.0, 0.05, 0.0])  # the template at 1.05 times the model's size
    placed = place_dynamics(dyn, space, X0, 0.04, translation_noise=3.0, deformation_noise=2.0, coupling="none",
                            max_spectral_radius=0.999)
    for A, A_old in ((placed.A1, dyn.A1), (placed.A2, dyn.A2)):
        np.testing.assert_array_equal(A[:2, 2:], 0.0)
        np.testing.assert_array_equal(A[2:, :2], 0.0)
        np.testing.assert_allclose(A[:2, :2], A_old[:2, :2])  # the blocks are kept as learned
        np.testing.assert_allclose(A[2:, 2:], A_old[2:, 2:])
    C_old, C = dyn.B0 @ dyn.B0.T, placed.B0 @ placed.B0.T
    np.testing.assert_allclose(C[:2, :2], (1.05 * 3.0) ** 2 * C_old[:2, :2], rtol=1e-9)
    np.testing.assert_allclose(C[2:, 2:], (1.05 * 2.0) ** 2 * C_old[2:, 2:], rtol=1e-9)
    np.testing.assert_allclose(C[:2, 2:], 1.05**2 * 6.0 * C_old[:2, 2:], rtol=1e-9)
    # translation mean where the object is placed, the learned mean shape at the placed size
    np.testing.assert_allclose(placed.mean, [0.0, 0.0, 1.05 * 1.01 - 1, 1.05 * -0.02])
    assert place_dynamics(dyn, space, None, 0.04).mean.tolist() == dyn.mean.tolist()


def test_place_dynamics_scales_the_simulated_translation_by_the_factor():
    """AR(2) dynamics are linear: noise times r gives motion times r, same time course."""
    space = _space()
    dyn = _coupled_dynamics(np.random.default_rng(4))
    one = place_dynamics(dyn, space, np.zeros(4), 0.04)
    four = place_dynamics(dyn, space, np.zeros(4), 0.04, translation_noise=4.0)
    rms = [np.sqrt(np.trace(d.steady_state_covariance()[4:6, 4:6])) for d in (one, four)]
    assert rms[1] == pytest.approx(4.0 * rms[0], rel=1e-6)
    assert one.spectral_radius() == pytest.approx(four.spectral_radius())


def test_place_dynamics_rejects_a_bad_factor():
    with pytest.raises(ValueError, match=r"placement.translation_noise: expected a number > 0, got -1"):
        place_dynamics(_coupled_dynamics(np.random.default_rng(5)), _space(), None, 0.04, translation_noise=-1.0)


def test_truncated_likelihood_is_the_papers_mean_of_clipped_squares():
    """000 eqs 10-11 on a vertical step edge: nearest feature per normal, penalty h²."""
    img = np.full((60, 80), 200.0, np.float32)
    img[:, :40] = 40.0  # dark left half: the edge lies between x = 39 and x = 40
    fimg = measure.feature_image(img, sigma=0.0, edge_sigma=1.0)
    pts = np.array([[37.5, 30.0], [41.5, 20.0], [20.0, 30.0]])  # nu = +2, -2, none within h
    nrm = np.tile([1.0, 0.0], (3, 1))
    got = likelihoods.truncated_log_likelihood(fimg, pts, nrm, h=5.0, sigma=2.0, threshold=8.0,
                                           polarity="dark_to_light")
    assert got == pytest.approx(-(4.0 + 4.0 + 25.0) / 3 / (2 * 2.0**2), abs=1e-3)
    # the wrong polarity finds nothing: every normal pays the penalty h²
    none = likelihoods.truncated_log_likelihood(fimg, pts, nrm, h=5.0, sigma=2.0, threshold=8.0,
                                            polarity="light_to_dark")
    assert none == pytest.approx(-25.0 / (2 * 2.0**2))
    # several curves at once, as CONDENSATION calls it: shape (N,)
    many = likelihoods.truncated_log_likelihood(fimg, np.stack([pts, pts + [2.0, 0.0]]), np.stack([nrm, nrm]),
                                            h=5.0, sigma=2.0, threshold=8.0)
    assert many.shape == (2,) and many[0] == pytest.approx(got, abs=1e-3)


def test_a_clutter_feature_beside_the_nearest_one_adds_nothing_to_the_truncated_score():
    img = np.full((40, 80), 200.0, np.float32)
    img[:, :40] = 40.0
    with_line = img.copy()
    with_line[:, 52:54] = 40.0  # a thin dark line 12 px outside the edge, inside the search
    pts, nrm = np.array([[39.5, 20.0]]), np.array([[1.0, 0.0]])
    scores = [likelihoods.truncated_log_likelihood(measure.feature_image(im), pts, nrm, h=15.0, sigma=2.0,
                                               threshold=8.0) for im in (img, with_line)]
    assert scores[0] == pytest.approx(scores[1], abs=1e-6)
    clutter = [likelihoods.log_likelihood(measure.feature_image(im), pts, nrm, h=15.0, sigma=6.0, alpha=0.02,
                                      threshold=8.0) for im in (img, with_line)]
    assert clutter[1] > clutter[0]  # AC eq 12.2 counts every feature on the normal


# ---------------------------------------------------------------------------------------------
# The cluttered clip


@pytest.fixture(scope="module")
def clutter_runs(tmp_path_factory):
    """Templates, a model learned with one cycle, and both trackers on test.mp4 (seed 0)."""
    for name in ("train", "test"):
        sample_clip(name)
    d = tmp_path_factory.mktemp("clutter")
    # the head of the papers' experiments: 12 control points, as the book draws it
    run(["draw", SAMPLE_DATA / "train.mp4", "--box", TRAIN_BOX, "--n-ctrl", "12", "-o", d / "head.yaml"])
    run(["learn", "-c", CLUTTER, "--template", d / "head.yaml", SAMPLE_DATA / "train.mp4",
         "-o", d / "model.yaml", "--no-rrd"])
    run(["draw", SAMPLE_DATA / "test.mp4", "--box", TEST_BOX, "--n-ctrl", "12", "-o", d / "head-test.yaml"])
    for tracker in ("condensation", "kalman"):
        run(["track", "-c", CLUTTER, "--tracker", tracker, "--model", d / "model.yaml",
             "--template", d / "head-test.yaml", SAMPLE_DATA / "test.mp4", "-o", d, "--seed", 0, "--no-rrd"])
    return d


def _scores(csv):
    truth = load_eval_truth(SAMPLE_DATA / "test.truth.csv")
    return (evaluate(csv, truth, threshold=LOCK_PX, lost_threshold=LOCK_PX),
            score_frames(load_track(csv), truth, lost_threshold=LOCK_PX))


def test_the_model_is_learned_in_one_cycle_as_the_config_says(clutter_runs):
    model = load_model(clutter_runs / "model.yaml")
    assert model.provenance["cycles"] == 1
    assert model.dynamics.is_stable()


def test_the_sample_model_is_placed_with_its_learned_modes(clutter_runs):
    """The model as `track -c sample-clutter.yaml --model M --template T` uses it on test.mp4."""
    learned = load_model(clutter_runs / "model.yaml").dynamics
    with open_video(SAMPLE_DATA / "test.mp4") as video:
        setup = tracking_setup(clutter_runs / "model.yaml", clutter_runs / "head-test.yaml",
                               load_settings(CLUTTER), video)
    placed = setup.dynamics
    assert placed.spectral_radius() == pytest.approx(learned.spectral_radius(), abs=1e-9)
    assert placed.spectral_radius() < 1
    for got, want in zip(placed.modes(), learned.modes()):
        assert got.frequency == pytest.approx(want.frequency, abs=1e-9)
        assert got.beta == pytest.approx(want.beta, abs=1e-6)


def test_condensation_keeps_lock_in_clutter(clutter_runs):
    result, frames = _scores(clutter_runs / "test.condensation.csv")
    assert result.frames_scored == 160
    assert result.precision >= 0.95, result  # centroid within 8 px
    assert result.centre_error_max < 20  # never off the object
    # pinned (seed 0 on the committed clip, the contour discriminant, the flow proposal): no
    # frame beyond 8 px, mean error 1.05 px, median 0.96 px, outline IoU 0.90 (without the flow
    # proposal 1 frame, 1.7 px, 1.45 px)
    assert result.frames_lost <= 5
    assert result.centre_error_mean == pytest.approx(1.05, abs=0.5)
    assert result.centre_error_median < 2.0
    assert result.outline_iou > 0.86
    # the box columns carry TEST_BOX, drawn loosely (IoU 0.70 with the true box on frame 0),
    # along with the contour: their IoU with the true boxes stays that of the drawn box
    assert result.mean_iou == pytest.approx(0.70, abs=0.04)
    # a model placed by the template: the carry is anchored on the first estimate, so the
    # first row's box is the drawn box
    with open(clutter_runs / "test.condensation.csv", newline="") as fh:
        first = next(csv.DictReader(fh))
    got = [float(first[k]) for k in ("bbox_x", "bbox_y", "bbox_w", "bbox_h")]
    assert got == pytest.approx([float(v) for v in TEST_BOX.split(",")], abs=0.002)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_condensation_is_on_the_object_again_after_the_pole(clutter_runs, seed, tmp_path):
    """Back on the object within 5 frames (0.2 s) of the pole's passing, and on it for the rest of the
    clip, whatever the tracking seed (the frames right after the pole are a matter of luck: one
    seed in four comes out of it 9-12 px off for a few frames, another touches the object and
    is 8.3 px off on the next frame)."""
    truth = load_truth(SAMPLE_DATA / "test.truth.csv")
    hidden = np.flatnonzero(truth.visible < 0.995)
    occluded = hidden[(hidden > 60) & (hidden < 110)]  # the pole, around frame 88
    assert 8 <= len(occluded) <= 12
    csv = clutter_runs / "test.condensation.csv"
    if seed:
        run(["track", "-c", CLUTTER, "--model", clutter_runs / "model.yaml", "--template",
             clutter_runs / "head-test.yaml", SAMPLE_DATA / "test.mp4", "-o", tmp_path, "--seed", seed, "--no-rrd"])
        csv = tmp_path / "test.condensation.csv"
    _, frames = _scores(csv)
    err = frames.centre_error[frames.frame > occluded.max()]
    # the first frame from which it is held for ten frames: by the fifth after the pole (0.2 s)
    held = [i for i in range(len(err) - 9) if np.all(err[i:i + 10] <= LOCK_PX)]
    assert held and held[0] <= 4, err[:15]
    assert np.mean(err[held[0]:] <= LOCK_PX) >= 0.95  # and the rest of the clip


def test_kalman_with_the_same_model_loses_lock(clutter_runs):
    result, frames = _scores(clutter_runs / "test.kalman.csv")
    assert result.precision < 0.5, result
    assert result.frames_lost > 80
    # and stays lost: no stretch of 20 frames in lock after the first ten
    in_lock = frames.centre_error[10:] <= LOCK_PX
    longest = max((len(run_) for run_ in "".join("1" if x else "0" for x in in_lock).split("0")), default=0)
    assert longest < 20
    # and says so: its own verdict (its confidence below measurement.lost_below) marks nearly
    # every frame that is more than 20 px off
    csv_path = clutter_runs / "test.kalman.csv"
    own = _column(csv_path, "confidence", frames.frame) < 0.5
    off = frames.centre_error > 20
    assert off.sum() > 100 and own[off].mean() > 0.9
    # The refined outline stays on the head on many of those frames (the flow and the colours
    # follow it where the estimate does not); the reported `lost` takes the region's word only
    # where it still agrees with the estimate, and so marks every frame whose outline has
    # strayed onto the clutter (the head's colours stand out there as on the head)
    flags = _lost_flags(csv_path, frames.frame)
    strayed = frames.outline_iou <= 0.3
    assert strayed.sum() >= 10 and flags[strayed].all()


def test_condensation_says_lost_rarely_while_on_the_object(clutter_runs):
    _, frames = _scores(clutter_runs / "test.condensation.csv")
    flags = _lost_flags(clutter_runs / "test.condensation.csv", frames.frame)
    on = frames.centre_error < 5
    assert on.sum() > 140 and flags[on].mean() < 0.05


def _column(csv_path, name: str, frame_numbers) -> np.ndarray:
    import csv as csv_module

    with open(csv_path, newline="") as fh:
        values = {int(r["frame"]): float(r[name]) for r in csv_module.DictReader(fh)}
    return np.array([values[int(k)] for k in frame_numbers])


def _lost_flags(csv_path, frame_numbers) -> np.ndarray:
    import csv as csv_module

    with open(csv_path, newline="") as fh:
        lost = {int(r["frame"]): r["lost"] == "1" for r in csv_module.DictReader(fh)}
    return np.array([lost[int(k)] for k in frame_numbers])


def test_the_same_seed_gives_the_same_csv_and_another_seed_does_not(clutter_runs, tmp_path):
    common = ["track", "-c", CLUTTER, "--model", clutter_runs / "model.yaml", "--template",
              clutter_runs / "head-test.yaml", SAMPLE_DATA / "test.mp4", "--end", 30, "--no-rrd"]
    for seed, out in ((0, "a"), (0, "b"), (1, "c")):
        run([*common, "--seed", seed, "-o", tmp_path / out])
    csv = [(tmp_path / out / "test.condensation.csv").read_bytes() for out in "abc"]
    assert csv[0] == csv[1]
    assert csv[0] != csv[2]
    # and the first 30 frames of the full run are these
    full = (clutter_runs / "test.condensation.csv").read_bytes().splitlines()
    assert csv[0].splitlines() == full[:31]


# ---------------------------------------------------------------------------------------------
# The multi-modal clip


@pytest.fixture(scope="module")
def three_heads_histograms(clutter_runs):
    """Per-frame tx histograms of CONDENSATION on three_heads.mp4 (configs/three-heads.yaml),
    the template being the one drawn on the training clip."""
    sample_clip("three_heads")
    settings = load_settings(THREE_HEADS)
    with open_video(SAMPLE_DATA / "three_heads.mp4") as video:
        setup = tracking_setup(None, clutter_runs / "head.yaml", settings, video)
        results = list(track_condensation(video, setup.space, setup.dynamics, settings.measurement,
                                          settings, np.random.default_rng(settings.seed), X0=setup.X0))
    edges = results[0].display["hist_edges"] + setup.space.origin[0]
    return np.array([r.display["histogram"] for r in results]), 0.5 * (edges[1:] + edges[:-1])


def _mass_near(hist: np.ndarray, centres: np.ndarray, x: np.ndarray, half: float = 20.0) -> np.ndarray:
    """Mass within ``half`` px of each x: hist (F, B), x (F, 3) -> (F, 3)."""
    near = np.abs(centres[None, None, :] - x[:, :, None]) <= half
    return (hist[:, None, :] * near).sum(axis=-1)


def test_three_heads_histogram_has_a_peak_at_each_head(three_heads_histograms):
    hist, centres = three_heads_histograms
    truth = load_truth(SAMPLE_DATA / "three_heads.truth.csv")
    x = np.column_stack([truth.select(j).cx for j in range(3)])
    assert hist.shape[0] == x.shape[0] == 110
    mass = _mass_near(hist, centres, x)
    # frame 0 is the steady state of the motion model: broad, no peak holds much
    assert mass[0].max() < 0.2 and hist[0].max() < 0.06
    # within two frames the set has found all three, and holds them while the walker
    # (object 2) approaches the others: frames 2-20
    early = slice(2, 21)
    assert np.all(mass[early] >= 0.03), mass[early]
    for k in range(2, 21):
        smooth = np.convolve(hist[k], [0.25, 0.5, 0.25], mode="same")
        peaks = centres[1:-1][(smooth[1:-1] >= smooth[:-2]) & (smooth[1:-1] > smooth[2:]) & (smooth[1:-1] > 0.01)]
        for j in range(3):
            assert np.min(np.abs(peaks - x[k, j])) <= 12, (k, j, peaks)
    # the walker's peak moves with it, from right to left
    walker = [centres[np.argmax(np.where(np.abs(centres - x[k, 2]) <= 25, hist[k], 0))] for k in (2, 20)]
    assert walker[0] - walker[1] == pytest.approx(x[2, 2] - x[20, 2], abs=10)
    # over every frame in which the walker is 50 px or more from both others, three peaks
    # (at least 1 % of the samples each) on most of them
    apart = (np.abs(x[:, 2] - x[:, 0]) > 50) & (np.abs(x[:, 2] - x[:, 1]) > 50)
    assert np.mean(np.all(mass[apart] >= 0.01, axis=1)) >= 0.6
    # and the distribution collapses onto the three peaks: the share of the samples near a
    # head grows from the broad start to most of them within ten frames
    near = mass.sum(axis=1)
    assert near[0] < 0.35 and np.all(near[10:21] >= 0.75)


def test_the_three_heads_motion_model_spreads_its_steady_state_over_the_frame(clutter_runs):
    settings = load_settings(THREE_HEADS)
    assert settings.condensation.init == "steady_state" and settings.observation.likelihood == "truncated"
    with open_video(SAMPLE_DATA / "three_heads.mp4") as video:
        setup = tracking_setup(None, clutter_runs / "head.yaml", settings, video)
        width = video.width
    P = setup.dynamics.steady_state_covariance()
    nx = setup.space.Nx
    std_tx = math.sqrt(P[nx, nx])
    assert std_tx == pytest.approx(200 / math.sqrt(2), rel=0.02)  # rho = 200 px over (tx, ty)
    assert 2 * std_tx > width / 2  # +-2 sd covers the frame from its middle
