"""Bad input and interrupted runs: every command refuses with one line, leaves nothing behind.

The sweep runs each command line of :data:`CASES` through the real entry point in its own
process (see ``forked_cli.py``: forked from one warm interpreter, so a hundred cases cost
seconds, not minutes), each in an empty working folder, and checks:

- the documented exit code (README, "Exit codes");
- exactly one line on stderr, ``Error: ...``, naming the file or option at fault;
- no traceback;
- nothing left in the working folder (no output folder, no ``.part`` file);
- every input file unchanged (a digest of the inputs folder after each case);
- peak resident memory well under 1 GiB (the child's own ``ru_maxrss``; a case that goes
  beyond 1 GiB is killed on the spot, so a runaway allocation fails fast instead of swapping).

A few cases also run through the installed ``trackcli`` script in a fresh interpreter.
Below the sweep, one test per defect of the bad-input report checks the fix in detail.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from conftest import CLIP_SIZE, ellipse_frame
from trackcli.cli import cli

FRAMES = 24
IN = "../in/"  # the inputs folder, seen from a case's working folder
LONG_NAME = "x" * 300 + ".yaml"  # longer than any file system allows

BILLION_LAUGHS = """\
seed: &l9 [&l8 [&l7 [&l6 [&l5 [&l4 [&l3 [&l2 [&l1 [lol, lol, lol, lol, lol, lol, lol, lol, lol],
  *l1, *l1, *l1, *l1, *l1, *l1, *l1, *l1], *l2, *l2, *l2, *l2, *l2, *l2, *l2, *l2],
  *l3, *l3, *l3, *l3, *l3, *l3, *l3, *l3], *l4, *l4, *l4, *l4, *l4, *l4, *l4, *l4],
  *l5, *l5, *l5, *l5, *l5, *l5, *l5, *l5], *l6, *l6, *l6, *l6, *l6, *l6, *l6, *l6],
  *l7, *l7, *l7, *l7, *l7, *l7, *l7, *l7], *l8, *l8, *l8, *l8, *l8, *l8, *l8, *l8]
"""


# ---------------------------------------------------------------------------------------------
# Inputs


def write_clip(path: Path, frames: int = FRAMES) -> Path:
    rng = np.random.default_rng(5)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, CLIP_SIZE)
    assert writer.isOpened()
    for k in range(frames):
        writer.write(ellipse_frame(rng, k))
    writer.release()
    return path


def write_template(path: Path, clip: str, size=CLIP_SIZE, points=None) -> Path:
    from trackcli.shapes.draw import ellipse_outline
    from trackcli.run.drawing import fit_template
    from trackcli.shapes.template import save_template

    outline = ellipse_outline(70.0, 60.0, 28.0, 36.0) if points is None else np.asarray(points, float)
    save_template(path, fit_template(outline, 12, clip=clip, frame=0, frame_size=size, source="test"))
    return path


def image_folder(path: Path, sizes, corrupt: int | None = None) -> Path:
    path.mkdir()
    rng = np.random.default_rng(3)
    for k, (w, h) in enumerate(sizes):
        img = cv2.resize(ellipse_frame(rng, k), (w, h))
        if k == corrupt:
            (path / f"{k + 1:04d}.jpg").write_bytes(b"\xff\xd8 not really a JPEG")
        else:
            cv2.imwrite(str(path / f"{k + 1:04d}.jpg"), img)
    return path


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    """``ROOT/in``: every input the cases use (clips, templates, model, configs, manifests)."""
    root = tmp_path_factory.mktemp("bad-input")
    d = root / "in"
    d.mkdir()
    clip = write_clip(d / "clip.avi")
    data = clip.read_bytes()
    write_clip(d / "long.avi", 60)
    (d / "trunc.avi").write_bytes((d / "long.avi").read_bytes()[: len((d / "long.avi").read_bytes()) // 2])
    (d / "empty.mp4").write_bytes(b"")
    (d / "garbage.mp4").write_bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    assert len(data) > 0
    image_folder(d / "oddsize", [CLIP_SIZE, CLIP_SIZE, (200, 100), CLIP_SIZE])
    image_folder(d / "corrupt", [CLIP_SIZE] * 4, corrupt=2)
    image_folder(d / "tiny", [(1, 1)] * 3)
    (d / "noframes").mkdir()
    (d / "noframes" / "notes.txt").write_text("no images here\n")
    # templates, each drawn (as far as the file says) on the clip it is used with
    write_template(d / "t.yaml", "clip.avi")
    write_template(d / "t_long.yaml", "long.avi")
    write_template(d / "t_trunc.yaml", "trunc.avi")
    write_template(d / "t_oddsize.yaml", "oddsize")
    write_template(d / "t_corrupt.yaml", "corrupt")
    write_template(d / "t_other_size.yaml", "clip.avi", size=(320, 240))
    t = yaml.safe_load((d / "t.yaml").read_text())
    t["control_points"] = [[50.0, 50.0]] * len(t["control_points"])
    (d / "degenerate.yaml").write_text(yaml.safe_dump(t))
    (d / "points.txt").write_text("10,10\n20,ten\n30,30\n")
    # YAML that is hostile or wrong
    (d / "laughs.yaml").write_text(BILLION_LAUGHS)
    (d / "deep.yaml").write_text("seed: " + "[" * 20000 + "]" * 20000 + "\n")
    (d / "huge.yaml").write_text("# padding\n" * 300_000 + "seed: 1\n")
    (d / "badutf8.yaml").write_bytes(b"seed: \xff\xfe\xfa\n")
    (d / "notmap.yaml").write_text("- 1\n- 2\n")
    (d / "unknown.yaml").write_text("particles: 3\n")
    (d / "wrongtype.yaml").write_text("seed: abc\n")
    (d / "range.yaml").write_text("condensation: {particles: 0}\n")
    (d / "format2.yaml").write_text("format: 2\n")
    (d / "garbage.yaml").write_text("{[: not yaml\n")
    (d / "prev").mkdir()
    (d / "prev" / "clip.condensation.config.yaml").write_text("seed: 4\n")
    # a model and a track
    runner = CliRunner()
    r = runner.invoke(cli, ["learn", "--template", str(d / "t.yaml"), str(clip), "-o", str(d / "model.yaml"),
                            "--cycles", "1", "--no-rrd", "--outdir", str(root / "training")])
    assert r.exit_code == 0, r.output
    r = runner.invoke(cli, ["track", "--tracker", "kalman", "--template", str(d / "t.yaml"), str(clip),
                            "-o", str(root / "tracked"), "--no-rrd"])
    assert r.exit_code == 0, r.output
    shutil.copy(root / "tracked" / "clip.kalman.csv", d / "track.csv")
    lines = (d / "track.csv").read_text().splitlines()
    (d / "badrow.csv").write_text("\n".join(lines[:3] + ["1,not,a,row"]) + "\n")
    (d / "truth.txt").write_text("".join(f"{42 + 2 * k},24,56,72\n" for k in range(FRAMES)))
    (d / "garbage.csv").write_text("this,is\nnot,a track\n")
    (d / "empty.csv").write_text("")
    (d / "truthless").mkdir()
    # manifests
    def manifest(name: str, text: str) -> None:
        (d / name).write_text(text)

    ok_clip = "{clip: clip.avi, template: t.yaml}"
    manifest("m_laughs.yaml", BILLION_LAUGHS.replace("seed:", "defaults:"))
    manifest("m_deep.yaml", "clips: " + "[" * 20000 + "]" * 20000 + "\n")
    manifest("m_garbage.yaml", "{[: not yaml\n")
    manifest("m_unknown.yaml", f"clips: [{ok_clip}]\ncolour: red\n")
    manifest("m_noclip.yaml", "clips: [{clip: absent.avi, template: t.yaml}]\n")
    manifest("m_tracker.yaml", "clips: [{clip: clip.avi, template: t.yaml, tracker: meanshift}]\n")
    manifest("m_dup.yaml", f"clips: [{ok_clip}, {ok_clip}]\n")
    manifest("m_format.yaml", f"format: 2\nclips: [{ok_clip}]\n")
    manifest("m_empty.yaml", "clips: []\n")
    manifest("m_settings.yaml", "clips: [{clip: clip.avi, template: t.yaml, settings: {seed: -3}}]\n")
    manifest("m_template.yaml", "clips: [{clip: clip.avi, template: absent.yaml}]\n")
    manifest("m_ok.yaml", f"clips: [{ok_clip}]\n")
    (d / "ünïcødé clip.avi").write_bytes(data)
    return root


# ---------------------------------------------------------------------------------------------
# The sweep: (id, command line, exit code, text the error line must contain)

CASES = [
    # draw
    ("draw-missing-clip", ["draw", IN + "absent.avi", "--ellipse", "70,60,28,36", "-o", "t.yaml"], 4, "absent.avi"),
    ("draw-empty-file", ["draw", IN + "empty.mp4", "--ellipse", "70,60,28,36", "-o", "t.yaml"], 4, "empty.mp4"),
    ("draw-garbage-video", ["draw", IN + "garbage.mp4", "--ellipse", "70,60,28,36", "-o", "t.yaml"], 4, "garbage.mp4"),
    ("draw-folder-without-images", ["draw", IN + "noframes", "--fps", "25", "--ellipse", "70,60,28,36", "-o", "t.yaml"], 4, "noframes"),
    ("draw-corrupt-frame", ["draw", IN + "corrupt", "--fps", "25", "--frame", "2", "--ellipse", "70,60,28,36", "-o", "t.yaml"], 4,
     "0003.jpg"),
    ("draw-frame-beyond-clip", ["draw", IN + "clip.avi", "--frame", "99", "--ellipse", "70,60,28,36", "-o", "t.yaml"],
     3, "99"),
    ("draw-box-three-numbers", ["draw", IN + "clip.avi", "--box", "1,2,3", "-o", "t.yaml"], 3, "--box"),
    ("draw-box-nan", ["draw", IN + "clip.avi", "--box", "nan,2,30,40", "-o", "t.yaml"], 3, "--box"),
    ("draw-ellipse-outside", ["draw", IN + "clip.avi", "--ellipse", "900,900,20,20", "-o", "t.yaml"], 3, "--ellipse"),
    ("draw-points-outside", ["draw", IN + "clip.avi", "--points", "-90,-90 -50,-90 -70,-50", "-o", "t.yaml"], 3,
     "--points"),
    ("draw-points-on-a-line", ["draw", IN + "clip.avi", "--points", "10,10 30,30 50,50", "-o", "t.yaml"], 3,
     "encloses almost no area"),
    ("draw-points-file-garbage", ["draw", IN + "clip.avi", "--points", IN + "points.txt", "-o", "t.yaml"], 4,
     "points.txt line 2"),
    ("draw-mask-missing", ["draw", IN + "clip.avi", "--mask", IN + "absent.png", "-o", "t.yaml"], 4, "absent.png"),
    ("draw-on-1x1-frames", ["draw", IN + "tiny", "--fps", "25", "--box", "0,0,1,1", "-o", "t.yaml"], 5, "tiny"),
    ("draw-over-its-clip", ["draw", IN + "clip.avi", "--ellipse", "70,60,28,36", "-o", IN + "clip.avi"], 3, "clip.avi"),
    ("draw-preview-is-template", ["draw", IN + "clip.avi", "--ellipse", "70,60,28,36", "-o", "t.yaml",
                                  "--preview", "t.yaml"], 3, "--preview"),
    ("draw-unwritable-folder", ["draw", IN + "clip.avi", "--ellipse", "70,60,28,36", "-o", "/proc/t.yaml"], 4,
     "/proc/t.yaml"),
    ("draw-folder-is-a-file", ["draw", IN + "clip.avi", "--ellipse", "70,60,28,36", "-o", IN + "t.yaml/x.yaml"], 4,
     "t.yaml"),
    ("draw-name-too-long", ["draw", IN + "clip.avi", "--ellipse", "70,60,28,36", "-o", LONG_NAME], 4, "too long"),
    ("draw-n-ctrl-2", ["draw", IN + "clip.avi", "--ellipse", "70,60,28,36", "--n-ctrl", "2", "-o", "t.yaml"], 3,
     "--n-ctrl"),
    ("draw-two-shapes", ["draw", IN + "clip.avi", "--box", "1,2,30,40", "--ellipse", "70,60,28,36", "-o", "t.yaml"],
     2, "--help"),
    ("draw-unicode-missing", ["draw", IN + "ünïcødé absent.avi", "--ellipse", "70,60,28,36", "-o", "t.yaml"], 4,
     "ünïcødé absent.avi"),
    # track
    ("track-missing-clip", ["track", "--template", IN + "t.yaml", IN + "absent.avi"], 4, "absent.avi"),
    ("track-truncated-video", ["track", "--template", IN + "t_trunc.yaml", IN + "trunc.avi", "-o", "out"], 4,
     "trunc.avi"),
    ("track-garbage-video", ["track", "--template", IN + "t.yaml", IN + "garbage.mp4"], 4, "garbage.mp4"),
    ("track-odd-sized-frame", ["track", "--template", IN + "t_oddsize.yaml", IN + "oddsize", "--fps", "25"], 4,
     "oddsize"),
    ("track-corrupt-frame", ["track", "--template", IN + "t_corrupt.yaml", IN + "corrupt", "--fps", "25"], 4,
     "0003.jpg"),
    ("track-template-missing", ["track", "--template", IN + "absent.yaml", IN + "clip.avi"], 4, "absent.yaml"),
    ("track-template-laughs", ["track", "--template", IN + "laughs.yaml", IN + "clip.avi"], 4, "laughs.yaml"),
    ("track-template-other-size", ["track", "--template", IN + "t_other_size.yaml", IN + "clip.avi"], 4, "320x240"),
    ("track-template-degenerate", ["track", "--template", IN + "degenerate.yaml", IN + "clip.avi"], 4,
     "degenerate.yaml"),
    ("track-config-unknown", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-c", IN + "unknown.yaml"], 3,
     "unknown.yaml"),
    ("track-config-laughs", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-c", IN + "laughs.yaml"], 3,
     "laughs.yaml"),
    ("track-config-deep", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-c", IN + "deep.yaml"], 3,
     "deep.yaml"),
    ("track-config-huge", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-c", IN + "huge.yaml"], 3,
     "huge.yaml"),
    ("track-config-not-utf8", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-c", IN + "badutf8.yaml"], 3,
     "badutf8.yaml"),
    ("track-particles-0", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "--particles", "0"], 3,
     "--particles"),
    ("track-seed-negative", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "--seed", "-1"], 3, "--seed"),
    ("track-start-beyond-end", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "--start", "500"], 3,
     "start (500)"),
    ("track-end-before-start", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "--start", "5", "--end", "3"],
     3, "end (3)"),
    ("track-model-garbage", ["track", "--model", IN + "garbage.yaml", IN + "clip.avi"], 4, "garbage.yaml"),
    ("track-model-is-a-template", ["track", "--model", IN + "t.yaml", IN + "clip.avi"], 4, "t.yaml"),
    ("track-outdir-is-a-file", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-o", IN + "t.yaml"], 3,
     "t.yaml"),
    ("track-output-over-its-config", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-o", IN + "prev",
                                      "-c", IN + "prev/clip.condensation.config.yaml"], 3, "-c/--config"),
    ("track-unwritable-outdir", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "-o", "/proc/out"], 4,
     "/proc/out"),
    ("track-nothing-to-track", ["track", IN + "clip.avi"], 2, "--help"),
    # learn
    ("learn-missing-clip", ["learn", "--template", IN + "t.yaml", IN + "absent.avi", "-o", "m.yaml"], 4,
     "absent.avi"),
    ("learn-truncated-clip", ["learn", "--template", IN + "t_trunc.yaml", IN + "trunc.avi", "-o", "m.yaml"], 4,
     "trunc.avi"),
    ("learn-template-missing", ["learn", "--template", IN + "absent.yaml", IN + "clip.avi", "-o", "m.yaml"], 4,
     "absent.yaml"),
    ("learn-template-laughs", ["learn", "--template", IN + "laughs.yaml", IN + "clip.avi", "-o", "m.yaml"], 4,
     "laughs.yaml"),
    ("learn-template-degenerate", ["learn", "--template", IN + "degenerate.yaml", IN + "clip.avi", "-o", "m.yaml"], 4,
     "degenerate.yaml"),
    ("learn-cycles-0", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "-o", "m.yaml", "--cycles", "0"], 3,
     "--cycles"),
    ("learn-shape-space-bogus", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "-o", "m.yaml",
                                 "--shape-space", "bogus"], 3, "--shape-space"),
    ("learn-pca-0", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "-o", "m.yaml", "--shape-space", "pca:0"],
     3, "pca"),
    ("learn-over-its-template", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "-o", IN + "t.yaml"], 3,
     "--template"),
    ("learn-from-tracks-missing", ["learn", "--template", IN + "t.yaml", "--from-tracks", IN + "absent.csv",
                                   "-o", "m.yaml"], 4, "absent.csv"),
    ("learn-from-tracks-garbage", ["learn", "--template", IN + "t.yaml", "--from-tracks", IN + "garbage.csv",
                                   "-o", "m.yaml"], 4, "garbage.csv"),
    ("learn-clips-and-tracks", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "--from-tracks",
                                IN + "track.csv", "-o", "m.yaml"], 2, "--help"),
    ("learn-config-wrong-type", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "-o", "m.yaml",
                                 "-c", IN + "wrongtype.yaml"], 3, "wrongtype.yaml"),
    ("learn-unwritable-outdir", ["learn", "--template", IN + "t.yaml", IN + "clip.avi", "-o", "m.yaml",
                                 "--outdir", "/proc/training"], 4, "/proc/training"),
    # inspect and simulate
    ("inspect-missing", ["inspect", IN + "absent.yaml"], 4, "absent.yaml"),
    ("inspect-garbage", ["inspect", IN + "garbage.yaml"], 4, "garbage.yaml"),
    ("inspect-laughs", ["inspect", IN + "laughs.yaml"], 4, "laughs.yaml"),
    ("inspect-deep", ["inspect", IN + "deep.yaml"], 4, "deep.yaml"),
    ("inspect-huge", ["inspect", IN + "huge.yaml"], 4, "huge.yaml"),
    ("inspect-not-utf8", ["inspect", IN + "badutf8.yaml"], 4, "badutf8.yaml"),
    ("inspect-a-template", ["inspect", IN + "t.yaml"], 4, "t.yaml"),
    ("inspect-not-a-mapping", ["inspect", IN + "notmap.yaml"], 4, "notmap.yaml"),
    ("simulate-missing", ["simulate", IN + "absent.yaml", "-o", "s.rrd"], 4, "absent.yaml"),
    ("simulate-frames-1", ["simulate", IN + "model.yaml", "--frames", "1", "-o", "s.rrd"], 3, "--frames"),
    ("simulate-paths-0", ["simulate", IN + "model.yaml", "--paths", "0", "-o", "s.rrd"], 3, "--paths"),
    ("simulate-bad-size", ["simulate", IN + "model.yaml", "--size", "wide", "-o", "s.rrd"], 3, "--size"),
    ("simulate-size-zero", ["simulate", IN + "model.yaml", "--size", "0,0", "-o", "s.rrd"], 3, "--size"),
    ("simulate-size-negative", ["simulate", IN + "model.yaml", "--size", "-5,10", "-o", "s.rrd"], 3, "--size"),
    ("simulate-size-huge", ["simulate", IN + "model.yaml", "--size", "100000,100000", "-o", "s.rrd"], 3, "--size"),
    ("simulate-over-its-model", ["simulate", IN + "model.yaml", "-o", IN + "model.yaml"], 3, "model.yaml"),
    ("simulate-unwritable", ["simulate", IN + "model.yaml", "-o", "/proc/s.rrd"], 4, "/proc/s"),
    ("simulate-model-laughs", ["simulate", IN + "laughs.yaml", "-o", "s.rrd"], 4, "laughs.yaml"),
    # eval
    ("eval-pred-missing", ["eval", IN + "absent.csv", IN + "truth.txt"], 4, "absent.csv"),
    ("eval-pred-not-a-track", ["eval", IN + "garbage.csv", IN + "truth.txt"], 4, "garbage.csv"),
    ("eval-pred-empty", ["eval", IN + "empty.csv", IN + "truth.txt"], 4, "empty.csv"),
    ("eval-pred-bad-row", ["eval", IN + "badrow.csv", IN + "truth.txt"], 4, "badrow.csv"),
    ("eval-pred-is-a-folder", ["eval", IN + "truthless", IN + "truth.txt"], 3, "truthless"),
    ("eval-truth-missing", ["eval", IN + "track.csv", IN + "absent.txt"], 4, "absent.txt"),
    ("eval-truth-garbage", ["eval", IN + "track.csv", IN + "garbage.yaml"], 4, "garbage.yaml"),
    ("eval-truth-folder-without-boxes", ["eval", IN + "track.csv", IN + "truthless"], 4, "truthless"),
    ("eval-threshold-0", ["eval", IN + "track.csv", IN + "truth.txt", "--threshold", "0"], 3, "--threshold"),
    ("eval-lost-threshold-negative", ["eval", IN + "track.csv", IN + "truth.txt", "--lost-threshold", "-5"], 3,
     "--lost-threshold"),
    ("eval-object-negative", ["eval", IN + "track.csv", IN + "truth.txt", "--object", "-1"], 3, "--object"),
    ("eval-truth-empty", ["eval", IN + "track.csv", IN + "empty.csv"], 4, "empty.csv"),
    # batch
    ("batch-manifest-missing", ["batch", IN + "absent.yaml", "-o", "out"], 4, "absent.yaml"),
    ("batch-manifest-garbage", ["batch", IN + "m_garbage.yaml", "-o", "out"], 3, "m_garbage.yaml"),
    ("batch-manifest-laughs", ["batch", IN + "m_laughs.yaml", "-o", "out"], 3, "m_laughs.yaml"),
    ("batch-manifest-deep", ["batch", IN + "m_deep.yaml", "-o", "out"], 3, "m_deep.yaml"),
    ("batch-manifest-huge", ["batch", IN + "huge.yaml", "-o", "out"], 3, "huge.yaml"),
    ("batch-unknown-key", ["batch", IN + "m_unknown.yaml", "-o", "out"], 3, "colour"),
    ("batch-clip-missing", ["batch", IN + "m_noclip.yaml", "-o", "out"], 4, "absent.avi"),
    ("batch-template-missing", ["batch", IN + "m_template.yaml", "-o", "out"], 4, "absent.yaml"),
    ("batch-bad-tracker", ["batch", IN + "m_tracker.yaml", "-o", "out"], 3, "meanshift"),
    ("batch-duplicate-names", ["batch", IN + "m_dup.yaml", "-o", "out"], 3, "clips[1].name"),
    ("batch-format-2", ["batch", IN + "m_format.yaml", "-o", "out"], 3, "format"),
    ("batch-no-clips", ["batch", IN + "m_empty.yaml", "-o", "out"], 3, "clips"),
    ("batch-invalid-setting", ["batch", IN + "m_settings.yaml", "-o", "out"], 3, "seed"),
    ("batch-jobs-0", ["batch", IN + "m_ok.yaml", "--jobs", "0", "-o", "out"], 3, "--jobs"),
    ("batch-outdir-is-a-file", ["batch", IN + "m_ok.yaml", "-o", IN + "t.yaml"], 3, "t.yaml"),
    # config
    ("config-check-missing", ["config", "check", IN + "absent.yaml"], 3, "absent.yaml"),
    ("config-check-unknown", ["config", "check", IN + "unknown.yaml"], 3, "particles"),
    ("config-check-wrong-type", ["config", "check", IN + "wrongtype.yaml"], 3, "seed"),
    ("config-check-out-of-range", ["config", "check", IN + "range.yaml"], 3, "condensation.particles"),
    ("config-check-format-2", ["config", "check", IN + "format2.yaml"], 3, "format"),
    ("config-check-laughs", ["config", "check", IN + "laughs.yaml"], 3, "laughs.yaml"),
    ("config-check-deep", ["config", "check", IN + "deep.yaml"], 3, "deep.yaml"),
    ("config-check-huge", ["config", "check", IN + "huge.yaml"], 3, "huge.yaml"),
    ("config-check-not-utf8", ["config", "check", IN + "badutf8.yaml"], 3, "badutf8.yaml"),
    ("config-check-not-a-mapping", ["config", "check", IN + "notmap.yaml"], 3, "notmap.yaml"),
    ("config-check-not-yaml", ["config", "check", IN + "garbage.yaml"], 3, "garbage.yaml"),
    ("config-check-a-folder", ["config", "check", IN + "prev"], 3, "prev"),
    ("config-show-laughs", ["config", "show", IN + "laughs.yaml"], 3, "laughs.yaml"),
    # sample-data
    ("sample-data-into-a-file", ["sample-data", IN + "t.yaml", "--truth-only"], 3, "t.yaml"),
    ("sample-data-unwritable", ["sample-data", "/proc/sd", "--truth-only"], 4, "/proc/sd"),
    ("sample-data-frames-1", ["sample-data", "sd", "--frames", "1"], 3, "--frames"),
    ("sample-data-bad-clip", ["sample-data", "sd", "--clip", "zebra"], 3, "--clip"),
    ("sample-data-seed-negative", ["sample-data", "sd", "--seed", "-4"], 3, "--seed"),
    # usage
    ("unknown-command", ["trek", IN + "clip.avi"], 2, "trek"),
    ("unknown-option", ["track", "--template", IN + "t.yaml", IN + "clip.avi", "--particle", "9"], 2, "--particle"),
]

#: Cases also run through the installed `trackcli` script, each in a fresh interpreter.
SCRIPT_CASES = ["draw-garbage-video", "track-truncated-video", "learn-missing-clip", "config-check-laughs",
                "batch-clip-missing", "eval-pred-not-a-track", "inspect-deep"]

#: Peak resident memory allowed to one case (MiB).
MAX_RSS_MIB = 512


@pytest.fixture(scope="module")
def sweep(root) -> dict[str, dict]:
    """Run every case once (in one driver process); results by case id, with the digest of the inputs."""
    cases = []
    for case_id, args, _, _ in CASES:
        cwd = root / case_id
        cwd.mkdir()
        cases.append({"args": args, "cwd": str(cwd)})
    before = _digest(root / "in")
    env = {**os.environ, "CI": "true", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, str(Path(__file__).with_name("forked_cli.py")), str(root / "in")],
                          input=json.dumps(cases), capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr
    results = json.loads(proc.stdout)
    return {"before": before, **{c[0]: r for c, r in zip(CASES, results)}}


def _digest(folder: Path) -> str:
    sys.path.insert(0, str(Path(__file__).parent))
    from forked_cli import digest

    return digest(folder)


def check_refusal(result: dict, code: int, token: str, cwd: Path) -> None:
    stderr = result["stderr"]
    assert "Traceback" not in stderr, stderr
    assert result["code"] == code, f"exit {result['code']}, expected {code}; stderr:\n{stderr}"
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), stderr
    assert token in lines[0], lines[0]
    assert sorted(p.name for p in cwd.iterdir()) == [], "left behind"


def test_the_sweep_covers_every_command_a_dozen_ways():
    per_command: dict[str, int] = {}
    for _, args, _, _ in CASES:
        per_command[args[0]] = per_command.get(args[0], 0) + 1
    for command in ("draw", "track", "learn", "eval", "batch", "config"):
        assert per_command[command] >= 12, (command, per_command[command])
    assert per_command["inspect"] + per_command["simulate"] >= 12


@pytest.mark.parametrize(("case_id", "code", "token"), [(c[0], c[2], c[3]) for c in CASES],
                         ids=[c[0] for c in CASES])
def test_bad_input_is_refused_cleanly(sweep, root, case_id, code, token):
    result = sweep[case_id]
    assert not result["killed_for_memory"], "killed: more than 1 GiB resident"
    check_refusal(result, code, token, root / case_id)
    assert result["inputs"] == sweep["before"], "an input was changed"
    assert result["maxrss_mib"] < MAX_RSS_MIB, result["maxrss_mib"]


@pytest.mark.parametrize("case_id", SCRIPT_CASES)
def test_the_installed_script_refuses_the_same_way(root, tmp_path, case_id):
    script = Path(sys.executable).with_name("trackcli")
    args, code, token = next((c[1], c[2], c[3]) for c in CASES if c[0] == case_id)
    cwd = root / f"script-{case_id}"
    cwd.mkdir()
    before = _digest(root / "in")
    proc = subprocess.run([str(script), *args], cwd=cwd, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "CI": "true"})
    check_refusal({"code": proc.returncode, "stderr": proc.stderr}, code, token, cwd)
    assert _digest(root / "in") == before


# ---------------------------------------------------------------------------------------------
# One test per defect of the report


def invoke(args, code: int):
    """Run the CLI in this process; check the exit code and that no exception escaped."""
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}:\n{result.output}"
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output
    return result


def error_line(result) -> str:
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    return lines[0]


@pytest.fixture
def drawn(tmp_path, ellipse_clip):
    """A copy of the small clip and a template drawn on it: (clip, template)."""
    clip = shutil.copy(ellipse_clip, tmp_path / "clip.avi")
    template = tmp_path / "t.yaml"
    invoke(["draw", clip, "--ellipse", "70,60,28,36", "-o", template], 0)
    return Path(clip), template


# 1. draw CLIP -o CLIP overwrote the video


def test_no_command_writes_over_its_own_input(tmp_path, drawn, root):
    clip, template = drawn
    data = clip.read_bytes()
    (tmp_path / "link.avi").symlink_to(clip)
    os.link(clip, tmp_path / "hard.avi")
    for out in (clip, tmp_path / "link.avi", tmp_path / "hard.avi"):
        line = error_line(invoke(["draw", clip, "--ellipse", "70,60,28,36", "-o", out], 3))
        assert "would overwrite the input" in line and "(CLIP)" in line
    assert clip.read_bytes() == data
    model, kept = root / "in" / "model.yaml", template.read_bytes()
    assert "(--template)" in error_line(invoke(["learn", "--template", template, clip, "-o", template], 3))
    assert template.read_bytes() == kept
    kept_model = model.read_bytes()
    assert "(MODEL)" in error_line(invoke(["simulate", model, "-o", model], 3))
    assert model.read_bytes() == kept_model
    config = tmp_path / "out" / "clip.kalman.config.yaml"
    config.parent.mkdir()
    config.write_text("seed: 2\n")
    line = error_line(invoke(["track", "--tracker", "kalman", "--template", template, clip, "-c", config,
                              "-o", config.parent], 3))
    assert "(-c/--config)" in line and config.read_text() == "seed: 2\n"


def test_an_existing_output_is_replaced(tmp_path, drawn):
    clip, template = drawn
    out = tmp_path / "again.yaml"
    out.write_text("old\n")
    invoke(["draw", clip, "--ellipse", "70,60,20,30", "-o", out], 0)
    assert yaml.safe_load(out.read_text())["kind"] == "trackcli-template"


# 2. tracebacks: deep YAML, unwritable output folder, a name too long


def test_file_system_errors_while_writing_name_the_file(tmp_path):
    from trackcli.errors import InputError
    from trackcli.io.outputs import write_text

    with pytest.raises(InputError, match=r"x{300}\.yaml: cannot write \(File name too long\)"):
        write_text(tmp_path / LONG_NAME, "a: 1\n")
    with pytest.raises(InputError, match=r"/proc/t\.yaml: cannot write"):
        write_text("/proc/t.yaml", "a: 1\n")
    assert list(tmp_path.iterdir()) == []


# 3. billion laughs and huge files


def test_yaml_that_expands_or_nests_too_much_is_refused_before_it_is_built():
    from trackcli.errors import ConfigError
    from trackcli.io.outputs import MAX_YAML_NODES, load_yaml_text

    with pytest.raises(ConfigError, match=f"too large once its aliases are expanded \\(more than {MAX_YAML_NODES}"):
        load_yaml_text(BILLION_LAUGHS, "cfg.yaml", ConfigError)
    with pytest.raises(ConfigError, match="nested more than 64 levels"):
        load_yaml_text("a: " + "[" * 65 + "]" * 65, "cfg.yaml", ConfigError)
    with pytest.raises(ConfigError, match="nested more than 64 levels"):
        load_yaml_text("a: " + "[" * 20000 + "]" * 20000, "cfg.yaml", ConfigError)
    with pytest.raises(ConfigError, match="refers to itself"):
        load_yaml_text("&a [*a]", "cfg.yaml", ConfigError)
    # aliases within the limits are fine, and shared as YAML says
    data = load_yaml_text("d: &d {particles: 9}\ne: *d\n", "cfg.yaml", ConfigError)
    assert data == {"d": {"particles": 9}, "e": {"particles": 9}}


def test_a_config_over_the_size_limit_is_refused_without_reading_it(tmp_path):
    from trackcli.io.outputs import MAX_YAML_BYTES

    big = tmp_path / "big.yaml"
    with big.open("w") as fh:
        fh.write("seed: 1\n")
        fh.truncate(MAX_YAML_BYTES + 1)
    line = error_line(invoke(["config", "check", big], 3))
    assert line == f"Error: {big}: too large for a configuration file (2.0 MiB; at most 2 MiB)"


def test_messages_about_huge_values_stay_short(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("seed: [" + ", ".join(["12345"] * 20000) + "]\n")
    line = error_line(invoke(["config", "check", cfg], 3))
    assert "seed: expected an integer >= 0, got [12345, 12345" in line and len(line) < 200


# 4. half-finished runs left the effective configuration behind


def test_a_failed_run_leaves_earlier_outputs_as_they_were(root, tmp_path):
    out = tmp_path / "out"
    invoke(["track", "--template", root / "in" / "t_long.yaml", root / "in" / "long.avi", "-o", out,
            "--particles", "50"], 0)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert sorted(before) == ["long.condensation.config.yaml", "long.condensation.csv", "long.condensation.rrd"]
    trunc = tmp_path / "long.avi"  # the same name, truncated: the run fails half-way
    trunc.write_bytes((root / "in" / "trunc.avi").read_bytes())
    line = error_line(invoke(["track", "--template", root / "in" / "t_long.yaml", trunc, "-o", out, "-c",
                              tmp_path / "absent.yaml"], 3))
    assert "absent.yaml" in line
    line = error_line(invoke(["track", "--template", root / "in" / "t_long.yaml", trunc, "-o", out,
                              "--particles", "50"], 4))
    assert "decoding stops at frame" in line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_learn_on_a_missing_clip_creates_no_training_folder(tmp_path, drawn):
    _, template = drawn
    invoke(["learn", "--template", template, tmp_path / "absent.avi", "-o", tmp_path / "m.yaml"], 4)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.avi", "t.png", "t.yaml"]


# 5. Ctrl-C on `batch --jobs 2` sometimes left a .rrd.part (the run itself is
#    tests/test_batch.py::test_ctrl_c_on_a_two_process_batch); here, the moments that leaked


def test_an_interrupt_just_after_rerun_opened_the_file_leaves_no_part(tmp_path, monkeypatch):
    """The leak: a worker interrupted inside Recording.__enter__, after Rerun created the file."""
    import rerun as rr

    from trackcli.io.recording import Recording

    def interrupted(self, name):
        raise KeyboardInterrupt

    monkeypatch.setattr(rr.RecordingStream, "send_recording_name", interrupted)
    with pytest.raises(KeyboardInterrupt):
        with Recording(tmp_path / "run.rrd", recording_id="run"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_an_interrupted_job_stops_at_a_frame_and_leaves_nothing(tmp_path, drawn):
    from trackcli.run import batch
    from trackcli.settings import load_settings

    clip, template = drawn
    job = batch.Job(name="clip", clip=str(clip), settings=load_settings(None, {"condensation.particles": 30}),
                    template=str(template))
    asked = []

    def interrupted() -> bool:
        asked.append(1)
        return len(asked) > 3

    with pytest.raises(KeyboardInterrupt):
        batch.run_job(job, tmp_path / "out", interrupted=interrupted)
    assert len(asked) == 4  # stopped at the fourth frame, not at some arbitrary point
    assert list((tmp_path / "out" / "clip").iterdir()) == []
    # interrupted after the last frame, before result.json: the complete outputs go too
    with pytest.raises(KeyboardInterrupt):
        batch.run_job(job, tmp_path / "out", interrupted=lambda: len(asked) > 50 or asked.append(1) is None
                      and len(asked) > 4 + 6)
    assert list((tmp_path / "out" / "clip").iterdir()) == []


def test_a_worker_interrupted_before_its_job_refuses_it(monkeypatch):
    from trackcli.run import executors

    monkeypatch.setattr(executors, "_interrupted", True)
    with pytest.raises(KeyboardInterrupt):
        executors._worker_job(None, "unused")


def test_the_parent_removes_what_unfinished_jobs_left(tmp_path):
    from trackcli.run import batch
    from trackcli.settings import Settings

    jobs = [batch.Job(name=n, clip="c.avi", settings=Settings(), template="t.yaml") for n in ("a", "b")]
    for job, files in zip(jobs, ([".a.condensation.rrd.part", ".a.condensation.csv.part", "a.condensation.csv"],
                                 ["b.condensation.csv", "b.condensation.config.yaml", "result.json"])):
        (tmp_path / job.name).mkdir()
        for f in files:
            (tmp_path / job.name / f).write_text("x")
    batch._sweep_unfinished(jobs, tmp_path)
    assert list((tmp_path / "a").iterdir()) == []  # unfinished: everything goes
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == [  # finished (result.json): kept
        "b.condensation.config.yaml", "b.condensation.csv", "result.json"]


# 6. accepted nonsense (outlines off the frame and 1x1 frames are in the sweep)


def test_a_template_that_does_not_outline_anything_is_warned_about(tmp_path, drawn, caplog):
    """A template on plain background scores no better than clutter on its own frame: the run
    goes on, but says that its lost verdict cannot be trusted."""
    clip, template = drawn
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        invoke(["track", "--template", template, clip, "-o", tmp_path / "out", "--particles", "30", "--no-rrd"], 0)
    assert "no more object-like than clutter" not in caplog.text
    blank = tmp_path / "blank.yaml"  # the same size, on the empty top-right of the frame
    invoke(["draw", clip, "--ellipse", "130,30,14,18", "-o", blank], 0)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        invoke(["track", "--template", blank, clip, "-o", tmp_path / "out", "--particles", "30", "--no-rrd"], 0)
    assert "clip: the template scores" in caplog.text and "the lost verdict and the confidence will be " \
        "unreliable" in caplog.text


def test_a_template_from_another_clip_is_warned_about(tmp_path, drawn, caplog):
    clip, template = drawn
    other = shutil.copy(clip, tmp_path / "other.avi")
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        invoke(["track", "--template", template, other, "-o", tmp_path / "out", "--particles", "30", "--no-rrd"], 0)
    assert f"{template} was drawn on {clip}, not on {other}: tracking starts where" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        invoke(["track", "--template", template, clip, "-o", tmp_path / "out", "--particles", "30", "--no-rrd"], 0)
    assert "was drawn on" not in caplog.text
    config = tmp_path / "spread.yaml"  # samples spread over the frame: the template does not place them
    config.write_text("condensation: {init: steady_state}\n"
                      "dynamics: {translation: {f: 0.0, beta: 1.0, rho: 2.0, gamma0: null}}\n")
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        invoke(["track", "--template", template, other, "-c", config, "-o", tmp_path / "out", "--particles", "30",
                "--no-rrd"], 0)
    assert "was drawn on" not in caplog.text


# 7. noise and inconsistency on stderr (decoder chatter and exit codes are in the sweep)


def test_an_error_names_its_clip_once(tmp_path, drawn):
    clip, template = drawn
    result = invoke(["track", "--template", template, clip, tmp_path / "absent.avi", "-o", tmp_path / "out",
                     "--particles", "30", "--no-rrd"], 1)
    assert f"Error: {tmp_path / 'absent.avi'}: no such file or folder\n" in result.stderr


def test_a_seed_beyond_64_bits_is_kept_exactly(tmp_path, drawn):
    from rrd_utils import read_column

    clip, template = drawn
    seed = 2**70
    proc = subprocess.run([str(Path(sys.executable).with_name("trackcli")), "-q", "track", "--template", str(template),
                           str(clip), "-o", str(tmp_path), "--particles", "30", "--seed", str(seed)],
                          capture_output=True, text=True, timeout=120, env={**os.environ, "CI": "true"})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr  # no RerunWarning, no OverflowError
    assert read_column(tmp_path / "clip.condensation.rrd", "__properties/trackcli", "seed") == [[str(seed)]]


# 8. recordings: a unique id per run, the seed among the properties, the same content


def test_the_same_run_twice_gives_the_same_recording_under_two_ids(tmp_path, drawn):
    from rerun.chunk import RrdReader

    from rrd_utils import read_column, rrd_cli

    clip, template = drawn
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        invoke(["track", "--template", template, clip, "-o", out, "--particles", "40", "--seed", "7"], 0)
    csv = [(o / "clip.condensation.csv").read_bytes() for o in outs]
    assert csv[0] == csv[1]
    rrd = [o / "clip.condensation.rrd" for o in outs]
    ids = [RrdReader(p).recordings()[0].recording_id for p in rrd]
    assert ids[0] != ids[1] and all(i.startswith("clip-condensation-seed7-") for i in ids)
    for p in rrd:
        assert read_column(p, "__properties/trackcli", "seed") == [["7"]]
        assert read_column(p, "__properties", "RecordingInfo:name") == [["clip-condensation-seed7"]]
    same = rrd_cli("compare", "--unordered", *rrd)
    assert same.returncode == 0, same.stdout + same.stderr
    # and the comparison does see a difference in the data
    invoke(["track", "--template", template, clip, "-o", tmp_path / "c", "--particles", "40", "--seed", "8"], 0)
    other = rrd_cli("compare", "--unordered", rrd[0], tmp_path / "c" / "clip.condensation.rrd")
    assert other.returncode != 0
