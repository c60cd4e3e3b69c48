"""End to end with the defaults: the light changes over the whole scene while the tracker follows.

A synthetic clip (320 x 240, 25 fps, still camera): a red oval moves over a cluttered
grey-green background with a band of brighter red below; from frame 10 to 40 the light over
the whole scene rises by 30 %, so that the oval's brightness passes the band's on the way, and
it stays there.  Read as it is, the colour model learned on frame 0 takes the brighter oval for
the band, which is background; read in the first frame's exposure, it does not.
"""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from test_reacquire import H, W, background
from trackcli.cli import cli

N = 60
OVAL, BAND = (28, 36, 120), (42, 54, 180)  # BGR; the band is the oval 1.5 times as bright


def light(k: int) -> float:
    return 1.0 + 0.3 * min(max((k - 10) / 30.0, 0.0), 1.0)


def centre(k: int) -> tuple[float, float]:
    return 100.0 + 2.0 * k, 90.0 + 0.5 * k


def write_clip(path: Path) -> Path:
    bg = background(np.random.default_rng(3))  # the re-acquisition clip's cluttered grey-green
    cv2.rectangle(bg, (0, 195), (W - 1, H - 1), BAND, -1)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (W, H))
    assert writer.isOpened()
    for k in range(N):
        img = bg.copy()
        cv2.ellipse(img, (centre(k), (44.0, 56.0), 0.0), OVAL, -1, cv2.LINE_AA)
        writer.write(np.clip(img * light(k), 0, 255).astype(np.uint8))
    writer.release()
    return path


@pytest.fixture(scope="module")
def rows(tmp_path_factory) -> list[dict]:
    out = tmp_path_factory.mktemp("lighting")
    clip = write_clip(out / "oval.avi")
    runner = CliRunner()
    c0 = centre(0)
    r = runner.invoke(cli, ["draw", str(clip), "--box", f"{c0[0] - 24},{c0[1] - 30},48,60", "-o", str(out / "t.yaml")],
                      catch_exceptions=False)
    assert r.exit_code == 0, r.output
    r = runner.invoke(cli, ["track", "--template", str(out / "t.yaml"), str(clip), "-o", str(out), "--no-rrd",
                            "--seed", "0"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    with open(out / "oval.condensation.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_the_object_is_held_and_called_held_while_the_light_changes(rows):
    assert len(rows) == N
    err = [float(np.hypot(float(r["cx"]) - centre(int(r["frame"]))[0], float(r["cy"]) - centre(int(r["frame"]))[1]))
           for r in rows]
    assert max(err) < 6.0
    assert not any(r["lost"] == "1" for r in rows)
    brighter = [float(r["confidence"]) for r in rows if light(int(r["frame"])) >= 1.2]
    assert min(brighter) > 0.85  # as confident as before the change (read as it is: 0.6-0.7)
