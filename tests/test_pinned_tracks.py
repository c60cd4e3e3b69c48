"""The trackers' outputs on the sample clips are pinned.

The CSVs in ``tests/data/pinned`` were written by ``trackcli track`` with the commands of
:data:`RUNS` (and, with ``--smooth``, :data:`SMOOTHED`).  Any change of what a tracker
computes (a refactor that should change nothing, a speed-up, a new thread pool) must leave
them as they are; a change that is meant to alter the numbers regenerates them and says why
in its commit.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from trackcli.cli import cli

ROOT = Path(__file__).resolve().parents[1]
PINNED = Path(__file__).resolve().parent / "data" / "pinned"



def _run(clip: str, template: str, *more: str, seed: str = "3", end: str = "25") -> list[str]:
    """The arguments of `trackcli track` on ``sample_data/CLIP.mp4`` with ``tests/data/pinned/TEMPLATE``."""
    return [f"sample_data/{clip}.mp4", "--template", f"tests/data/pinned/{template}", *more,
            "--end", end, "--seed", seed]


# name of the pinned CSV -> arguments of `trackcli track` (paths relative to the repository)
RUNS = {
    "test.condensation.csv": _run("test", "test.template.yaml", "--tracker", "condensation"),
    "test.kalman.csv": _run("test", "test.template.yaml", "--tracker", "kalman"),
    "three_heads.condensation.csv": _run("three_heads", "three_heads.template.yaml", "--tracker", "condensation",
                                         "-c", "three-heads", seed="5"),
    "test.mht.csv": _run("test", "test.template.yaml", "--tracker", "mht"),
    # a structure template (draw --parts face:205,125,32,35 --parts shirt_left:185,195,30,30
    # --parts shirt_right:245,195,30,30 on frame 0)
    "test.coupled.csv": _run("test", "test.structure.yaml", "--tracker", "coupled"),
    # mixed-state dynamics (a motion label per sample; draw --box 22,52,36,36 on frame 0)
    "bouncing_ball.condensation.csv": _run("bouncing_ball", "bouncing_ball.template.yaml", "--model",
                                           "examples/bouncing_ball.mixed.yaml", "-c",
                                           "examples/bouncing_ball.settings.yaml", seed="2", end="30"),
    # the papers' observation models (a middle part of the name tells runs of one clip apart)
    "test.clutter.condensation.csv": _run("test", "test.template.yaml", "-c", "tests/data/pinned/clutter.yaml"),
    "three_heads.truncated.mht.csv": _run("three_heads", "three_heads.template.yaml", "--tracker", "mht",
                                          "-c", "tests/data/pinned/truncated.yaml", seed="5"),
}

#: name of a pinned smoothed CSV -> the run of :data:`RUNS` that writes it with ``--smooth``
SMOOTHED = {"test.condensation.smoothed.csv": "test.condensation.csv",
            "test.kalman.smoothed.csv": "test.kalman.csv"}


def _written(name: str) -> str:
    """The file a run of :data:`RUNS` writes: ``CLIP.TRACKER.csv``, without a pin's middle part."""
    parts = name.split(".")
    return ".".join([parts[0], *parts[-2:]])


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def _ulp(text: str) -> float:
    """One unit in the last printed decimal place of a CSV cell."""
    digits = text.split(".", 1)[1] if "." in text else ""
    digits = digits.split("e", 1)[0].split("E", 1)[0]
    return 10.0 ** -len(digits)


def _same(a: str, b: str) -> bool:
    """Equal up to the arithmetic of the installed numpy/OpenCV build.

    Builds of the same versions (and compatible later versions) may differ in the last bits
    of a float (other SIMD paths, another summation order), which moves a printed value by
    a unit in its last place or a relative 1e-6.  A change to what a tracker computes moves
    its outputs far more than that.
    """
    if a == b:
        return True
    try:
        x, y = float(a), float(b)
    except ValueError:
        return False
    if math.isnan(x) and math.isnan(y):
        return True
    return abs(x - y) <= 2 * max(_ulp(a), _ulp(b)) + 1e-5 * max(abs(x), abs(y))


@pytest.mark.parametrize("name", sorted(set(RUNS) - set(SMOOTHED.values())))  # those: with their smoothed pin
def test_the_tracks_of_the_sample_clips_are_as_pinned(name, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    res = CliRunner().invoke(cli, ["-q", "track", *RUNS[name], "-o", str(tmp_path), "--no-rrd"])
    assert res.exit_code == 0, res.output
    _assert_as_pinned(name, tmp_path / _written(name))


@pytest.mark.parametrize("name", sorted(SMOOTHED))
def test_the_smoothed_tracks_are_as_pinned_and_leave_the_track_as_it_was(name, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    track = SMOOTHED[name]
    res = CliRunner().invoke(cli, ["-q", "track", *RUNS[track], "--smooth", "-o", str(tmp_path), "--no-rrd"])
    assert res.exit_code == 0, res.output
    _assert_as_pinned(name, tmp_path / name)
    _assert_as_pinned(track, tmp_path / track)


def _assert_as_pinned(name: str, path: Path) -> None:
    head_new, new = _rows(path)
    head_old, old = _rows(PINNED / name)
    assert head_new == head_old
    assert len(new) == len(old)
    for i, (r_new, r_old) in enumerate(zip(new, old)):
        bad = [(h, a, b) for h, a, b in zip(head_old, r_new, r_old) if not _same(a, b)]
        assert not bad, f"{name} row {i}: first differences {bad[:4]}"


def test_the_number_of_threads_does_not_change_the_track(tmp_path, monkeypatch):
    """Scoring the samples in one thread or two gives the same CSV, to the digit, and the pinned one."""
    monkeypatch.chdir(ROOT)
    name = "test.condensation.csv"
    texts = []
    for threads in ("1", "2"):
        out = tmp_path / threads
        res = CliRunner().invoke(cli, ["-q", "track", *RUNS[name], "--threads", threads, "-o", str(out),
                                       "--no-rrd"])
        assert res.exit_code == 0, res.output
        texts.append((out / name).read_text())
        _assert_as_pinned(name, out / name)
    assert texts[0] == texts[1]


def test_the_discriminant_power_reaches_the_weights_and_leaves_the_papers_models_as_they_are(tmp_path, monkeypatch):
    """``observation.discriminant_power`` changes a default track; under the clutter model
    (AC eq 12.2) the weights are the likelihood itself whatever it says."""
    monkeypatch.chdir(ROOT)
    name = "test.condensation.csv"
    texts = {}
    for label, lines in {"untempered": ["  discriminant_power: 1.0"],
                         "clutter": ["  likelihood: clutter"],
                         "clutter_tempered": ["  likelihood: clutter", "  discriminant_power: 0.2"]}.items():
        cfg = tmp_path / f"{label}.yaml"
        cfg.write_text("observation:\n" + "\n".join(lines) + "\n")
        out = tmp_path / label
        res = CliRunner().invoke(cli, ["-q", "track", *RUNS[name], "-c", str(cfg), "-o", str(out), "--no-rrd"])
        assert res.exit_code == 0, res.output
        texts[label] = (out / name).read_text()
    assert texts["untempered"] != (PINNED / name).read_text()
    assert texts["clutter"] == texts["clutter_tempered"]
