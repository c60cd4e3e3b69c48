"""First-frame templates that cover the mask: a mask's pieces joined into one object
(segment.masks), the closed fit with local parameters (shapes.draw.fit_closed) and the count
of control points that grows until the curve covers the outline (run.drawing.fit_covering)."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from test_spline import _curve_to_polygon, _runs_against
from trackcli.cli import cli
from trackcli.run import drawing
from trackcli.segment import masks
from trackcli.shapes import draw
from trackcli.shapes.spline import SplineBasis, dense_polygon
from trackcli.shapes.template import load_template


def _filled(Q: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    n = len(Q) // 2
    return draw.polygon_mask(dense_polygon(Q, SplineBasis(n), 40 * n), (shape[1], shape[0]))


def _fenced_disc() -> tuple[np.ndarray, np.ndarray]:
    """A disc, and the same disc cut into three pieces by two bars 7 px wide (a fence)."""
    whole = np.zeros((240, 320), np.uint8)
    cv2.circle(whole, (160, 120), 80, 255, -1)
    cut = whole.copy()
    cut[:, 127:134] = 0
    cut[:, 187:194] = 0
    return whole, cut


# ---------------------------------------------------------------------------------------------
# a mask in pieces: one object


def test_pieces_cut_apart_by_a_fence_are_joined_into_one_region():
    whole, cut = _fenced_disc()
    assert cv2.connectedComponents(cut)[0] - 1 == 3
    joined = masks.join_pieces(cut)
    assert len(joined.joined) == 2 and not joined.left_out
    assert cv2.connectedComponents(joined.region.astype(np.uint8))[0] - 1 == 1
    # the fill is the gaps the fence left, not the disc's outside: the region is the disc
    assert masks.mask_iou(joined.region, whole) > 0.99
    assert 3 <= joined.radius <= 8
    assert "3 pieces; 2 joined to the largest by filling the gaps between them" in joined.describe()


def test_only_the_gaps_between_pieces_are_filled_not_the_outlines_other_concavities():
    # two blocks side by side 6 px apart, one with a notch 6 px wide: the gap is filled, the notch stays
    m = np.zeros((100, 200), np.uint8)
    m[20:80, 20:95] = 255
    m[20:80, 101:180] = 255
    m[20:50, 140:146] = 0  # the notch, open to the top
    joined = masks.join_pieces(m)
    assert len(joined.joined) == 1
    assert joined.region[30:70, 95:101].all()  # the gap
    assert not joined.region[20:45, 141:145].any()  # the notch


def test_a_piece_whose_gap_costs_more_than_it_brings_is_left_out(caplog):
    m = np.zeros((200, 300), np.uint8)
    cv2.circle(m, (80, 100), 50, 255, -1)
    cv2.circle(m, (250, 100), 12, 255, -1)  # 120 px away: filling the gap takes more than its area
    m[10:12, 10:12] = 255  # a speck of annotation
    joined = masks.join_pieces(m)
    assert not joined.joined and sorted(joined.left_out) == [4, int(np.count_nonzero(m[:, 200:]))]
    assert masks.mask_iou(joined.region, m) > 0.94
    with caplog.at_level(logging.INFO, logger="trackcli"):
        outline = masks.object_outline(m)
    assert outline[:, 0].max() < 140  # the large disc alone
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "3 pieces; 2 (5" in warnings[0] and "left out" in warnings[0]


def test_specks_left_out_are_said_at_info_level_only(caplog):
    m = np.zeros((200, 300), np.uint8)
    cv2.circle(m, (80, 100), 50, 255, -1)
    m[10:12, 250:252] = 255
    with caplog.at_level(logging.INFO, logger="trackcli"):
        masks.object_outline(m)
    assert "2 pieces; 1 (0.051 % of its area) left out" in caplog.text
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


def test_a_mask_in_one_piece_is_its_outline():
    m = np.zeros((100, 120), np.uint8)
    cv2.ellipse(m, ((60, 50), (70, 40), 20), 255, -1)
    joined = masks.join_pieces(m)
    assert joined.describe() == "" and np.array_equal(joined.region, m > 0)
    np.testing.assert_array_equal(masks.object_outline(m), masks.mask_outline(m))


def test_object_outline_errors():
    with pytest.raises(Exception, match="no object"):
        masks.object_outline(np.zeros((20, 20), np.uint8))
    with pytest.raises(Exception, match="2-D"):
        masks.object_outline(np.ones((4, 4, 3), np.uint8))


def test_draw_mask_in_pieces_gives_one_template_over_all_of_them(tmp_path, caplog):
    whole, cut = _fenced_disc()
    frames = tmp_path / "frames"
    frames.mkdir()
    image = np.full((240, 320, 3), 90, np.uint8)
    image[cut > 0] = (40, 160, 220)
    cv2.imwrite(str(frames / "0001.png"), image)
    cv2.imwrite(str(tmp_path / "mask.png"), cut)
    with caplog.at_level(logging.INFO, logger="trackcli"):
        r = CliRunner().invoke(cli, ["-v", "draw", str(frames), "--fps", "25", "--mask", str(tmp_path / "mask.png"),
                                     "-o", str(tmp_path / "t.yaml")])
    assert r.exit_code == 0, r.output
    assert "joined to the largest by filling the gaps" in caplog.text
    t = load_template(tmp_path / "t.yaml")
    filled = _filled(t.Q, whole.shape) > 0
    assert masks.mask_iou(filled, whole) > 0.95
    n, labels = cv2.connectedComponents(cut)
    assert all(np.mean(filled[labels == k]) > 0.95 for k in range(1, n))  # every piece is in


# ---------------------------------------------------------------------------------------------
# the closed fit


def test_bend_vertices_start_at_the_first_point_and_find_the_corners_first():
    square = draw.resample_polygon(np.array([[0, 0], [100, 0], [100, 100], [0, 100]], float), 400, True)
    v = draw.bend_vertices(np.roll(square, -50, axis=0), 4)  # start half way along a side
    assert v[0] == 0 and len(v) == 4
    corners = {(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0)}
    # the first vertex is the start; the three others are corners of the square
    got = {tuple(np.round(np.roll(square, -50, axis=0)[i], 6)) for i in v[1:]}
    assert got <= corners and len(got) == 3


@pytest.mark.parametrize("share", [0.0, 0.5, 1.0])
def test_outline_params_put_the_bends_at_whole_spans_as_far_as_bend_share_says(share):
    # a 200 x 50 rectangle from a corner, 4 control points: by arc length its corners come at
    # s = 0, 1.6, 2, 3.6; by its bends (the corners) at 0, 1, 2, 3
    rect = draw.resample_polygon(np.array([[0, 0], [200, 0], [200, 50], [0, 50]], float), 1000, True)
    s = draw.outline_params(rect, 4, share)
    assert s[0] == 0.0 and np.all(np.diff(s) > 0) and s[-1] < 4
    corners = [0, 400, 500, 900]
    np.testing.assert_allclose(s[corners], (1 - share) * np.array([0, 1.6, 2, 3.6]) + share * np.arange(4), atol=1e-9)


def _hand() -> np.ndarray:
    m = np.zeros((400, 400), np.uint8)
    cv2.ellipse(m, ((200, 260), (130, 150), 0), 255, -1)
    for angle, length in ((-60, 110), (-25, 150), (0, 160), (20, 150), (45, 120)):
        a = np.deg2rad(angle - 90)
        start = (int(200 + 40 * np.cos(a)), int(230 + 40 * np.sin(a)))
        end = (int(200 + (40 + length) * np.cos(a)), int(230 + (40 + length) * np.sin(a)))
        cv2.line(m, start, end, 255, 22)
    return m


def test_the_closed_fit_follows_an_ellipse_closely():
    pts = draw.ellipse_outline(160.0, 120.0, 60.0, 35.0, 25.0, n=600)
    for n, tol in ((8, 0.5), (12, 0.15), (24, 0.1)):
        Q = draw.fit_closed(pts, n)
        assert _curve_to_polygon(Q, n, pts) < tol


@pytest.mark.parametrize("n_ctrl", [24, 32, 48, 64, 96])
def test_the_closed_fit_does_not_fold_or_loop_with_many_control_points(n_ctrl):
    # a hand's fingers: with parameters that only move locally, a curve with enough control
    # points to follow the fingers runs along the outline everywhere, however many it has
    # (12 cannot follow five fingers, and their curve crosses itself: its IoU is low, and the
    # growth of fit_covering goes on)
    m = _hand()
    outline = draw.canonical_start(masks.mask_outline(m).astype(float))
    pts = draw.resample_polygon(outline, 1500, True)
    Q = draw.fit_closed(pts, n_ctrl)
    assert _runs_against(Q, n_ctrl, pts) == 0
    assert masks.mask_iou(_filled(Q, m.shape), m) > 0.9


def test_a_leg_five_pixels_wide_is_followed_with_enough_control_points():
    # a flamingo: a body, a neck and a head, and a leg 5 px wide that holds a tenth of its area
    bird = np.zeros((400, 400), np.uint8)
    cv2.ellipse(bird, ((150, 120), (160, 70), 10), 255, -1)
    cv2.line(bird, (220, 110), (300, 40), 255, 12)
    cv2.circle(bird, (305, 38), 14, 255, -1)
    cv2.line(bird, (150, 150), (170, 380), 255, 5)
    outline = draw.canonical_start(masks.mask_outline(bird).astype(float))
    cover = drawing.fit_covering(outline, 12, 64)
    filled = _filled(cover.Q, bird.shape) > 0
    assert masks.mask_iou(filled, bird) > 0.93
    assert filled[300:330, 155:175].any()  # the leg's lower part is inside the curve


def test_the_closed_fit_starts_at_the_outlines_first_point():
    # the canonical start (topmost point, clockwise) gives control point 0 at the top
    pts = draw.canonical_start(draw.ellipse_outline(100.0, 100.0, 50.0, 30.0, 0.0, n=400))
    Q = draw.fit_closed(pts, 12)
    C = np.column_stack([Q[:12], Q[12:]])
    assert np.argmin(np.hypot(*(C - pts[0]).T)) in (0, 1, 11)


# ---------------------------------------------------------------------------------------------
# draw's defaults on templates from masks


def test_the_growing_fit_covers_a_mask_far_better_than_twelve_control_points(caplog):
    m = _hand()
    outline = draw.canonical_start(masks.mask_outline(m).astype(float))
    cover = drawing.fit_covering(outline, 12, 64)
    twelve = dict(cover.tried)[12]
    assert cover.iou >= drawing.TARGET_IOU > twelve + 0.1
    assert masks.mask_iou(_filled(cover.Q, m.shape), m) >= drawing.TARGET_IOU - 0.01
    assert cover.note() == f" ({cover.n_ctrl} control points, IoU {cover.iou:.2f} with the outline)"


def test_given_control_points_win_over_the_growth():
    outline = draw.canonical_start(masks.mask_outline(_hand()).astype(float))
    for n in (10, 12, 30):
        assert drawing.fit_template(outline, n).n_ctrl == n


# ---------------------------------------------------------------------------------------------
# the trackers with templates of many control points


@pytest.mark.parametrize("tracker", ["kalman", "condensation", "mht"])
def test_the_trackers_follow_a_template_of_sixty_four_control_points(tmp_path, ellipse_clip, tracker):
    # the shape-spaces built on a template (translation, similarity, affine) have the same
    # size whatever its control points; the curve's sampling and the outline grow with them
    from conftest import CLIP_DRIFT, CLIP_ELLIPSE, CLIP_FRAMES
    from trackcli.io.tracks import read_columns

    runner = CliRunner()
    cx, cy, a, b = CLIP_ELLIPSE
    r = runner.invoke(cli, ["draw", str(ellipse_clip), "--ellipse", f"{cx},{cy},{a},{b}", "--n-ctrl", "64",
                            "-o", str(tmp_path / "t.yaml")])
    assert r.exit_code == 0, r.output
    assert load_template(tmp_path / "t.yaml").n_ctrl == 64
    r = runner.invoke(cli, ["track", str(ellipse_clip), "--template", str(tmp_path / "t.yaml"), "--tracker", tracker,
                            "--no-rrd", "--seed", "0", "-o", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    cols = read_columns(next((tmp_path / "out").glob("*.csv")), ["cx", "cy"])
    true_x = cx + CLIP_DRIFT * np.arange(CLIP_FRAMES)
    assert np.max(np.hypot(cols["cx"] - true_x, cols["cy"] - cy)) < 3.0


# ---------------------------------------------------------------------------------------------
# bench/davis.py --template-only


def test_the_davis_bench_scores_frame_zero_templates_without_tracking(tmp_path):
    # a DAVIS-layout folder of one sequence, an ellipse in two frames: the template is drawn
    # from the first mask and scored against it; nothing is tracked
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    seq = tmp_path / "davis" / "ellipse"
    (seq / "img").mkdir(parents=True)
    (seq / "masks").mkdir()
    for k in range(2):
        m = np.zeros((120, 160), np.uint8)
        cv2.ellipse(m, ((70 + 2 * k, 60), (56, 72), 0), 255, -1)
        image = np.full((120, 160, 3), 200, np.uint8)
        image[m > 0] = (40, 40, 40)
        cv2.imwrite(str(seq / "img" / f"{k:05d}.jpg"), image)
        cv2.imwrite(str(seq / "masks" / f"{k:05d}.png"), m)
    env = {**os.environ, "PYTHONPATH": str(root)}
    out = tmp_path / "rows.json"
    r = subprocess.run([sys.executable, str(root / "bench" / "davis.py"), str(tmp_path / "davis"), "--template-only",
                        "--work", str(tmp_path / "work"), "--json", str(out)], capture_output=True, text=True, env=env,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    (row,) = json.loads(out.read_text())
    assert row["name"] == "ellipse" and row["tmpl"] > 0.95 and row["n_ctrl"] == 12
    assert "12 control points, IoU" in row["source"]
    assert "ellipse" in r.stdout and "mean (1)" in r.stdout
    assert not list((tmp_path / "work").glob("ellipse/*.csv"))  # nothing tracked
