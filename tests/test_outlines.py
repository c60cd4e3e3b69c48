"""Outlines in the track CSV, outline IoU in eval, coverage warnings and the precision/success plot."""

from __future__ import annotations

import csv
import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import CLIP_FRAMES, SAMPLE_DATA, sample_clip
from trackcli.cli import cli
from trackcli.errors import InputError
from trackcli.run.evaluate import GroundTruth, Track, coverage_notes, load_track, load_truth, polygon_iou, score_frames
from trackcli.sample_data import load_outline, load_truth as load_sample_truth, polygon_centroid, true_outline
from trackcli.io.tracks import BoxCarry, DrawnBox, clip_box, outline_header, read_outlines
from trackcli.shapes.template import load_template


def run(args, code: int):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert "Traceback" not in result.output
    return result


@pytest.fixture
def tracked(tmp_path, ellipse_clip):
    tmpl = tmp_path / "ellipse.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    out = tmp_path / "out"
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-c", estimate_only(tmp_path),
         "-o", out], 0)
    return out / "ellipse.kalman.csv"


def estimate_only(folder, extra: str = ""):
    """A configuration whose outline columns are the estimate's own curve (no refinement)."""
    cfg = folder / "estimate-only.yaml"
    cfg.write_text("outline: {refine: false}\n" + extra)
    return cfg


# ---------------------------------------------------------------------------------------------
# The CSV columns


def test_outline_columns_follow_the_other_columns_and_agree_with_them(tracked):
    """Without refinement the outline columns are the estimate's curve, whose centroid and box
    the other columns report."""
    with open(tracked, newline="") as fh:
        rows = list(csv.DictReader(fh))
        fh.seek(0)
        head = next(csv.reader(fh))
    assert head[-len(outline_header(64)):] == outline_header(64)
    assert head.index("lost") < head.index("outline_closed")
    frames, outlines, closed = read_outlines(tracked)
    assert outlines.shape == (CLIP_FRAMES, 64, 2)
    assert closed.all()
    assert frames.tolist() == [int(r["frame"]) for r in rows]
    for r, poly in zip(rows, outlines):
        # the outline is the contour whose centroid and box the other columns report
        np.testing.assert_allclose(polygon_centroid(poly), [float(r["cx"]), float(r["cy"])], atol=0.3)
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        assert lo[0] >= float(r["bbox_x"]) - 0.01 and lo[1] >= float(r["bbox_y"]) - 0.01
        assert hi[0] <= float(r["bbox_x"]) + float(r["bbox_w"]) + 0.01
        assert hi[1] <= float(r["bbox_y"]) + float(r["bbox_h"]) + 0.01
        # 64 points of a dense contour span nearly all of its box
        assert hi[0] - lo[0] > float(r["bbox_w"]) - 1.0


def test_outline_points_setting(tmp_path, ellipse_clip):
    tmpl = tmp_path / "e.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    cfg = tmp_path / "c.yaml"
    cfg.write_text("output: {outline_points: 0}\n")
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-c", cfg, "-o", tmp_path], 0)
    head = (tmp_path / "ellipse.kalman.csv").read_text().splitlines()[0].split(",")
    assert not [c for c in head if c.startswith("outline")]
    with pytest.raises(InputError, match="no outline columns"):
        read_outlines(tmp_path / "ellipse.kalman.csv")
    cfg.write_text("output: {outline_points: 12}\n")
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-c", cfg, "-o", tmp_path], 0)
    assert read_outlines(tmp_path / "ellipse.kalman.csv")[1].shape == (CLIP_FRAMES, 12, 2)
    cfg.write_text("output: {outline_points: 1}\n")
    result = run(["track", ellipse_clip, "--template", tmpl, "--no-rrd", "-c", cfg, "-o", tmp_path], 3)
    assert "output.outline_points" in result.stderr


# ---------------------------------------------------------------------------------------------
# Polygon IoU


def _circle(r, n=400):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return r * np.column_stack([np.cos(t), np.sin(t)])


@pytest.mark.parametrize("r, d", [(10.0, 3.0), (50.0, 15.0), (40.0, 0.0), (30.0, 70.0)])
def test_polygon_iou_of_two_discs_matches_the_lens_formula(r, d):
    if d >= 2 * r:
        exact = 0.0
    else:
        inter = 2 * r * r * np.arccos(d / (2 * r)) - 0.5 * d * np.sqrt(4 * r * r - d * d)
        exact = inter / (2 * np.pi * r * r - inter)
    got = polygon_iou(_circle(r) + 100, _circle(r) + [100 + d, 100])
    assert got == pytest.approx(exact, abs=0.01)


def test_polygon_iou_known_squares_and_degenerate_inputs():
    sq = np.array([[0, 0], [40, 0], [40, 40], [0, 40]], float)
    assert polygon_iou(sq, sq) == 1.0
    assert polygon_iou(sq, sq + [20, 0]) == pytest.approx(1 / 3, abs=0.01)
    assert polygon_iou(sq, sq[::-1]) == 1.0  # orientation does not matter
    assert polygon_iou(sq, np.full((4, 2), np.nan)) == 0.0
    assert polygon_iou(sq, sq[:2]) == 0.0


# ---------------------------------------------------------------------------------------------
# eval with outlines


def _truth_track_csv(path, shift=(0.0, 0.0), n_points=64, frames=None):
    """A track CSV whose rows are the sample truth of test.mp4 (outline resampled), shifted."""
    truth = load_sample_truth(SAMPLE_DATA / "test.truth.csv")
    base = load_outline(SAMPLE_DATA / "test.outline.json")
    step = base.points.shape[0] // n_points
    names = ["frame", "cx", "cy", "bbox_x", "bbox_y", "bbox_w", "bbox_h", "lost", *outline_header(n_points)]
    dx, dy = shift
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        for k in range(len(truth)) if frames is None else frames:
            row = truth.row(k)
            poly = true_outline(row, base)[::step] + [dx, dy]
            w.writerow([row["frame"], row["cx"] + dx, row["cy"] + dy, row["bbox_x"] + dx, row["bbox_y"] + dy,
                        row["bbox_w"], row["bbox_h"], 0, 1, *poly.reshape(-1).round(3)])
    return path


def test_eval_reads_outlines_on_both_sides_and_scores_them(tmp_path):
    sample_clip("test")
    truth = load_truth(SAMPLE_DATA / "test.truth.csv")
    assert truth.outline is not None and truth.outline.shape[1:] == (256, 2)
    exact = load_track(_truth_track_csv(tmp_path / "exact.csv"))
    assert exact.outline.shape == (160, 64, 2)
    s = score_frames(exact, truth)
    # a 64-point copy of the 256-point outline: cut corners cost well under 1 %
    assert s.outline_iou.min() > 0.99
    shifted = score_frames(load_track(_truth_track_csv(tmp_path / "shift.csv", shift=(6.0, 0.0))), truth)
    assert 0.80 < shifted.outline_iou.mean() < 0.97
    # the outline sees a shift the box IoU sees too, but sees it differently: not the same numbers
    assert not np.allclose(shifted.outline_iou, shifted.iou, atol=0.01)


def test_eval_without_outlines_reports_none(tmp_path):
    sample_clip("test")
    csv_path = tmp_path / "box.csv"
    lines = ["frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h", "0,227.5,194,177,116.7,109.6,127.3"]
    csv_path.write_text("\n".join(lines) + "\n")
    result = run(["eval", csv_path, SAMPLE_DATA / "test.truth.csv", "--json"], 0)
    assert json.loads(result.stdout)["outline_iou"] is None
    # a truth copied away from its outline file has no outlines
    lone = tmp_path / "test.truth.csv"
    lone.write_text((SAMPLE_DATA / "test.truth.csv").read_text())
    assert load_truth(lone).outline is None


def test_eval_cli_prints_outline_iou(tmp_path):
    sample_clip("test")
    result = run(["eval", _truth_track_csv(tmp_path / "t.csv"), SAMPLE_DATA / "test.truth.csv"], 0)
    line = [ln for ln in result.stdout.splitlines() if ln.startswith("outline IoU")]
    assert len(line) == 1 and float(line[0].split()[-1]) > 0.99
    assert result.stderr == ""  # same frames on both sides: no warning


# ---------------------------------------------------------------------------------------------
# Prediction and truth of different length


def _boxes(n, first=0):
    b = np.tile([10.0, 10.0, 20.0, 20.0], (n, 1))
    return np.arange(first, first + n), b


def test_coverage_notes_name_what_was_scored():
    f, b = _boxes(100)
    truth = GroundTruth(f, b[:, :2] + 10, b, np.ones(100, bool), source="truth.txt")
    tf, tb = _boxes(30)
    short = Track(tf, tb[:, :2] + 10, tb, np.zeros(30, bool), source="short.csv")
    notes = coverage_notes(short, truth, score_frames(short, truth))
    assert "70 truth frames outside the track's frames 0-29 are not scored" in notes[0]
    assert notes[-1] == "scored 30 frames: frames 0-29"
    lf, lb = _boxes(120)
    long = Track(lf, lb[:, :2] + 10, lb, np.zeros(120, bool), source="long.csv")
    notes = coverage_notes(long, truth, score_frames(long, truth))
    assert "20 predicted frames (100-119) have no ground truth" in notes[0]
    assert notes[-1] == "scored 100 frames: frames 0-99"
    same = Track(f, b[:, :2] + 10, b, np.zeros(100, bool))
    assert coverage_notes(same, truth) == []


def test_eval_cli_warns_on_different_lengths(tmp_path):
    sample_clip("test")
    short = _truth_track_csv(tmp_path / "short.csv", frames=range(40))
    result = run(["eval", short, SAMPLE_DATA / "test.truth.csv"], 0)
    warning = result.stderr.strip()
    assert warning.startswith("Warning: ") and len(result.stderr.splitlines()) == 1
    assert "120 truth frames outside the track's frames 0-39 are not scored" in warning
    assert "scored 40 frames: frames 0-39" in warning
    data = json.loads(run(["eval", short, SAMPLE_DATA / "test.truth.csv", "--json"], 0).stdout)
    assert data["kind"] == "eval" and data["frames_scored"] == 40
    assert any("not scored" in w for w in data["warnings"])
    assert run(["-q", "eval", short, SAMPLE_DATA / "test.truth.csv"], 0).stderr == ""


# ---------------------------------------------------------------------------------------------
# Several tracks and the plot


def test_eval_several_tracks_and_plot(tmp_path):
    sample_clip("test")
    good = _truth_track_csv(tmp_path / "test.good.csv")
    bad = _truth_track_csv(tmp_path / "test.bad.csv", shift=(30.0, 0.0))
    png = tmp_path / "plots" / "pr.png"
    result = run(["eval", good, bad, SAMPLE_DATA / "test.truth.csv", "--plot", png], 0)
    assert "== good" in result.stdout and "== bad" in result.stdout
    img = cv2.imread(str(png))
    assert img is not None and img.shape[1] == 1000
    assert not list(png.parent.glob(".*part*"))
    lines = run(["eval", good, bad, SAMPLE_DATA / "test.truth.csv", "--json"], 0).stdout.splitlines()
    scores = [json.loads(ln) for ln in lines]
    assert [s["track"] for s in scores] == [str(good), str(bad)]
    assert scores[0]["precision"] == 1.0 and scores[1]["precision"] == 0.0


def test_plot_curves_are_drawn_where_the_scores_say():
    from trackcli.run.plots import curves, draw_plots

    f, b = _boxes(50)
    truth = GroundTruth(f, b[:, :2] + 10, b, np.ones(50, bool))
    perfect = curves("perfect", score_frames(Track(f, b[:, :2] + 10, b, np.zeros(50, bool)), truth))
    assert perfect.precision.min() == 1.0 and perfect.auc == pytest.approx(20 / 21)
    img = draw_plots([perfect])
    # the precision curve of a perfect track runs along the top of the left panel: blue pixels there
    blue = (img[..., 0] > 150) & (img[..., 2] < 80)
    rows = np.flatnonzero(blue[:, 100:480].any(axis=1))
    assert rows.size and rows.min() < 60


def test_track_json_has_kind_and_rounded_floats(tmp_path, ellipse_clip, caplog):
    import logging

    caplog.set_level(logging.INFO, logger="trackcli")
    tmpl = tmp_path / "e.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    result = run(["-v", "track", ellipse_clip, "--template", tmpl, "--particles", "40", "--seed", "3", "--no-rrd",
                  "--json", "-o", tmp_path], 0)
    data = json.loads(result.stdout)
    assert data["kind"] == "clip" and data["status"] == "ok" and data["frames"] == CLIP_FRAMES
    floats = [v for v in data.values() if isinstance(v, float)]
    assert floats and all(len(repr(v).lstrip("-").replace(".", "").lstrip("0").split("e")[0]) <= 6 for v in floats)
    # -v says where the settings, the start and the sampling came from
    for text in ("settings: the defaults, options condensation.particles=40, seed=3", "initial shape X0",
                 "seed 3; samples", "frames decoded"):
        assert text in caplog.text, text


def test_csv_cells_of_whole_arrays_match_the_one_value_rule():
    """The array formatter writes every cell exactly as the per-value rule does: trailing zeros
    dropped, NaN empty, infinities spelled out, values below 1e-3 in significant digits."""
    from trackcli.io.tracks import _fmt, _fmt_all

    rng = np.random.default_rng(7)
    special = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 1e-3, -1e-3, 9.99e-4, -9.99e-4, 1e-9, 5e-4,
                        1.0005, 2.5, -2.5, 0.9995, -0.9995, 1e300, 123456789.125, 100.0, -100.0])
    for digits in (3, 4, 6, 8):
        for _ in range(200):
            v = np.concatenate([rng.choice(special, 5), rng.normal(0, 10 ** rng.uniform(-5, 4), 20),
                                np.round(rng.normal(0, 100, 5), rng.integers(0, 4))])
            assert _fmt_all(v, digits) == [_fmt(float(x), digits) for x in v]
    assert _fmt_all(np.zeros(0), 3) == []
    assert _fmt_all(np.array([[1.5, 2.0], [np.nan, 1e-4]]), 3) == ["1.5", "2", "", "0.0001"]


# ---------------------------------------------------------------------------------------------
# The drawn box, carried by the estimate


@settings(max_examples=60, deadline=None)
@given(drawn=st.tuples(st.floats(-50, 300), st.floats(-50, 300), st.floats(1, 200), st.floats(1, 200)),
       start=st.tuples(st.floats(-50, 300), st.floats(-50, 300), st.floats(1, 200), st.floats(1, 200)),
       shift=st.tuples(st.floats(-100, 100), st.floats(-100, 100)), scale=st.floats(0.2, 5))
def test_the_carried_box_is_the_drawn_one_at_the_start_and_moves_and_scales_with_the_contour(drawn, start, shift,
                                                                                            scale):
    carry = BoxCarry.between(drawn, start)
    np.testing.assert_allclose(carry(start), drawn, rtol=1e-9, atol=1e-9)
    # the contour's box moved by `shift` and scaled by `scale` about its corner: the carried box
    # moves and scales alike about the same point
    x, y, w, h = start
    moved = (x + shift[0], y + shift[1], w * scale, h * scale)
    bx, by, bw, bh = drawn
    expect = (x + shift[0] + (bx - x) * scale, y + shift[1] + (by - y) * scale, bw * scale, bh * scale)
    np.testing.assert_allclose(carry(moved), expect, rtol=1e-9, atol=1e-6)


def test_the_carry_is_anchored_on_the_start_curve_or_for_a_placed_model_on_its_first_estimate():
    from types import SimpleNamespace

    start = (12.0, 22.0, 30.0, 50.0)
    own = DrawnBox(box=(10.0, 20.0, 40.0, 60.0), frame=3, start=start)
    placed = DrawnBox(box=(10.0, 20.0, 40.0, 60.0), frame=3, start=start, first=True)
    on_frame = SimpleNamespace(index=3, bbox=(15.0, 25.0, 20.0, 40.0))
    later = SimpleNamespace(index=7, bbox=(15.0, 25.0, 20.0, 40.0))  # a track started with --start
    np.testing.assert_allclose(own.carry(on_frame)(start), own.box)
    np.testing.assert_allclose(own.carry(later)(start), own.box)
    np.testing.assert_allclose(placed.carry(on_frame)(on_frame.bbox), placed.box)
    np.testing.assert_allclose(placed.carry(later)(start), placed.box)


def test_a_start_box_without_width_carries_nothing():
    assert BoxCarry.between((0, 0, 10, 10), (5, 5, 0, 10)) is None
    assert BoxCarry.between((0, 0, 10, 10), (5, 5, 10, float("nan"))) is None


def _first_box(csv_path):
    with open(csv_path, newline="") as fh:
        r = next(csv.DictReader(fh))
    return np.array([float(r[k]) for k in ("bbox_x", "bbox_y", "bbox_w", "bbox_h")])


def test_a_track_from_a_box_reports_the_drawn_box_and_output_box_outline_the_contours(tmp_path, ellipse_clip):
    """A box drawn well outside the ellipse: the track's box columns report that box (moved with
    the contour), not the segmented outline's own tight box; ``output.box: outline`` gives the latter, and
    a template drawn otherwise has no box to carry."""
    box = (30.0, 10.0, 90.0, 100.0)  # the ellipse (70,60,28,36) with a wide margin
    tmpl = tmp_path / "box.yaml"
    run(["draw", ellipse_clip, "--box", ",".join(f"{v:g}" for v in box), "-o", tmpl], 0)
    assert load_template(tmpl).box == box
    for tracker in ("kalman", "condensation"):
        run(["track", ellipse_clip, "--template", tmpl, "--tracker", tracker, "--no-rrd", "-c", estimate_only(tmp_path),
             "-o", tmp_path / "a"], 0)
        first = _first_box(tmp_path / "a" / f"ellipse.{tracker}.csv")
        np.testing.assert_allclose(first, box, atol=5.0)  # the first estimate is near the template, not on it
    cfg = estimate_only(tmp_path, "output:\n  box: outline\n")
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-c", cfg, "-o", tmp_path / "b"], 0)
    own = _first_box(tmp_path / "b" / "ellipse.kalman.csv")
    assert np.abs(own - np.array(box))[2:].min() > 10  # the segmented outline is well inside the box

    def outline_box(csv_path):
        _, outlines, _ = read_outlines(csv_path)
        lo, hi = outlines[0].min(axis=0), outlines[0].max(axis=0)
        return np.array([*lo, *(hi - lo)])

    np.testing.assert_allclose(own, outline_box(tmp_path / "b" / "ellipse.kalman.csv"), atol=0.6)
    ell = tmp_path / "ell.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", ell], 0)
    assert load_template(ell).box is None
    run(["track", ellipse_clip, "--template", ell, "--tracker", "kalman", "--no-rrd", "-c", estimate_only(tmp_path),
         "-o", tmp_path / "c"], 0)
    np.testing.assert_allclose(_first_box(tmp_path / "c" / "ellipse.kalman.csv"),
                               outline_box(tmp_path / "c" / "ellipse.kalman.csv"), atol=0.6)


# ---------------------------------------------------------------------------------------------
# The box clipped to the frame


@settings(max_examples=100, deadline=None)
@given(box=st.tuples(st.floats(-300, 500), st.floats(-300, 500), st.floats(0.5, 400), st.floats(0.5, 400)))
def test_the_box_is_its_part_inside_the_frame_or_itself_when_none_of_it_is(box):
    size = (160, 120)
    x, y, w, h = box
    out = clip_box(box, size)
    ix0, iy0, ix1, iy1 = max(x, 0), max(y, 0), min(x + w, size[0]), min(y + h, size[1])
    if ix1 > ix0 and iy1 > iy0:
        np.testing.assert_allclose(out, (ix0, iy0, ix1 - ix0, iy1 - iy0), atol=1e-9)
        assert out[0] >= 0 and out[1] >= 0 and out[0] + out[2] <= size[0] + 1e-9 and out[1] + out[3] <= size[1] + 1e-9
    else:  # nothing of it in view: the box as it was
        assert out == tuple(float(v) for v in box)


def test_a_box_inside_the_frame_or_not_finite_is_left_as_it_is():
    assert clip_box((10, 20, 30, 40), (160, 120)) == (10.0, 20.0, 30.0, 40.0)
    nan = float("nan")
    out = clip_box((nan, 20, 30, 40), (160, 120))
    assert np.isnan(out[0]) and out[1:] == (20.0, 30.0, 40.0)


def test_an_outline_reaching_beyond_the_frame_has_its_box_clipped_and_its_outline_kept(tmp_path, ellipse_clip):
    """An ellipse drawn over the frame's left edge: the box columns give the part in view, the
    outline columns the whole curve."""
    tmpl = tmp_path / "edge.yaml"
    run(["draw", ellipse_clip, "--ellipse", "12,60,28,36", "-o", tmpl], 0)
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-c", estimate_only(tmp_path),
         "-o", tmp_path], 0)
    csv_path = tmp_path / "ellipse.kalman.csv"
    _, outlines, _ = read_outlines(csv_path)
    with open(csv_path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(outlines) == CLIP_FRAMES
    beyond = 0
    for r, pts in zip(rows, outlines):
        x, y, w, h = (float(r[k]) for k in ("bbox_x", "bbox_y", "bbox_w", "bbox_h"))
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        assert x >= 0 and y >= 0 and x + w <= 160 + 1e-3 and y + h <= 120 + 1e-3
        if lo[0] < -1:  # the curve reaches beyond the left edge: the box starts at it
            beyond += 1
            assert x == 0.0
            assert x + w == pytest.approx(hi[0], abs=0.01)
    assert beyond == CLIP_FRAMES


def test_the_refined_outline_fits_the_object_at_least_as_well_as_the_estimate(tmp_path, ellipse_clip):
    """With ``outline.refine`` (the default) the outline columns are refit in the full image: on
    the drifting ellipse they cover the true region at least as well as the estimate's curve."""
    from conftest import CLIP_DRIFT, CLIP_ELLIPSE, CLIP_SIZE
    from trackcli.run.masks import outline_mask, region_similarity

    tmpl = tmp_path / "e.yaml"
    run(["draw", ellipse_clip, "--ellipse", "66,62,24,30", "-o", tmpl], 0)  # a little off and small
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-o", tmp_path / "r"], 0)
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-c", estimate_only(tmp_path),
         "-o", tmp_path / "e"], 0)
    _, refined, _ = read_outlines(tmp_path / "r" / "ellipse.kalman.csv")
    _, estimate, _ = read_outlines(tmp_path / "e" / "ellipse.kalman.csv")
    w, h = CLIP_SIZE
    cx, cy, a, b = CLIP_ELLIPSE
    j_ref, j_est = [], []
    for k in range(CLIP_FRAMES):
        truth = np.zeros((h, w), np.uint8)
        cv2.ellipse(truth, ((cx + CLIP_DRIFT * k, cy), (2 * a, 2 * b), 0.0), 1, -1)
        j_ref.append(region_similarity(outline_mask(refined[k], (h, w)), truth > 0))
        j_est.append(region_similarity(outline_mask(estimate[k], (h, w)), truth > 0))
    assert min(j_ref) > 0.9, j_ref
    assert np.mean(j_ref) >= np.mean(j_est) - 0.01, (j_ref, j_est)
