"""Tests for the command line: help, exit codes, one-line errors, and happy paths for `draw`."""

from __future__ import annotations

import logging

import click
import cv2
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from conftest import CLIP_DRIFT, CLIP_ELLIPSE, CLIP_FRAMES, CLIP_SIZE, CONFIGS
from trackcli import __version__
from trackcli.cli import cli
from trackcli.settings import Settings, render_commented, settings_from_dict
from trackcli.shapes.draw import ellipse_outline, polygon_mask
from trackcli.segment.masks import mask_iou
from trackcli.shapes.spline import dense_polygon
from trackcli.shapes.template import load_template


def run(args, code: int):
    """Invoke the CLI; check the exit code and that no Python exception escaped."""
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result


def one_line_error(result) -> str:
    """The single ``Error: ...`` line a library error prints on stderr."""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("Error: "), result.stderr
    return lines[0]


def usage_error(result) -> str:
    """The single ``Error: ...`` line of a usage error, which points to the command's help."""
    line = one_line_error(result)
    assert "--help')" in line, line
    return line


def all_commands(group: click.Group, prefix: tuple[str, ...] = ()):
    for name, cmd in sorted(group.commands.items()):
        yield (*prefix, name)
        if isinstance(cmd, click.Group):
            yield from all_commands(cmd, (*prefix, name))


COMMANDS = list(all_commands(cli))


@pytest.fixture
def template_file(tmp_path, ellipse_clip):
    out = tmp_path / "ellipse.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", out], 0)
    return out


# ---------------------------------------------------------------------------------------------
# Help and version


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_top_level_help(flag):
    result = run([flag], 0)
    assert result.output.startswith("Usage: ")
    for name in ("draw", "learn", "track", "eval", "config"):
        assert name in result.output


def test_version():
    result = run(["--version"], 0)
    assert result.output.strip() == f"trackcli, version {__version__}"


def test_every_pipeline_command_is_there():
    assert {("draw",), ("track",), ("learn",), ("eval",), ("inspect",), ("simulate",), ("config", "show"),
            ("config", "check")} <= set(COMMANDS)


@pytest.mark.parametrize("command", COMMANDS, ids=[" ".join(c) for c in COMMANDS])
def test_every_command_help(command):
    result = run([*command, "--help"], 0)
    assert result.output.startswith("Usage: ")
    assert " ".join(command) in result.output.splitlines()[0]


def test_verbosity_flags_are_accepted():
    run(["-q", "config", "show"], 0)
    run(["-vv", "config", "show"], 0)


# ---------------------------------------------------------------------------------------------
# config


def test_config_show_prints_the_defaults_as_yaml():
    result = run(["config", "show"], 0)
    assert settings_from_dict(yaml.safe_load(result.stdout)) == Settings()


def test_config_show_comments_is_the_committed_default_file():
    result = run(["config", "show", "--comments"], 0)
    assert result.stdout == render_commented()
    assert result.stdout == (CONFIGS / "default.yaml").read_text(encoding="utf-8")


def test_config_show_with_a_file_applies_it(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("seed: 42\ncondensation:\n  particles: 64\n", encoding="utf-8")
    shown = yaml.safe_load(run(["config", "show", p], 0).stdout)
    assert shown["seed"] == 42 and shown["condensation"]["particles"] == 64
    assert shown["kalman"] == yaml.safe_load(run(["config", "show"], 0).stdout)["kalman"]


@pytest.mark.parametrize("name", [p.name for p in sorted(CONFIGS.glob("*.yaml"))])
def test_config_check_committed_files(name):
    result = run(["config", "check", CONFIGS / name], 0)
    assert result.stdout.strip().endswith(": OK")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("measurement:\n  n_normals: abc\n", "measurement.n_normals: expected an integer in [3, 1000], got 'abc'"),
        ("seed: true\n", "seed: expected an integer >= 0, got True"),
        ("kalman: 3\n", "kalman: expected a mapping of settings, got 3"),
        ("shape_space: rigid\n", "shape_space: expected one of 'translation', 'similarity', 'affine', got 'rigid'"),
        ("dynamics:\n  translation:\n    foo: 1\n", "dynamics.translation.foo: unknown setting"),
        ("seed: 1\nkalman: {rho_f: 2\n", "line 3: "),
        ("- 1\n- 2\n", "expected a mapping of settings at the top level"),
    ],
    ids=["type", "bool", "scalar-section", "choice", "unknown", "syntax", "list"],
)
def test_config_check_bad_file(tmp_path, text, expected):
    p = tmp_path / "bad.yaml"
    p.write_text(text, encoding="utf-8")
    line = one_line_error(run(["config", "check", p], 3))
    assert line.startswith(f"Error: {p}")
    assert expected in line


def test_config_check_missing_file(tmp_path):
    line = one_line_error(run(["config", "check", tmp_path / "absent.yaml"], 3))
    assert "no such configuration file" in line


def test_config_show_bad_file(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("video:\n  step: 0\n", encoding="utf-8")
    assert "video.step: expected an integer >= 1, got 0" in one_line_error(run(["config", "show", p], 3))


# ---------------------------------------------------------------------------------------------
# draw: user mistakes


def test_draw_without_a_shape_is_a_usage_error(tmp_path, ellipse_clip):
    line = usage_error(run(["draw", ellipse_clip, "-o", tmp_path / "t.yaml"], 2))
    assert "give exactly one of --points, --ellipse, --box, --mask" in line
    assert not (tmp_path / "t.yaml").exists()


def test_draw_with_two_shapes_is_a_usage_error(tmp_path, ellipse_clip):
    result = run(["draw", ellipse_clip, "--box", "40,20,60,80", "--ellipse", "70,60,28,36", "-o", tmp_path / "t.yaml"], 2)
    assert "(got --ellipse, --box)" in usage_error(result)


def test_draw_open_without_points_is_a_usage_error(tmp_path, ellipse_clip):
    result = run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "--open", "-o", tmp_path / "t.yaml"], 2)
    assert "--open goes with --points" in usage_error(result)


def test_draw_without_output_is_a_usage_error(ellipse_clip):
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36"], 2)


def test_draw_missing_clip(tmp_path):
    clip = tmp_path / "absent.mp4"
    line = one_line_error(run(["draw", clip, "--box", "1,2,30,40", "-o", tmp_path / "t.yaml"], 4))
    assert str(clip) in line


@pytest.mark.parametrize(
    ("box", "text"),
    [
        ("1,2,3", "--box: expected 4 numbers, got 3"),
        ("a,b,c,d", "--box: expected comma-separated numbers"),
        ("40,20,0,80", "width and height must be positive"),
        ("500,500,30,30", "outside the 160x120 frame"),
        ("60,50,5,5", "--box 60,50,5,5: spans only 5x5 px (at least 8 px each way)"),
        ("1,2,3,4,5", "--box: expected 4 numbers, got 5"),
        ("nan,2,30,40", "--box"),
    ],
)
def test_draw_bad_box(tmp_path, ellipse_clip, box, text):
    line = one_line_error(run(["draw", ellipse_clip, "--box", box, "-o", tmp_path / "t.yaml"], 3))
    assert text in line
    assert not (tmp_path / "t.yaml").exists()


@pytest.mark.parametrize(
    ("option", "value", "text"),
    [
        ("--ellipse", "70,60,28", "--ellipse: expected 4 to 5 numbers, got 3"),
        ("--ellipse", "70,60,-28,36", "semi-axes must be positive"),
        ("--points", "10,10 20,10 20", "odd count"),
        ("--points", "no-such-points.txt", "neither x,y pairs nor an existing points file"),
    ],
)
def test_draw_bad_shape_values(tmp_path, ellipse_clip, option, value, text):
    assert text in one_line_error(run(["draw", ellipse_clip, option, value, "-o", tmp_path / "t.yaml"], 3))


def test_draw_bad_mask_files(tmp_path, ellipse_clip):
    out = tmp_path / "t.yaml"
    assert "no such mask file" in one_line_error(run(["draw", ellipse_clip, "--mask", tmp_path / "m.png", "-o", out], 4))
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((10, 10), 255, np.uint8))
    assert "mask is 10x10 but the frame is 160x120" in one_line_error(
        run(["draw", ellipse_clip, "--mask", small, "-o", out], 4))
    empty = tmp_path / "empty.png"
    cv2.imwrite(str(empty), np.zeros((120, 160), np.uint8))
    assert "no object" in one_line_error(run(["draw", ellipse_clip, "--mask", empty, "-o", out], 5))


def test_draw_frame_beyond_the_clip(tmp_path, ellipse_clip):
    result = CliRunner().invoke(cli, ["draw", str(ellipse_clip), "--frame", "50", "--ellipse", "70,60,28,36",
                                      "-o", str(tmp_path / "t.yaml")])
    assert result.exit_code != 0
    assert "Traceback" not in result.output and isinstance(result.exception, SystemExit)
    line = one_line_error(result)
    assert "frame index 50 is out of range" in line and f"0..{CLIP_FRAMES - 1}" in line
    assert not (tmp_path / "t.yaml").exists()


def test_draw_negative_frame_is_an_invalid_option_value(tmp_path, ellipse_clip):
    result = run(["draw", ellipse_clip, "--frame", "-1", "--ellipse", "70,60,28,36", "-o", tmp_path / "t.yaml"], 3)
    assert "'--frame'" in one_line_error(result)


def test_draw_too_few_control_points_for_the_degree(tmp_path, ellipse_clip):
    result = run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "--n-ctrl", "3", "--degree", "4",
                  "-o", tmp_path / "t.yaml"], 3)
    assert "needs at least 5 control points" in one_line_error(result)


# ---------------------------------------------------------------------------------------------
# draw: happy paths on the synthetic clip


def check_outputs(out, png, clip, frame: int):
    t = load_template(out)
    assert t.frame_size == CLIP_SIZE and t.frame == frame and t.clip == str(clip)
    image = cv2.imread(str(png))
    assert image is not None and image.shape == (CLIP_SIZE[1], CLIP_SIZE[0], 3)
    return t


def region_iou(t, frame: int) -> float:
    cx, cy, a, b = CLIP_ELLIPSE
    truth = polygon_mask(ellipse_outline(cx + CLIP_DRIFT * frame, cy, a, b), CLIP_SIZE)
    return mask_iou(polygon_mask(dense_polygon(t.Q, t.basis(), 400), CLIP_SIZE), truth)


def test_draw_ellipse_writes_template_and_preview(tmp_path, ellipse_clip):
    out = tmp_path / "sub" / "head.yaml"
    result = run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "--n-ctrl", "10", "-o", out], 0)
    png = out.with_suffix(".png")
    assert result.stdout.strip() == f"wrote {out} and {png}"
    t = check_outputs(out, png, ellipse_clip, 0)
    assert t.n_ctrl == 10 and t.degree == 2 and t.closed
    assert t.source == "ellipse 70,60,28,36"
    assert region_iou(t, 0) >= 0.97
    assert not list(out.parent.glob(".*.part"))


def test_draw_box_on_a_later_frame_finds_the_object(tmp_path, ellipse_clip):
    k = 4
    cx, cy, a, b = CLIP_ELLIPSE
    box = f"{cx + CLIP_DRIFT * k - 1.25 * a:.1f},{cy - 1.2 * b:.1f},{2.5 * a:.1f},{2.4 * b:.1f}"
    out = tmp_path / "box.yaml"
    png = tmp_path / "preview-of-box.png"
    run(["draw", ellipse_clip, "--frame", k, "--box", box, "--preview", png, "-o", out], 0)
    t = check_outputs(out, png, ellipse_clip, k)
    assert t.source.startswith(f"box {box} (GrabCut)")
    assert region_iou(t, k) >= 0.9


def test_draw_mask_route(tmp_path, ellipse_clip):
    cx, cy, a, b = CLIP_ELLIPSE
    mask = tmp_path / "mask.png"
    cv2.imwrite(str(mask), polygon_mask(ellipse_outline(cx, cy, a, b), CLIP_SIZE))
    out = tmp_path / "m.yaml"
    run(["draw", ellipse_clip, "--mask", mask, "-o", out], 0)
    t = check_outputs(out, out.with_suffix(".png"), ellipse_clip, 0)
    assert region_iou(t, 0) >= 0.95


def test_draw_points_open_curve(tmp_path, ellipse_clip):
    out = tmp_path / "p.yaml"
    pts = "20,100 40,60 70,30 100,60 120,100"
    run(["draw", ellipse_clip, "--points", pts, "--open", "--n-ctrl", "6", "--degree", "3", "-o", out], 0)
    t = check_outputs(out, out.with_suffix(".png"), ellipse_clip, 0)
    assert (t.closed, t.degree, t.n_ctrl, t.source) == (False, 3, 6, "points")


def test_draw_points_file_and_recording(tmp_path, ellipse_clip):
    pts = tmp_path / "pts.txt"
    pts.write_text("# a square\n40,30\n100,30\n100,90\n40,90\n", encoding="utf-8")
    out, rrd = tmp_path / "sq.yaml", tmp_path / "sq.rrd"
    result = run(["draw", ellipse_clip, "--points", pts, "--rrd", rrd, "-o", out], 0)
    assert result.stdout.strip().endswith(f"and {rrd}")
    check_outputs(out, out.with_suffix(".png"), ellipse_clip, 0)
    assert rrd.is_file() and rrd.stat().st_size > 0


# ---------------------------------------------------------------------------------------------
# track, learn, inspect, simulate, eval: user mistakes


def test_track_without_model_or_template_is_a_usage_error(tmp_path, ellipse_clip):
    line = usage_error(run(["track", ellipse_clip, "-o", tmp_path], 2))
    assert "give --model, --template, or both" in line


def test_track_without_clips_is_a_usage_error(template_file):
    run(["track", "--template", template_file], 2)


MALFORMED_MODELS = {
    "not-yaml": "kind: trackcli-model\nA1: [[1, 2]\n",
    "not-a-model": "just text\n",
    "template-not-model": "kind: trackcli-template\nformat: 1\n",
    "missing-parts": "kind: trackcli-model\nformat: 1\n",
    "future-format": "kind: trackcli-model\nformat: 99\n",
}


@pytest.mark.parametrize("name", sorted(MALFORMED_MODELS))
def test_track_with_a_malformed_model(tmp_path, ellipse_clip, name):
    model = tmp_path / "model.yaml"
    model.write_text(MALFORMED_MODELS[name], encoding="utf-8")
    line = one_line_error(run(["track", ellipse_clip, "--model", model, "-o", tmp_path / "out", "--no-rrd"], 4))
    assert str(model) in line


@pytest.mark.parametrize("name", sorted(MALFORMED_MODELS))
def test_inspect_and_simulate_a_malformed_model(tmp_path, name):
    model = tmp_path / "model.yaml"
    model.write_text(MALFORMED_MODELS[name], encoding="utf-8")
    assert str(model) in one_line_error(run(["inspect", model], 4))
    assert str(model) in one_line_error(run(["simulate", model, "--frames", "5", "--paths", "1"], 4))


def test_inspect_missing_model(tmp_path):
    assert "no such model file" in one_line_error(run(["inspect", tmp_path / "absent.yaml"], 4))


def test_track_with_missing_or_malformed_template(tmp_path, ellipse_clip):
    out = tmp_path / "out"
    assert "no such template file" in one_line_error(
        run(["track", ellipse_clip, "--template", tmp_path / "absent.yaml", "-o", out], 4))
    bad = tmp_path / "bad.yaml"
    bad.write_text("kind: trackcli-template\nformat: 1\ncontrol_points: [[1, 2], [3, 4]]\n", encoding="utf-8")
    assert "needs at least 3 control points" in one_line_error(run(["track", ellipse_clip, "--template", bad, "-o", out], 4))


def test_track_with_a_template_from_another_frame_size(tmp_path, ellipse_clip):
    t = tmp_path / "big.yaml"
    t.write_text(yaml.safe_dump({"format": 1, "kind": "trackcli-template", "frame_size": [640, 480],
                                 "control_points": [[10, 10], [50, 10], [50, 50], [10, 50]]}), encoding="utf-8")
    line = one_line_error(run(["track", ellipse_clip, "--template", t, "-o", tmp_path / "out", "--no-rrd"], 4))
    assert "640x480" in line and "160x120" in line


def test_track_missing_clip(tmp_path, template_file):
    clip = tmp_path / "absent.mp4"
    assert str(clip) in one_line_error(run(["track", clip, "--template", template_file, "-o", tmp_path / "o"], 4))


def test_track_with_a_bad_config(tmp_path, ellipse_clip, template_file):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("video: 3\n", encoding="utf-8")
    line = one_line_error(run(["track", ellipse_clip, "--template", template_file, "-c", cfg, "--fps", "10",
                               "-o", tmp_path / "o"], 3))
    assert line == f"Error: {cfg}: video: expected a mapping of settings, got 3"


def test_track_happy_path_with_hand_set_dynamics(tmp_path, ellipse_clip, template_file):
    out = tmp_path / "out"
    result = run(["track", ellipse_clip, "--template", template_file, "--tracker", "kalman", "--no-rrd", "-o", out], 0)
    assert "kalman" in result.stdout
    assert (out / "ellipse.kalman.csv").is_file()
    assert (out / "ellipse.kalman.config.yaml").is_file()


def test_learn_without_template_is_a_usage_error(tmp_path, ellipse_clip):
    run(["learn", ellipse_clip, "-o", tmp_path / "m.yaml"], 2)


def test_learn_without_clips_is_a_usage_error(tmp_path, template_file):
    assert "give at least one training CLIP" in usage_error(run(["learn", "--template", template_file,
                                                                  "-o", tmp_path / "m.yaml"], 2))


TRACK_HEADER = "frame,time,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h"
TRUTH_HEADER = "frame,time,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,tx,ty,angle,scale,visible"


TRUTH_ROW = "0,0,0,5,5,0,0,10,10,5,5,0,1,1\n"


@pytest.mark.parametrize(
    ("pred", "truth", "culprit", "text"),
    [
        (None, f"{TRUTH_HEADER}\n{TRUTH_ROW}", "pred.csv", "not found"),
        (f"{TRACK_HEADER}\n0,0,5,5,0,0,10,10\n", None, "truth.csv", "not found"),
        ("a,b\n1,2\n", f"{TRUTH_HEADER}\n{TRUTH_ROW}", "pred.csv", "lacks columns"),
        (f"{TRACK_HEADER}\n0,0,five,5,0,0,10,10\n", f"{TRUTH_HEADER}\n{TRUTH_ROW}", "pred.csv line 2", "'five'"),
        (f"{TRACK_HEADER}\n0,0,5,5,0,0,10,10\n", "1,2,3\n", "truth.csv line 1", "expected 4 numbers"),
        (f"{TRACK_HEADER}\n0,0,5,5,0,0,10,10\n", f"{TRUTH_HEADER}\n", "truth.csv", "no rows"),
        (b"\x89PNG\r\n\x1a\n\xff\xfe", f"{TRUTH_HEADER}\n{TRUTH_ROW}", "pred.csv", "not a text file"),
    ],
    ids=["no-pred", "no-truth", "pred-header", "pred-value", "truth-box", "truth-empty", "pred-binary"],
)
def test_eval_malformed_inputs(tmp_path, pred, truth, culprit, text):
    paths = []
    for name, content in (("pred.csv", pred), ("truth.csv", truth)):
        p = tmp_path / name
        if isinstance(content, bytes):
            p.write_bytes(content)
        elif content is not None:
            p.write_text(content, encoding="utf-8")
        paths.append(p)
    line = one_line_error(run(["eval", *paths], 4))
    assert line.startswith(f"Error: {tmp_path / culprit}")
    assert text in line


# ---------------------------------------------------------------------------------------------
# Outputs never take the place of inputs, and failed runs keep earlier outputs


@pytest.fixture
def tracked(tmp_path, ellipse_clip, template_file):
    out = tmp_path / "out"
    run(["track", ellipse_clip, "--template", template_file, "--tracker", "kalman", "--no-rrd", "-o", out], 0)
    return out / "ellipse.kalman.csv"


def test_render_refuses_to_write_over_its_inputs(tmp_path, ellipse_clip, tracked):
    before = {p: p.read_bytes() for p in (ellipse_clip, tracked)}
    for extra in (["-o", ellipse_clip], ["--sheet", "2", "-o", tracked]):
        line = one_line_error(run(["render", tracked, ellipse_clip, "--end", "2", *extra], 3))
        assert "would overwrite the input" in line
    assert "ending in .png" in usage_error(run(["render", tracked, ellipse_clip, "--sheet", "2", "-o",
                                                tmp_path / "sheet.mp4"], 2))
    for name in ("overlay.txt", "overlay", "overlay.png"):  # not a video's ending: said before any work
        line = usage_error(run(["render", tracked, ellipse_clip, "-o", tmp_path / name], 2))
        assert f"not {name!r}" in line and ".mp4" in line
        assert not (tmp_path / name).exists()
    assert {p: p.read_bytes() for p in before} == before


def test_render_writes_no_images_into_the_frames_folder_it_reads(tmp_path, ellipse_clip, template_file):
    frames = tmp_path / "frames"
    frames.mkdir()
    cap = cv2.VideoCapture(str(ellipse_clip))
    for i in range(3):
        ok, image = cap.read()
        assert ok and cv2.imwrite(str(frames / f"{i:04d}.png"), image)
    cap.release()
    run(["track", frames, "--template", template_file, "--tracker", "kalman", "--no-rrd", "--fps", "25",
         "-o", tmp_path / "out"], 0)
    track = tmp_path / "out" / "frames.kalman.csv"
    listing = sorted(p.name for p in frames.iterdir())
    run(["render", track, frames, "--png", "-o", frames], 3)
    assert "frames folder of CLIP" in one_line_error(run(["render", track, frames, "--sheet", "2", "-o",
                                                          frames / "sheet.png"], 3))
    assert sorted(p.name for p in frames.iterdir()) == listing
    run(["render", track, frames, "--sheet", "2", "-o", tmp_path / "sheet.png"], 0)


def test_eval_plot_refuses_to_write_over_its_inputs(tracked):
    truth = tracked.with_name("truth.txt")
    truth.write_text("".join("40,20,60,80\n" for _ in range(CLIP_FRAMES)))
    for target in (truth, tracked):
        before = target.read_bytes()
        line = one_line_error(run(["eval", tracked, truth, "--plot", target], 3))
        assert "would overwrite the input" in line and target.read_bytes() == before


def test_a_failed_draw_keeps_the_outputs_of_the_run_before(tmp_path, ellipse_clip, monkeypatch):
    from trackcli.errors import InputError
    from trackcli.run import drawing

    out = tmp_path / "t.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", out], 0)
    before = {p: p.read_bytes() for p in (out, out.with_suffix(".png"))}

    def fail(path, *args, **kwargs):
        raise InputError(f"{path}: cannot write recording (disk full)")

    monkeypatch.setattr(drawing, "record_template", fail)
    line = one_line_error(run(["draw", ellipse_clip, "--ellipse", "72,60,28,36", "-o", out,
                               "--rrd", tmp_path / "t.rrd"], 4))
    assert str(tmp_path / "t.rrd") in line and ".part" not in line
    assert {p: p.read_bytes() for p in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.png", "t.yaml"]


def test_render_to_a_folder_or_an_unwritable_place_names_the_cause(tmp_path, ellipse_clip, tracked):
    folder = tmp_path / "a folder"
    folder.mkdir()
    assert "is a folder" in one_line_error(run(["render", tracked, ellipse_clip, "--end", "2", "-o", folder], 4))
    blocker = tmp_path / "a file"
    blocker.write_text("")
    line = one_line_error(run(["render", tracked, ellipse_clip, "--end", "2", "-o", blocker / "v.mp4"], 4))
    assert "a file" in line and "OpenCV" not in line


def test_draw_finds_an_impossible_output_folder_before_segmenting(tmp_path, ellipse_clip, monkeypatch):
    from trackcli.segment import grabcut

    def never(*args, **kwargs):
        raise AssertionError("segmented although the output cannot be written")

    monkeypatch.setattr(grabcut, "segment_candidates", never)
    blocker = tmp_path / "a file"
    blocker.write_text("")
    line = one_line_error(run(["draw", ellipse_clip, "--box", "40,20,60,80", "-o", blocker / "t.yaml"], 4))
    assert "cannot create the output folder" in line


def test_render_warns_when_the_track_lies_outside_the_clips_frames(tmp_path, ellipse_clip, tracked, caplog):
    small = tmp_path / "small"
    small.mkdir()
    cap = cv2.VideoCapture(str(ellipse_clip))
    for i in range(CLIP_FRAMES):
        ok, image = cap.read()
        assert ok and cv2.imwrite(str(small / f"{i:04d}.png"), cv2.resize(image, (40, 30)))
    cap.release()
    with caplog.at_level(logging.WARNING, logger="trackcli"):  # whatever an earlier -q left set
        run(["render", tracked, small, "--fps", "25", "--sheet", "2", "-o", tmp_path / "s.png"], 0)
    assert "lie outside the 40x30 frames" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        run(["render", tracked, ellipse_clip, "--sheet", "2", "-o", tmp_path / "t.png"], 0)
    assert "outside" not in caplog.text


def test_render_to_avi_writes_motion_jpeg(tmp_path, ellipse_clip, tracked, capfd):
    result = run(["render", tracked, ellipse_clip, "--end", "3", "-o", tmp_path / "r.avi"], 0)
    assert "video (MJPG) of 3 frames" in result.stdout
    assert "FFMPEG" not in capfd.readouterr().err  # no fallback message from OpenCV's writer
    cap = cv2.VideoCapture(str(tmp_path / "r.avi"))
    assert cap.read()[0]
    cap.release()
