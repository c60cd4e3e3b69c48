"""Coupled structures (003): structure templates and ``--tracker coupled``."""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from trackcli.cli import cli
from trackcli.errors import ConfigError
from trackcli.shapes.structure import parse_part

SIZE = (200, 150)
N_FRAMES = 30
# part centres relative to the face centre, px
PARTS = {"left_eye": (-14.0, -10.0), "right_eye": (14.0, -10.0), "mouth": (0.0, 16.0)}


def face_centre(k: int) -> tuple[float, float]:
    return 70.0 + 1.6 * k, 70.0 + 8.0 * np.sin(k / 6.0)


def write_face_clip(path) -> None:
    """A light oval with three dark blobs (eyes, mouth) moving over a noisy background."""
    rng = np.random.default_rng(3)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, SIZE)
    for k in range(N_FRAMES):
        img = (90 + 20 * rng.standard_normal((SIZE[1], SIZE[0], 3))).clip(0, 255).astype(np.uint8)
        cx, cy = face_centre(k)
        cv2.ellipse(img, ((cx, cy), (52, 66), 0.0), (200, 205, 210), -1, cv2.LINE_AA)
        for name, (dx, dy) in PARTS.items():
            axes = (14, 6) if name == "mouth" else (9, 6)
            cv2.ellipse(img, ((cx + dx, cy + dy), axes, 0.0), (40, 35, 30), -1, cv2.LINE_AA)
        writer.write(img)
    writer.release()


@pytest.fixture(scope="module")
def face(tmp_path_factory):
    d = tmp_path_factory.mktemp("face")
    clip = d / "face.avi"
    write_face_clip(clip)
    cx, cy = face_centre(0)
    parts = []
    for name, (dx, dy) in PARTS.items():
        w, h = (20, 12) if name == "mouth" else (14, 10)
        parts += ["--parts", f"{name}:{cx + dx - w / 2:.1f},{cy + dy - h / 2:.1f},{w},{h}"]
    res = CliRunner().invoke(cli, ["-q", "draw", str(clip), *parts, "-o", str(d / "face.yaml")])
    assert res.exit_code == 0, res.output
    return d, clip, d / "face.yaml"


def test_coupled_keeps_every_part_within_3px(face):
    d, clip, template = face
    res = CliRunner().invoke(cli, ["-q", "track", str(clip), "--template", str(template), "--tracker", "coupled",
                                   "-o", str(d / "out"), "--no-rrd", "--seed", "1"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(d / "out" / "face.coupled.csv", newline="")))
    assert len(rows) == N_FRAMES
    worst = 0.0
    for r in rows:
        cx, cy = face_centre(int(r["frame"]))
        for name, (dx, dy) in PARTS.items():
            err = np.hypot(float(r[f"{name}_x"]) - (cx + dx), float(r[f"{name}_y"]) - (cy + dy))
            worst = max(worst, err)
        assert r["lost"] == "0"
    assert worst <= 3.0, worst
    # the outline follows the structure's centre
    err_c = [np.hypot(float(r["cx"]) - face_centre(int(r["frame"]))[0], float(r["cy"]) - face_centre(int(r["frame"]))[1])
             for r in rows]
    assert max(err_c) <= 4.0


def test_the_same_seed_gives_the_same_coupled_track(face, tmp_path):
    d, clip, template = face
    texts = []
    for out in ("a", "b"):
        res = CliRunner().invoke(cli, ["-q", "track", str(clip), "--template", str(template), "--tracker", "coupled",
                                       "-o", str(tmp_path / out), "--no-rrd", "--seed", "4", "--end", "10"])
        assert res.exit_code == 0, res.output
        texts.append((tmp_path / out / "face.coupled.csv").read_text())
    assert texts[0] == texts[1]


@pytest.mark.parametrize("spec, text", [
    ("eye", "expected NAME:x,y,w,h"),
    ("1eye:1,2,3,4", "expected NAME:x,y,w,h"),
    ("eye:1,2,3", "four numbers"),
    ("eye:a,2,3,4", "must be numbers"),
    ("eye:1,2,2,4", "at least 3x3"),
])
def test_bad_part_specs_are_one_line_errors(spec, text):
    with pytest.raises(ConfigError, match=text):
        parse_part(spec)


def _error_line(res) -> str:
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code != 0 and "Traceback" not in res.output, res.output
    return lines[-1]


def test_structure_templates_are_validated(face, tmp_path):
    d, clip, template = face
    runner = CliRunner()
    # a part outside the frame, and a single part
    res = runner.invoke(cli, ["-q", "draw", str(clip), "--parts", "a:190,140,20,20", "--parts", "b:10,10,8,8",
                              "-o", str(tmp_path / "x.yaml")])
    assert "is not inside the 200x150 frame" in _error_line(res)
    res = runner.invoke(cli, ["-q", "draw", str(clip), "--parts", "a:10,10,8,8", "-o", str(tmp_path / "x.yaml")])
    assert "at least two parts" in _error_line(res)
    # a contour template given to the coupled tracker
    res = runner.invoke(cli, ["-q", "draw", str(clip), "--ellipse", "70,70,26,33", "-o", str(tmp_path / "e.yaml")])
    assert res.exit_code == 0
    res = runner.invoke(cli, ["-q", "track", str(clip), "--template", str(tmp_path / "e.yaml"), "--tracker", "coupled",
                              "-o", str(tmp_path / "o"), "--no-rrd"])
    assert "not a structure template" in _error_line(res)
    # a damaged patch, and a patch of the wrong size
    doc = yaml.safe_load(template.read_text())
    for change, text in ((lambda p: p.update(patch_png="not base64!"), "not a base64 PNG"),
                         (lambda p: p.update(box=[1, 2, 30, 30]), "the patch is")):
        bad = yaml.safe_load(template.read_text())
        change(bad["parts"][0])
        path = tmp_path / "bad.yaml"
        path.write_text(yaml.safe_dump(bad))
        res = runner.invoke(cli, ["-q", "track", str(clip), "--template", str(path), "--tracker", "coupled",
                                  "-o", str(tmp_path / "o2"), "--no-rrd"])
        assert text in _error_line(res)
    assert doc["parts"][0]["name"] == "left_eye"
