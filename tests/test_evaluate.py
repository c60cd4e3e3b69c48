"""Tests for trackcli.run.evaluate: hand-computed metrics, file parsing and error messages."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.errors import ConfigError, DataError, InputError
from trackcli.run.evaluate import (
    SUCCESS_THRESHOLDS,
    GroundTruth,
    Track,
    box_centres,
    box_iou,
    evaluate,
    format_table,
    load_track,
    load_truth,
    score_frames,
    success_rates,
)

TRACK_HEADER = "frame,time,x0,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,ess"
TRUTH_HEADER = "frame,time,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,tx,ty,angle,scale,visible"


def write_track(path, rows, *, lost=None):
    """rows: (frame, cx, cy, x, y, w, h); extra columns are filled with junk to be ignored."""
    header = TRACK_HEADER + (",lost" if lost is not None else "")
    lines = [header]
    for i, (f, cx, cy, x, y, w, h) in enumerate(rows):
        line = f"{f},{f / 25:.3f},{7 * i},{cx},{cy},{x},{y},{w},{h},{0.5}"
        if lost is not None:
            line += f",{lost[i]}"
        lines.append(line)
    path.write_text("\n".join(lines) + "\n")
    return path


def truth_from_boxes(boxes, first_frame=0):
    return GroundTruth.from_boxes(np.asarray(boxes, dtype=float), first_frame=first_frame)


def track_from_boxes(frames, boxes, lost=None):
    boxes = np.asarray(boxes, dtype=float).reshape(-1, 4)
    lost = np.zeros(len(frames), bool) if lost is None else np.asarray(lost, bool)
    return Track(np.asarray(frames), box_centres(boxes), boxes, lost)


# ---------------------------------------------------------------------------------------------
# Geometry and metrics with known answers


def test_iou_known_values():
    a = np.array([0.0, 0.0, 10.0, 10.0])
    assert box_iou(a, a) == 1.0
    assert box_iou(a, [5.0, 0.0, 10.0, 10.0]) == pytest.approx(1 / 3, abs=1e-15)  # half-overlapping
    assert box_iou(a, [0.0, 0.0, 10.0, 5.0]) == 0.5  # contained half
    assert box_iou(a, [10.0, 0.0, 10.0, 10.0]) == 0.0  # touching edges
    assert box_iou(a, [30.0, 30.0, 4.0, 4.0]) == 0.0
    assert box_iou(a, [2.0, 3.0, 0.0, 0.0]) == 0.0  # degenerate box
    assert box_iou(a, [np.nan, 0.0, 1.0, 1.0]) == 0.0
    # 2x2 offset square inside: inter 4 of union 100
    assert box_iou(a, [4.0, 4.0, 2.0, 2.0]) == pytest.approx(0.04)


def test_constant_345_offset_gives_error_5_everywhere():
    rng = np.random.default_rng(1)
    # integer boxes keep every centre and the 3-4-5 distance exact in floating point
    boxes = np.column_stack([rng.integers(0, 300, (30, 2)), rng.integers(20, 60, (30, 2))]).astype(float)
    truth = truth_from_boxes(boxes)
    shifted = boxes + [3.0, 4.0, 0.0, 0.0]
    res = evaluate(track_from_boxes(np.arange(30), shifted), truth, threshold=5.0)
    assert res.centre_error_mean == 5.0
    assert res.centre_error_median == 5.0
    assert res.centre_error_max == 5.0
    assert res.precision == 1.0  # error <= threshold, inclusive
    assert evaluate(track_from_boxes(np.arange(30), shifted), truth, threshold=4.99).precision == 0.0
    assert res.frames_scored == 30 and res.frames_missing == 0 and res.frames_lost == 0
    assert res.centre_kind == "box"


def test_centroid_truth_uses_prediction_centroid(tmp_path):
    """Against a trackcli truth file, centroids are compared, not box centres."""
    truth = tmp_path / "clip.truth.csv"
    truth.write_text(
        TRUTH_HEADER
        + "\n0,0.0,0,50,60,30,40,40,40,0,0,0,1,1\n1,0.04,0,52,61,32,41,40,40,0,0,0,1,1\n"
    )
    # centroids off by (3, 4), boxes exact: centre error must be 5 although the boxes agree
    pred = write_track(tmp_path / "p.csv", [(0, 53, 64, 30, 40, 40, 40), (1, 55, 65, 32, 41, 40, 40)])
    res = evaluate(pred, truth)
    assert res.centre_kind == "centroid"
    assert res.centre_error_mean == pytest.approx(5.0)
    assert res.mean_iou == 1.0


def test_precision_counts_frames_under_threshold():
    truth = truth_from_boxes(np.tile([100.0, 100.0, 20.0, 20.0], (5, 1)))
    offsets = np.array([0.0, 10.0, 19.0, 20.0, 21.0])
    pred = track_from_boxes(range(5), np.array([[100.0 + d, 100.0, 20.0, 20.0] for d in offsets]))
    assert evaluate(pred, truth, threshold=20).precision == pytest.approx(4 / 5)
    assert evaluate(pred, truth, threshold=10).precision == pytest.approx(2 / 5)
    assert evaluate(pred, truth, threshold=0).precision == pytest.approx(1 / 5)


def test_success_auc_of_known_iou_sequence():
    # IoUs 1, 1/2, 1/3, 0.  Counting thresholds t in {0, .05, ..., 1} with IoU > t:
    # 1 -> 20 (all but t = 1), 1/2 -> 10 (t <= .45), 1/3 -> 7 (t <= .30), 0 -> 0.
    truth = truth_from_boxes(np.tile([0.0, 0.0, 10.0, 10.0], (4, 1)))
    pred = track_from_boxes(
        range(4),
        [[0, 0, 10, 10], [0, 0, 10, 5], [5, 0, 10, 10], [40, 40, 10, 10]],
    )
    res = evaluate(pred, truth)
    assert res.success_auc == pytest.approx(37 / 84, abs=1e-15)
    assert res.mean_iou == pytest.approx((1 + 0.5 + 1 / 3 + 0) / 4)
    assert res.success_rates[0] == 0.75 and res.success_rates[-1] == 0.0
    assert len(res.success_rates) == 21
    assert res.frames_lost == 1  # IoU 0
    np.testing.assert_array_equal(
        success_rates([1.0, 0.5, 1 / 3, 0.0]),
        [(np.array([1.0, 0.5, 1 / 3, 0.0]) > t).mean() for t in SUCCESS_THRESHOLDS],
    )


def test_lost_rules():
    truth = truth_from_boxes(np.tile([0.0, 0.0, 40.0, 40.0], (4, 1)))
    boxes = [[0, 0, 40, 40], [10, 0, 40, 40], [0, 0, 40, 40], [100, 100, 40, 40]]
    pred = track_from_boxes(range(4), boxes, lost=[False, False, True, False])
    res = evaluate(pred, truth)
    assert res.frames_lost == 2  # flagged frame 2, IoU 0 at frame 3
    assert evaluate(pred, truth, lost_threshold=5.0).frames_lost == 3  # frame 1 is 10 px off
    assert evaluate(pred, truth, lost_threshold=10.0).frames_lost == 2
    scores = score_frames(pred, truth, lost_threshold=5.0)
    np.testing.assert_array_equal(scores.lost, [False, True, True, True])


def test_missing_frames_are_inf_error_zero_iou_and_lost():
    truth = truth_from_boxes(np.tile([0.0, 0.0, 10.0, 10.0], (6, 1)))
    # predictions for 0, 1, 2, 5: frames 3 and 4 lie inside the window and have no row
    pred = track_from_boxes([0, 1, 2, 5], np.tile([3.0, 4.0, 10.0, 10.0], (4, 1)))
    scores = score_frames(pred, truth)
    np.testing.assert_array_equal(scores.missing, [False, False, False, True, True, False])
    assert np.all(np.isinf(scores.centre_error[scores.missing]))
    assert np.all(scores.iou[scores.missing] == 0)
    res = evaluate(pred, truth, threshold=20)
    assert res.frames_scored == 6 and res.frames_missing == 2 and res.frames_lost == 2
    assert res.precision == pytest.approx(4 / 6)
    # error statistics cover the frames that have an estimate
    assert res.centre_error_mean == pytest.approx(5.0) and res.centre_error_max == pytest.approx(5.0)
    iou = (7 * 6) / (200 - 42)
    assert res.mean_iou == pytest.approx(4 * iou / 6)


def test_nan_estimate_counts_as_missing(tmp_path):
    truth = truth_from_boxes(np.tile([0.0, 0.0, 10.0, 10.0], (3, 1)))
    p = tmp_path / "p.csv"
    p.write_text("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,5,5,0,0,10,10\n1,,,,,,\n2,nan,nan,nan,nan,nan,nan\n")
    res = evaluate(p, truth)
    assert res.frames_missing == 2 and res.frames_lost == 2 and res.centre_error_max == 0.0


def test_window_follows_start_and_step():
    truth = truth_from_boxes(np.tile([0.0, 0.0, 10.0, 10.0], (20, 1)))
    frames = np.arange(4, 17, 3)  # --start 4 --step 3: 4, 7, 10, 13, 16
    pred = track_from_boxes(frames, np.tile([0.0, 0.0, 10.0, 10.0], (frames.size, 1)))
    res = evaluate(pred, truth)
    assert (res.first_frame, res.last_frame, res.frame_step) == (4, 16, 3)
    assert res.frames_scored == 5 and res.frames_missing == 0 and res.mean_iou == 1.0
    # one row dropped from the middle: the step is still 3 and frame 10 is missing
    pred2 = track_from_boxes(np.delete(frames, 2), np.tile([0.0, 0.0, 10.0, 10.0], (4, 1)))
    res2 = evaluate(pred2, truth)
    assert res2.frame_step == 3 and res2.frames_scored == 5 and res2.frames_missing == 1


def test_absent_truth_frames_are_not_scored():
    boxes = np.tile([0.0, 0.0, 10.0, 10.0], (5, 1))
    boxes[1] = np.nan
    boxes[3] = 0.0
    truth = truth_from_boxes(boxes)
    np.testing.assert_array_equal(truth.present, [True, False, True, False, True])
    pred = track_from_boxes(range(5), np.tile([50.0, 50.0, 10.0, 10.0], (5, 1)))  # wrong everywhere
    res = evaluate(pred, truth)
    assert res.frames_scored == 3 and res.frames_absent == 2 and res.frames_lost == 3


def test_no_overlap_is_data_error():
    truth = truth_from_boxes(np.tile([0.0, 0.0, 10.0, 10.0], (5, 1)))
    pred = track_from_boxes([10, 11], np.tile([0.0, 0.0, 10.0, 10.0], (2, 1)))
    with pytest.raises(DataError, match="no frame has both"):
        evaluate(pred, truth)
    absent = truth_from_boxes(np.zeros((5, 4)))
    with pytest.raises(DataError):
        evaluate(track_from_boxes(range(5), np.tile([0.0, 0.0, 10.0, 10.0], (5, 1))), absent)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "x"])
def test_bad_thresholds_are_config_errors(bad):
    truth = truth_from_boxes([[0.0, 0.0, 10.0, 10.0]])
    pred = track_from_boxes([0], [[0.0, 0.0, 10.0, 10.0]])
    with pytest.raises(ConfigError, match="threshold"):
        evaluate(pred, truth, threshold=bad)
    with pytest.raises(ConfigError, match="lost_threshold"):
        evaluate(pred, truth, lost_threshold=bad)


def test_to_dict_is_strict_json_and_table_mentions_metrics():
    truth = truth_from_boxes(np.tile([0.0, 0.0, 10.0, 10.0], (4, 1)))
    pred = track_from_boxes([0, 1, 3], np.tile([3.0, 4.0, 10.0, 10.0], (3, 1)))
    res = evaluate(pred, truth, lost_threshold=8)
    assert res.frames_scored == 4
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["frames_missing"] == 1 and d["lost_threshold"] == 8.0
    assert d["centre_error_mean"] == pytest.approx(5.0)
    assert len(d["success_rates"]) == len(d["success_thresholds"]) == 21
    assert all(type(v) in (int, float, str, list, type(None)) for v in d.values())
    table = format_table(res)
    for word in ("precision @ 20 px", "success AUC", "mean IoU", "frames missing", "5.00"):
        assert word in table


# ---------------------------------------------------------------------------------------------
# Properties


box_st = st.tuples(
    st.floats(-100, 100), st.floats(-100, 100), st.floats(0.5, 80), st.floats(0.5, 80)
).map(np.array)


@settings(max_examples=200, deadline=None)
@given(box_st, box_st, st.floats(-50, 50), st.floats(-50, 50))
def test_iou_properties(a, b, dx, dy):
    iou = float(box_iou(a, b))
    assert 0.0 <= iou <= 1.0
    assert iou == pytest.approx(float(box_iou(b, a)), abs=1e-12)
    assert float(box_iou(a, a)) == pytest.approx(1.0)
    shift = np.array([dx, dy, 0.0, 0.0])
    assert float(box_iou(a + shift, b + shift)) == pytest.approx(iou, abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=50))
def test_auc_approximates_mean_iou(ious):
    """AUC = (1/21) sum_t 1[u > t]; for one u that count is ceil(20 u) (u < 1), so
    |AUC - 20/21 * mean IoU| <= 1/21."""
    u = np.array(ious)
    rates = success_rates(u)
    assert np.all(np.diff(rates) <= 0)  # non-increasing in t
    assert abs(rates.mean() - 20 / 21 * u.mean()) <= 1 / 21 + 1e-12


# ---------------------------------------------------------------------------------------------
# Ground-truth files


@pytest.mark.parametrize(
    "sep", [",", "\t", " ", "  ", ", "], ids=["comma", "tab", "space", "spaces", "comma-space"]
)
def test_box_file_separators(tmp_path, sep):
    rows = [[10, 20, 30, 40], [11.5, 21, 30, 40], [12, 22, 31, 41]]
    p = tmp_path / "groundtruth_rect.txt"
    p.write_text("\n".join(sep.join(str(v) for v in r) for r in rows) + "\n\n")
    truth = load_truth(p)
    np.testing.assert_array_equal(truth.frame, [0, 1, 2])
    np.testing.assert_array_equal(truth.box, rows)
    np.testing.assert_array_equal(truth.centre[0], [25.0, 40.0])  # x + w/2, y + h/2
    assert truth.centre_kind == "box" and truth.present.all()


def test_box_file_nan_and_zero_lines(tmp_path):
    p = tmp_path / "gt.txt"
    p.write_text("10,20,30,40\nNaN,NaN,NaN,NaN\n0,0,0,0\nnan\tnan\tnan\tnan\r\n12,22,30,40\n")
    truth = load_truth(p)
    np.testing.assert_array_equal(truth.present, [True, False, False, False, True])
    np.testing.assert_array_equal(truth.frame, np.arange(5))


def test_box_file_vot_polygons_are_their_bounding_rectangles(tmp_path):
    # VOT writes rotated boxes as four corners; a file may mix them with x,y,w,h lines
    p = tmp_path / "groundtruth.txt"
    p.write_text("10,20,40,20,40,60,10,60\n"  # axis-aligned: the box 10,20,30,40
                 "25,10,45,30,25,50,5,30\n"  # a square turned 45 degrees about (25, 30)
                 "nan,nan,nan,nan,nan,nan,nan,nan\n"
                 "12,22,30,40\n")
    truth = load_truth(p)
    np.testing.assert_allclose(truth.box[[0, 1, 3]], [[10, 20, 30, 40], [5, 10, 40, 40], [12, 22, 30, 40]])
    np.testing.assert_allclose(truth.centre[1], [25.0, 30.0])
    np.testing.assert_array_equal(truth.present, [True, True, False, True])


@pytest.mark.parametrize("name", ["groundtruth_rect.txt", "groundtruth.txt"])
def test_folder_form(tmp_path, name):
    clip = tmp_path / "Clip"
    (clip / "img").mkdir(parents=True)
    (clip / name).write_text("1,2,3,4\n5,6,7,8\n")
    truth = load_truth(clip)
    np.testing.assert_array_equal(truth.box, [[1, 2, 3, 4], [5, 6, 7, 8]])
    assert truth.source.endswith(name)


def test_folder_prefers_groundtruth_rect(tmp_path):
    (tmp_path / "groundtruth.txt").write_text("9,9,9,9\n")
    (tmp_path / "groundtruth_rect.txt").write_text("1,2,3,4\n")
    np.testing.assert_array_equal(load_truth(tmp_path).box, [[1, 2, 3, 4]])


def test_truth_csv_objects_and_visibility(tmp_path):
    p = tmp_path / "clip.truth.csv"
    p.write_text(
        TRUTH_HEADER
        + "\n"
        + "\n".join(
            [
                "0,0.0,0,50,60,30,40,40,40,0,0,0,1,1",
                "0,0.0,1,150,160,130,140,40,40,0,0,0,1,1",
                "1,0.04,0,51,60,31,40,40,40,0,0,0,1,0",
                "1,0.04,1,151,160,131,140,40,40,0,0,0,1,1",
                "2,0.08,0,52,60,32,40,40,40,0,0,0,1,1",
            ]
        )
        + "\n"
    )
    t0 = load_truth(p)
    np.testing.assert_array_equal(t0.frame, [0, 1, 2])
    np.testing.assert_array_equal(t0.present, [True, False, True])
    np.testing.assert_array_equal(t0.centre[2], [52, 60])
    assert t0.centre_kind == "centroid"
    t1 = load_truth(p, object_id=1)
    np.testing.assert_array_equal(t1.frame, [0, 1])
    np.testing.assert_array_equal(t1.box[1], [131, 140, 40, 40])
    with pytest.raises(ConfigError, match=r"object 7.*objects in the file: 0, 1"):
        load_truth(p, object_id=7)


def test_track_file_reads_lost_and_ignores_other_columns(tmp_path):
    p = write_track(
        tmp_path / "est.csv",
        [(2, 5.0, 6.0, 1, 2, 8, 9), (0, 1.0, 2.0, 0, 0, 2, 4)],
        lost=[1, 0],
    )
    track = load_track(p)
    np.testing.assert_array_equal(track.frame, [0, 2])  # sorted by frame
    np.testing.assert_array_equal(track.centre, [[1, 2], [5, 6]])
    np.testing.assert_array_equal(track.box, [[0, 0, 2, 4], [1, 2, 8, 9]])
    np.testing.assert_array_equal(track.lost, [False, True])


def test_end_to_end_files(tmp_path):
    gt = tmp_path / "groundtruth_rect.txt"
    gt.write_text("\n".join(f"{10 + i}\t{20 + i}\t30\t40" for i in range(10)) + "\n")
    rows = [(f, 25 + f + 3, 40 + f + 4, 10 + f + 3, 20 + f + 4, 30, 40) for f in range(2, 10, 2)]
    res = evaluate(write_track(tmp_path / "p.csv", rows), tmp_path)
    assert res.frames_scored == 4 and res.first_frame == 2 and res.frame_step == 2
    assert res.centre_error_max == pytest.approx(5.0)
    assert res.mean_iou == pytest.approx((27 * 36) / (2 * 1200 - 27 * 36))


# ---------------------------------------------------------------------------------------------
# Malformed inputs: one-line messages that name the file and the line


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("1,2,3,4\n5,6,7,8\n1,2,3\n", r"truth\.txt line 3: expected 4 numbers \(x,y,w,h\) or 8 \(a polygon"),
        ("1,2,3,4,5\n", r"line 1: expected 4 numbers \(x,y,w,h\) or 8 .*, got 5"),
        ("1,2,3,4,5,6,7,x\n", r"line 1: y4 must be a number, got 'x'"),
        ("1,2,3,4\n1,two,3,4\n", r"line 2: y must be a number, got 'two'"),
        ("1,,3,4\n", r"line 1: empty field y"),
        ("1,2,3,4\n\n5,6,7,8\n", r"line 2: blank line"),
        ("1,2,-3,4\n", r"line 1: w and h must be >= 0"),
        ("1,2,inf,4\n", r"line 1: w must be finite or NaN"),
        ("", r"empty truth file"),
        ("\n\n", r"empty truth file"),
        ("format: 1\nkind: trackcli-template\n", r"truth\.txt: not a truth file \(its first line, 'format: 1', reads like YAML"),
        ("seed: 3\n", r"not a truth file .*reads like YAML"),
    ],
)
def test_malformed_box_files(tmp_path, text, pattern):
    p = tmp_path / "truth.txt"
    p.write_text(text)
    with pytest.raises(InputError, match=pattern) as info:
        load_truth(p)
    assert "\n" not in str(info.value)
    assert "truth.txt" in str(info.value)


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w\n0,1,2,3,4,5\n", r"lacks column bbox_h"),
        ("frame,time,cx\n0,0,1\n", r"lacks columns cy, bbox_x, bbox_y, bbox_w, bbox_h"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,1,2,3,4,5,6\n0.5,1,2,3,4,5,6\n", r"p\.csv line 3: frame must be an integer"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,1,2,3,4,5\n", r"line 2: expected 7 fields"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,1,abc,3,4,5,6\n", r"line 2: cy must be a number, got 'abc'"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,1,2,3,4,5,6\n\n0,1,2,3,4,5,6\n", r"line 4: frame 0 repeats \(.*line 2\)"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,lost\n0,1,2,3,4,5,6,maybe\n", r"line 2: lost must be 0 or 1"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,1,2,3,4,-5,6\n", r"line 2: bbox_w and bbox_h must be >= 0"),
        ("frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n", r"header but no rows"),
        ("", r"empty predictions file"),
        ("format: 1\nkind: trackcli-template\n", r"not a predictions CSV \(its first line, 'format: 1', reads like YAML"),
    ],
)
def test_malformed_predictions(tmp_path, text, pattern):
    p = tmp_path / "p.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=pattern) as info:
        load_track(p)
    assert "\n" not in str(info.value)
    assert "p.csv" in str(info.value)


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("frame,object,cx,cy,bbox_x,bbox_y,bbox_w\n0,0,1,2,3,4,5\n", r"truth file lacks column bbox_h"),
        ("frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,visible\n0,0,1,2,3,4,5,6,yes\n", r"line 2: visible must be a number"),
        ("frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,0,1,2,3,4,5,6\n0,0,1,2,3,4,5,6\n", r"line 3: frame 0 of object 0 repeats"),
        ("frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h\n0,x,1,2,3,4,5,6\n", r"line 2: frame must be an integer"),
    ],
)
def test_malformed_truth_csv(tmp_path, text, pattern):
    p = tmp_path / "clip.truth.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=pattern):
        load_truth(p)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(InputError, match=r"nope\.csv: predictions file not found"):
        load_track(tmp_path / "nope.csv")
    with pytest.raises(InputError, match=r"gt\.txt: truth file not found"):
        load_truth(tmp_path / "gt.txt")
    with pytest.raises(InputError, match=r"folder holds no ground truth \(looked for groundtruth_rect\.txt, groundtruth\.txt\)"):
        load_truth(tmp_path)
    with pytest.raises(InputError, match="got a folder"):
        load_track(tmp_path)
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"\xff\xfe\x00\x81garbage")
    with pytest.raises(InputError, match="not a text file"):
        load_track(binary)
    # InputError is also an OSError, so plain callers can catch it as such
    with pytest.raises(OSError):
        load_truth(tmp_path / "gt.txt")


def test_bad_object_id_is_config_error(tmp_path):
    p = tmp_path / "gt.txt"
    p.write_text("1,2,3,4\n")
    for bad in (-1, 1.5, "0", True):
        with pytest.raises(ConfigError, match="object_id"):
            load_truth(p, object_id=bad)


def test_pinned_scores_on_a_shifted_track():
    """A fixed, seeded jitter around a drifting box: pinned numbers guard against regressions."""
    rng = np.random.default_rng(20260)
    n = 40
    t = np.arange(n)
    boxes = np.column_stack([100 + 2.0 * t, 80 + 0.5 * t, np.full(n, 30.0), np.full(n, 60.0)])
    truth = truth_from_boxes(boxes)
    noisy = boxes + np.column_stack([rng.normal(0, 4, (n, 2)), rng.normal(0, 2, (n, 2))])
    res = evaluate(track_from_boxes(t, noisy), truth, threshold=5.0, lost_threshold=8.0)
    errs = np.hypot(*(box_centres(noisy) - box_centres(boxes)).T)
    assert res.centre_error_mean == pytest.approx(errs.mean())
    assert res.precision == pytest.approx(np.mean(errs <= 5.0))
    assert res.frames_lost == int(np.sum(errs > 8.0))
    assert math.isclose(res.mean_iou, float(box_iou(noisy, boxes).mean()))
    # pinned (numpy Generator PCG64, seed 20260)
    assert res.centre_error_mean == pytest.approx(5.037271364027988, rel=1e-12)
    assert res.centre_error_median == pytest.approx(4.335372643951779, rel=1e-12)
    assert res.centre_error_max == pytest.approx(15.338200726675657, rel=1e-12)
    assert (res.precision, res.frames_lost) == (0.575, 5)
    assert res.success_auc == pytest.approx(0.7261904761904763, rel=1e-12)
    assert res.mean_iou == pytest.approx(0.7381554515668547, rel=1e-12)


def test_visible_column_is_a_fraction(tmp_path):
    # trackcli truth files give the visible fraction of the object: partly hidden frames are
    # scored, fully hidden ones (0) are absent, and the committed sample truth loads.
    p = tmp_path / "t.truth.csv"
    p.write_text("frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,visible\n"
                 "0,0,10,10,5,5,10,10,1.0000\n1,0,10,10,5,5,10,10,0.3500\n2,0,10,10,5,5,10,10,0.0000\n")
    gt = load_truth(p)
    assert gt.present.tolist() == [True, True, False]
    with pytest.raises(InputError, match="fraction from 0 to 1"):
        bad = tmp_path / "bad.truth.csv"
        bad.write_text("frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,visible\n0,0,1,2,3,4,5,6,1.5\n")
        load_truth(bad)
    from pathlib import Path

    sample = Path(__file__).resolve().parents[1] / "sample_data" / "test.truth.csv"
    assert load_truth(sample).present.all()


def test_the_truth_formats_place_outlines_only_with_the_function_given(tmp_path):
    # io.truth reads the formats and knows nothing of the sample clips; the outlines beside a
    # sample clip's truth CSV are placed by the function eval's reader passes it
    from pathlib import Path

    from trackcli.io import truth as formats
    from trackcli.sample_data import load_outline, load_truth as load_sample_truth, true_outline

    sample = Path(__file__).resolve().parents[1] / "sample_data" / "test.truth.csv"
    assert formats.load_truth(sample).outline is None
    gt = load_truth(sample)
    rows = load_sample_truth(sample).select(0)
    base = load_outline(sample.with_name("test.outline.json"))
    assert gt.outline.shape == (len(gt.frame), len(base.points), 2)
    np.testing.assert_allclose(gt.outline[7], true_outline(rows.row(7), base), atol=1e-9)
    seen = []

    def place(path, rs):
        seen.append((path, len(rs)))
        return gt.outline

    assert formats.load_truth(sample, outlines=place).outline is not None
    assert seen == [(sample.with_name("test.outline.json"), len(gt.frame))]

    def refuse(path, rs):
        raise ValueError("no pose")

    with pytest.raises(InputError, match="cannot place the outline of test.outline.json"):
        formats.load_truth(sample, outlines=refuse)
