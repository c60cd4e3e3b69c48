"""The mode-based multiple-hypothesis tracker (``track --tracker mht``) on the sample training clip.

A template is drawn on frame 0 of ``sample_data/train.mp4`` (the clean clip: one head, plain
background) from the true box; the first ``FRAMES`` frames are tracked through the command line.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA, sample_clip
from trackcli.cli import cli
from trackcli.sample_data import load_truth

FRAMES = 80
K = 3  # the default mht.modes


def run(args, code: int = 0):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result


def rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("mht")


@pytest.fixture(scope="module")
def truth():
    return load_truth(SAMPLE_DATA / "train.truth.csv").select(0)


@pytest.fixture(scope="module")
def setup(work, truth) -> tuple[Path, Path]:
    clip = sample_clip("train")
    x, y, w, h = truth.bbox_x[0], truth.bbox_y[0], truth.bbox_w[0], truth.bbox_h[0]
    template = work / "head.yaml"
    run(["draw", clip, "--box", f"{x - 0.1 * w:.1f},{y - 0.1 * h:.1f},{1.2 * w:.1f},{1.2 * h:.1f}", "-o", template])
    return clip, template


def track(setup, work: Path, name: str, tracker: str, config: str = "", *extra) -> list[dict[str, str]]:
    clip, template = setup
    cfg = work / f"{name}.yaml"
    cfg.write_text(f"video:\n  end: {FRAMES}\n{config}", encoding="utf-8")
    out = work / name
    run(["track", clip, "--template", template, "--tracker", tracker, "-c", cfg, "-o", out, "--no-rrd", *extra])
    return rows(out / f"train.{tracker}.csv")


@pytest.fixture(scope="module")
def default_rows(setup, work):
    return track(setup, work, "mht-default", "mht")


def test_one_mode_one_seed_one_step_is_the_kalman_tracker(setup, work):
    """With one mode, its prediction as the only seed and one Gauss-Newton step, each frame is
    exactly the Kalman tracker's predict-measure-assimilate with the same gates."""
    kal = track(setup, work, "kalman", "kalman")
    one = track(setup, work, "mht-one", "mht", "mht:\n  modes: 1\n  samples: 1\n  iterations: 1\n")
    assert len(one) == len(kal) == FRAMES
    for key in ("cx", "cy", "bbox_x", "bbox_y", "bbox_w", "bbox_h"):
        a = np.array([float(r[key]) for r in kal])
        b = np.array([float(r[key]) for r in one])
        assert np.max(np.abs(a - b)) < 1.0, key
    assert all(r["modes"] == "1" and float(r["w_mode1"]) == 1.0 for r in one)


def test_modes_are_reported_and_bounded(default_rows):
    assert len(default_rows) == FRAMES
    for r in default_rows:
        n = int(float(r["modes"]))
        assert 1 <= n <= K
        w = [float(r[f"w_mode{j}"] or "nan") for j in range(1, K + 1)]  # absent modes: empty cells
        assert math.isclose(sum(w[:n]), 1.0, rel_tol=1e-6)
        assert all(a >= b for a, b in zip(w[:n], w[1:n]))
        assert all(math.isnan(v) for v in w[n:])
        assert all(math.isfinite(float(r[f"cx_mode{j}"])) for j in range(1, n + 1))
        # the estimate is the heaviest mode
        assert abs(float(r["cx_mode1"]) - float(r["cx"])) < 0.01


def test_mht_follows_the_head_on_the_clean_clip(default_rows, truth):
    frames = np.array([int(r["frame"]) for r in default_rows])
    est = np.array([[float(r["cx"]), float(r["cy"])] for r in default_rows])
    err = np.hypot(*(est - np.column_stack([truth.cx, truth.cy])[frames]).T)
    assert err.mean() < 2.0 and err.max() < 6.0
    assert not any(r["lost"] in ("1", "True", "true") for r in default_rows)


def test_same_seed_same_track(setup, work, default_rows):
    again = track(setup, work, "mht-again", "mht")
    assert again == default_rows


@pytest.mark.parametrize("config, message", [
    ("mht:\n  modes: 0\n", "mht.modes"),
    ("mht:\n  samples: -1\n", "mht.samples"),
    ("mht:\n  merge_distance: 0\n", "mht.merge_distance"),
    ("mht:\n  iterations: many\n", "mht.iterations"),
    ("mht:\n  spread: 0\n", "mht.spread"),
])
def test_bad_settings_are_one_line_errors(setup, work, config, message):
    clip, template = setup
    cfg = work / "bad.yaml"
    cfg.write_text(config, encoding="utf-8")
    result = run(["track", clip, "--template", template, "--tracker", "mht", "-c", cfg, "-o", work / "bad"], code=3)
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]


def test_smoothing_an_mht_track_is_refused(setup, work):
    clip, template = setup
    result = run(["track", clip, "--template", template, "--tracker", "mht", "--smooth", "-o", work / "s"], code=3)
    assert "--smooth" in result.output and len(result.output.strip().splitlines()) == 1


@pytest.mark.parametrize("shape_space", ["translation", "affine"])
def test_mht_runs_on_other_shape_spaces(setup, work, truth, shape_space):
    got = track(setup, work, f"mht-{shape_space}", "mht", f"shape_space: {shape_space}\n")
    assert len(got) == FRAMES
    assert all(1 <= int(float(r["modes"])) <= K for r in got)
    err = np.hypot(float(got[-1]["cx"]) - truth.cx[FRAMES - 1], float(got[-1]["cy"]) - truth.cy[FRAMES - 1])
    assert err < 5.0


def test_mht_follows_an_open_curve(setup, work):
    clip, _ = setup
    template = work / "open.yaml"
    run(["draw", clip, "--points", "190,230 200,140 240,105 280,140 290,230", "--open", "-o", template])
    cfg = work / "open-config.yaml"
    cfg.write_text("video:\n  end: 20\n", encoding="utf-8")
    run(["track", clip, "--template", template, "--tracker", "mht", "-c", cfg, "-o", work / "open", "--no-rrd"])
    got = rows(work / "open" / "train.mht.csv")
    assert len(got) == 20 and all(math.isfinite(float(r["cx"])) for r in got)
