"""``track --smooth`` and ``learn --method em`` on the sample training clip."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import rrd_utils as ru
from conftest import SAMPLE_DATA, sample_clip
from trackcli.cli import cli
from trackcli.errors import InputError
from trackcli.sample_data import load_truth

BOX = "172,91,135,155"  # around the head on frame 0 of train.mp4 (as in the README)


def run(args, code: int = 0):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result


def rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def centroid_errors(table: list[dict[str, str]], truth) -> np.ndarray:
    frames = np.array([int(r["frame"]) for r in table])
    est = np.array([[float(r["cx"]), float(r["cy"])] for r in table])
    return np.hypot(*(est - np.column_stack([truth.cx, truth.cy])[frames]).T)


def jitter(table: list[dict[str, str]]) -> float:
    """RMS second difference of the centroid track, px per frame²."""
    c = np.array([[float(r["cx"]), float(r["cy"])] for r in table])
    return float(np.sqrt(np.mean(np.diff(c, 2, axis=0) ** 2)))


@pytest.fixture(scope="module")
def clip() -> Path:
    return sample_clip("train")


@pytest.fixture(scope="module")
def truth():
    return load_truth(SAMPLE_DATA / "train.truth.csv").select(0)


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("smooth_em")


@pytest.fixture(scope="module")
def template(clip, work) -> Path:
    out = work / "head.yaml"
    run(["draw", clip, "--box", BOX, "--n-ctrl", "12", "-o", out])  # the book's 12-point head
    return out


@pytest.fixture(scope="module")
def mle_model(clip, template, work) -> Path:
    """A model learned on the clip: a smoother is only as good as the dynamics it assumes."""
    model = work / "mle.yaml"
    run(["learn", "-c", SAMPLE_DATA.parent / "configs" / "sample-clutter.yaml", "--template", template, clip,
         "-o", model, "--no-rrd"])
    return model


def test_kalman_smoothing_writes_a_second_track_and_contour_and_steadies_the_track(clip, truth, template, work,
                                                                                   mle_model):
    out = work / "kalman"
    result = run(["track", clip, "--model", mle_model, "--template", template, "--tracker", "kalman", "--smooth",
                  "-o", out])
    assert "smoothed -> " in result.output
    filtered, smoothed = rows(out / "train.kalman.csv"), rows(out / "train.kalman.smoothed.csv")
    assert list(filtered[0]) == list(smoothed[0])           # the same track format
    assert [r["frame"] for r in filtered] == [r["frame"] for r in smoothed]
    assert filtered[-1]["X_tx"] == smoothed[-1]["X_tx"]      # the last frame has nothing after it
    assert any(f["X_tx"] != s["X_tx"] for f, s in zip(filtered, smoothed))
    # each frame's smoothed variance is at most the filtered one
    for f, s in zip(filtered, smoothed):
        assert float(s["std_tx"]) <= float(f["std_tx"]) + 1e-9
    err_f, err_s = centroid_errors(filtered, truth), centroid_errors(smoothed, truth)
    assert err_s.mean() <= err_f.mean()
    assert jitter(smoothed) < jitter(filtered)
    rrd = out / "train.kalman.rrd"
    assert ru.count_rows(rrd, "video/smoothed", "LineStrips2D:strips") == len(smoothed)


def test_condensation_smoothing_lowers_the_centre_error_on_the_training_clip(clip, truth, template, work,
                                                                            mle_model):
    """With a model learned on the clip (the smoother is only as good as the dynamics it assumes).

    The particle smoother's transition density is the AR(2) model's: the motion prior's jump
    mixture and the re-acquisition proposal are turned off here, so that the filter samples
    exactly the density the smoother assumes.  The observation model is the clutter density of
    AC eq 12.2, whose smoother likelihood on this clean clip keeps an effective sample size the
    backward pass can work with (the sharper discriminant leaves a handful of samples).
    """
    import yaml

    settings = yaml.safe_load((SAMPLE_DATA.parent / "configs" / "sample-clutter.yaml").read_text(encoding="utf-8"))
    settings.update({"jumps": {"fraction": 0.0}, "reacquire": {"enabled": False}})
    settings["observation"]["likelihood"] = "clutter"
    config = work / "clutter-ar2.yaml"
    config.write_text(yaml.safe_dump(settings), encoding="utf-8")
    model = mle_model
    out = work / "condensation"
    run(["track", clip, "-c", config, "--model", model, "--template", template, "--smooth", "--seed", "0",
         "--no-rrd", "-o", out])
    filtered = rows(out / "train.condensation.csv")
    smoothed = rows(out / "train.condensation.smoothed.csv")
    assert len(smoothed) == len(filtered)
    err_f, err_s = centroid_errors(filtered, truth), centroid_errors(smoothed, truth)
    assert err_s.mean() < err_f.mean()
    # (no claim on jitter here: the smoothed weights have a smaller effective sample size than
    # the filtered ones, and their Monte-Carlo noise makes this track less steady)


def _non_decreasing(path: list[float]) -> bool:
    p = np.asarray(path)
    return bool(np.all(np.diff(p) >= -1e-9 * np.abs(p[1:])))


def test_learn_em_from_the_training_clip_and_from_its_tracks(clip, template, work):
    model = work / "em.yaml"
    result = run(["learn", "--template", template, clip, "-o", model, "--method", "em", "--cycles", "1",
                  "--end", "120", "--no-rrd", "--json"])
    report = json.loads(result.stdout)["learning"]
    assert report["method"] == "em"
    em = report["em"]
    assert em["iterations"] >= 1 and _non_decreasing(em["log_likelihood"])
    # the model file's log-likelihood is that of the returned model (stabilised, if it had to be)
    final = em["stabilised_log_likelihood"] if em["stabilised_log_likelihood"] is not None else em["log_likelihood"][-1]
    assert report["log_likelihood"] == pytest.approx(final)
    saved = yaml.safe_load(model.read_text(encoding="utf-8"))
    assert saved["provenance"]["method"] == "em"
    assert saved["provenance"]["learning"]["em"]["log_likelihood"] == em["log_likelihood"]

    track = work / "em_training" / "train.cycle1.csv"
    from_tracks = work / "em-tracks.yaml"
    text = run(["learn", "--template", template, "--from-tracks", track, "-o", from_tracks, "--method", "em"]).output
    assert "EM " in text and "log-likelihood of the measurements" in text
    saved = yaml.safe_load(from_tracks.read_text(encoding="utf-8"))
    assert saved["provenance"]["method"] == "em"
    assert _non_decreasing(saved["provenance"]["learning"]["em"]["log_likelihood"])


def test_learn_em_from_tracks_without_uncertainty_is_a_one_line_error(template, work, tmp_path):
    bad = tmp_path / "no_std.csv"
    xs = np.cumsum(np.random.default_rng(0).normal(size=(20, 4)), axis=0)
    with open(bad, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "time", "X_tx", "X_ty", "X_scos_m1", "X_ssin"])
        for k, x in enumerate(xs):
            w.writerow([k, k / 25, *x])
    result = run(["learn", "--template", template, "--from-tracks", bad, "-o", tmp_path / "m.yaml",
                  "--method", "em"], code=InputError.exit_code)
    assert result.output.startswith("Error: ") and result.output.count("\n") == 1
    assert "std_tx" in result.output
    assert not (tmp_path / "m.yaml").exists()
