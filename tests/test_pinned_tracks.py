"""The trackers' outputs on the sample clips are pinned.

The CSVs in ``tests/data/pinned`` were written by ``trackcli track`` with the commands of
:data:`RUNS`.  Any change of what a tracker computes (a refactor that should change
nothing, a speed-up, a new thread pool) must leave them as they are; a change that is
meant to alter the numbers regenerates them and says why in its commit.
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

# name of the pinned CSV -> arguments of `trackcli track` (paths relative to the repository)
RUNS = {
    "test.condensation.csv": ["sample_data/test.mp4", "--template", "tests/data/pinned/test.template.yaml",
                              "--tracker", "condensation", "--end", "25", "--seed", "3"],
    "test.kalman.csv": ["sample_data/test.mp4", "--template", "tests/data/pinned/test.template.yaml",
                        "--tracker", "kalman", "--end", "25", "--seed", "3"],
    "three_heads.condensation.csv": ["sample_data/three_heads.mp4", "--template",
                                     "tests/data/pinned/three_heads.template.yaml", "--tracker", "condensation",
                                     "--end", "25", "--seed", "5", "-c", "three-heads"],
}


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def _same(a: str, b: str) -> bool:
    if a == b:
        return True
    try:
        x, y = float(a), float(b)
    except ValueError:
        return False
    return math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-9) or (math.isnan(x) and math.isnan(y))


@pytest.mark.parametrize("name", sorted(RUNS))
def test_the_tracks_of_the_sample_clips_are_as_pinned(name, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    res = CliRunner().invoke(cli, ["-q", "track", *RUNS[name], "-o", str(tmp_path), "--no-rrd"])
    assert res.exit_code == 0, res.output
    head_new, new = _rows(tmp_path / name)
    head_old, old = _rows(PINNED / name)
    assert head_new == head_old
    assert len(new) == len(old)
    for i, (r_new, r_old) in enumerate(zip(new, old)):
        bad = [(h, a, b) for h, a, b in zip(head_old, r_new, r_old) if not _same(a, b)]
        assert not bad, f"{name} row {i}: first differences {bad[:4]}"


@pytest.mark.parametrize("threads", ["1", "2"])
def test_the_number_of_threads_does_not_change_the_track(threads, tmp_path, monkeypatch):
    """Scoring the samples in one thread or two gives the pinned CSV, to the digit."""
    monkeypatch.chdir(ROOT)
    name = "test.condensation.csv"
    res = CliRunner().invoke(cli, ["-q", "track", *RUNS[name], "--threads", threads, "-o", str(tmp_path),
                                   "--no-rrd"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / name).read_text() == (PINNED / name).read_text()
