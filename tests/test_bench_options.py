"""The benchmark scripts' options for measuring one setting against the defaults.

``bench/davis.py`` and ``bench/quality.py`` take ``--extra "OPTIONS"`` (passed to ``trackcli
track``) and ``--templates DIR`` (the templates an earlier run left, used instead of drawing
them again).  Each test builds a tiny folder of the script's layout, runs the script twice,
and checks that the second run drew nothing, tracked from the first run's template and with
the option given.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _ellipse_frames(n: int, size=(120, 160)) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """A dark ellipse moving right by 2 px a frame on a light ground: frames (BGR) and masks."""
    images, masks = [], []
    for k in range(n):
        m = np.zeros(size, np.uint8)
        cv2.ellipse(m, ((60 + 2 * k, 60), (40, 56), 0), 255, -1)
        image = np.full((*size, 3), (190, 200, 210), np.uint8)
        image[m > 0] = (40, 60, 150)
        images.append(image)
        masks.append(m)
    return images, masks


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, str(ROOT / "bench" / script), *args], capture_output=True, text=True,
                       env=env, timeout=900)
    assert r.returncode == 0, r.stderr
    return r


def _effective_config(folder: Path) -> dict:
    (path,) = folder.rglob("*.config.yaml")
    return yaml.safe_load(path.read_text())


def test_davis_bench_reuses_templates_and_passes_track_options(tmp_path):
    seq = tmp_path / "davis" / "ellipse"
    (seq / "img").mkdir(parents=True)
    (seq / "masks").mkdir()
    for k, (image, m) in enumerate(zip(*_ellipse_frames(6))):
        cv2.imwrite(str(seq / "img" / f"{k:05d}.jpg"), image)
        cv2.imwrite(str(seq / "masks" / f"{k:05d}.png"), m)
    off = tmp_path / "off.yaml"
    off.write_text("observation:\n  still_weight: 0\n")

    _run("davis.py", str(tmp_path / "davis"), "--work", str(tmp_path / "w1"), "--json", str(tmp_path / "a.json"))
    _run("davis.py", str(tmp_path / "davis"), "--work", str(tmp_path / "w2"), "--json", str(tmp_path / "b.json"),
         "--templates", str(tmp_path / "w1"), "--extra", f"-c {off}")

    (a,), (b,) = json.loads((tmp_path / "a.json").read_text()), json.loads((tmp_path / "b.json").read_text())
    assert a["J"] > 0.8 and b["J"] > 0.8  # both tracked the ellipse
    assert not (tmp_path / "w2" / "ellipse.template.yaml").exists()  # nothing drawn the second time
    assert b["tmpl"] == a["tmpl"] and b["n_ctrl"] == a["n_ctrl"]  # the first run's template
    assert _effective_config(tmp_path / "w1")["observation"]["still_weight"] == 1.0
    assert _effective_config(tmp_path / "w2")["observation"]["still_weight"] == 0.0


def test_quality_bench_reuses_templates_and_passes_track_options(tmp_path):
    clip = tmp_path / "footage" / "ellipse"
    (clip / "img").mkdir(parents=True)
    rows = []
    for k, (image, m) in enumerate(zip(*_ellipse_frames(6))):
        cv2.imwrite(str(clip / "img" / f"{k + 1:04d}.jpg"), image)
        x, y, w, h = cv2.boundingRect(m)
        rows.append(f"{x},{y},{w},{h}")
    (clip / "groundtruth_rect.txt").write_text("\n".join(rows) + "\n")
    off = tmp_path / "off.yaml"
    off.write_text("jumps:\n  brake: 0\n")
    common = ["--seeds", "", "--footage", str(tmp_path / "footage"), "--cache", str(tmp_path / "cache")]

    _run("quality.py", *common, "--keep", str(tmp_path / "k1"), "--json", str(tmp_path / "a.json"))
    _run("quality.py", *common, "--keep", str(tmp_path / "k2"), "--json", str(tmp_path / "b.json"),
         "--templates", str(tmp_path / "k1"), "--extra", f"-c {off}")

    a = json.loads((tmp_path / "a.json").read_text())["trackcli"]["ellipse"]
    b = json.loads((tmp_path / "b.json").read_text())["trackcli"]["ellipse"]
    assert a["p20"] == 1.0 and b["p20"] == 1.0
    # lost counted in the object's size: no frame off by twice it, every frame within a tenth of
    # it, none of them flagged
    assert a["off"] == 0 and a["held"] == a["frames"] and a["lost_held"] == 0
    assert (tmp_path / "k1" / "ellipse.template.yaml").exists()
    assert not (tmp_path / "k2" / "ellipse.template.yaml").exists()  # nothing drawn the second time
    assert _effective_config(tmp_path / "k1")["jumps"]["brake"] == 0.02
    assert _effective_config(tmp_path / "k2")["jumps"]["brake"] == 0.0
