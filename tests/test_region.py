"""The outline refinement (trackcli.observe.region) on synthetic frames: where it starts, how its
outline is written, how its colours follow the object."""

from __future__ import annotations

import types

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from trackcli.cli import cli
from trackcli.errors import TemplateError
from trackcli.observe import region as R
from trackcli.run.masks import outline_mask, region_similarity
from trackcli.shapes.template import Template, load_template, save_template

SIZE = (120, 160)  # height, width


def settings(**kw):
    base = dict(refine=True, prior_width=0.5, flow=True, colour_rate=0.0, lost_contrast=3.0)
    base.update(kw)
    return types.SimpleNamespace(**base)


def c_shape(dx: float = 0.0) -> np.ndarray:
    """A thick 'C' open to the right (bool mask of SIZE): a disc less a disc and a slot."""
    m = np.zeros(SIZE, np.uint8)
    cx, cy = 70 + dx, 60
    cv2.circle(m, (int(round(cx)), cy), 36, 1, -1)
    cv2.circle(m, (int(round(cx)), cy), 20, 0, -1)
    cv2.rectangle(m, (int(round(cx)), cy - 12), (int(round(cx)) + 40, cy + 12), 0, -1)
    return m.astype(bool)


def frame(mask: np.ndarray, rng: np.random.Generator, obj=(40, 40, 200), back=(90, 160, 90)) -> np.ndarray:
    img = np.empty(SIZE + (3,))
    img[:] = back
    img[mask] = obj
    img += rng.normal(0.0, 6.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def ellipse_about(mask: np.ndarray) -> np.ndarray:
    """A smooth outline about a mask, as a template's curve is: the fitted ellipse, grown a little."""
    (cx, cy), (a, b), ang = cv2.fitEllipse(R.mask_polygons(mask)[0].astype(np.float32))
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    a, b = 0.55 * a, 0.55 * b
    c, s = np.cos(np.radians(ang)), np.sin(np.radians(ang))
    x, y = a * np.cos(t), b * np.sin(t)
    return np.column_stack([cx + c * x - s * y, cy + s * x + c * y])


# ---------------------------------------------------------------------------------------------
# A region as polygons


def test_mask_polygons_fill_back_a_mask_with_pieces_and_holes():
    m = np.zeros(SIZE, bool)
    m[10:60, 10:70] = True
    m[25:40, 25:45] = False        # a hole
    m[80:100, 100:130] = True      # a second, smaller piece
    m[5, 150] = True               # a speck, left out
    pieces = R.mask_polygons(m)
    assert len(pieces) == 3
    assert cv2.contourArea(pieces[0].astype(np.float32)) > cv2.contourArea(pieces[1].astype(np.float32))
    back = R.region_fill(pieces, SIZE)
    assert not back[30:35, 30:40].any()  # the hole stays a hole
    assert not back[5, 150]
    assert region_similarity(back, m) > 0.95


def test_a_templates_region_is_written_and_read_back(tmp_path):
    m = c_shape()
    pieces = R.mask_polygons(m)
    t = Template(ellipse_about(m)[::10], region=tuple(pieces))
    save_template(tmp_path / "t.yaml", t)
    back = load_template(tmp_path / "t.yaml")
    assert len(back.region) == len(pieces)
    for a, b in zip(back.region, pieces):
        np.testing.assert_array_equal(a, b)
    assert "region" not in back.extra
    with pytest.raises(TemplateError, match="region"):
        Template(t.control_points, region=([[1.0, 2.0], [3.0, 4.0]],))
    (tmp_path / "bad.yaml").write_text((tmp_path / "t.yaml").read_text().replace("region:", "region: 3\nx:"))
    with pytest.raises(TemplateError, match="region"):
        load_template(tmp_path / "bad.yaml")


def test_draw_from_a_mask_keeps_the_mask_as_the_templates_region(tmp_path, ellipse_clip):
    m = np.zeros(SIZE, np.uint8)
    cv2.ellipse(m, ((70, 60), (56, 72), 0.0), 255, -1)
    m[50:70, 70:100] = 0  # a notch the spline smooths over
    cv2.imwrite(str(tmp_path / "m.png"), m)
    r = CliRunner().invoke(cli, ["draw", str(ellipse_clip), "--mask", str(tmp_path / "m.png"), "-o",
                                 str(tmp_path / "t.yaml")])
    assert r.exit_code == 0, r.output
    t = load_template(tmp_path / "t.yaml")
    assert t.region is not None
    assert region_similarity(R.region_fill(t.region, SIZE), m > 0) > 0.97


# ---------------------------------------------------------------------------------------------
# Where the refinement starts


def run_refiner(start, n: int = 4):
    """J of each frame's refined outline on a C drifting right, from an ellipse about it."""
    rng = np.random.default_rng(3)
    ref = R.OutlineRefiner(settings(), start=start)
    js = []
    for k in range(n):
        m = c_shape(2.0 * k)
        est = ellipse_about(m)  # the tracker's estimate: where the object is, not its shape
        fit = ref(frame(m, rng), est)
        js.append(region_similarity(outline_mask(fit.outline, SIZE), m))
    return js


def test_the_refinement_starts_from_the_templates_region():
    """The region the template was fitted to teaches the colours: the background the smooth
    template takes in (the C's mouth) is background from the first frame on."""
    with_region = run_refiner(R.mask_polygons(c_shape()))
    without = run_refiner(None)
    assert with_region[0] > 0.97  # the first frame's outline is the region's
    assert min(with_region[1:]) > 0.9, with_region
    assert np.mean(with_region[1:]) > np.mean(without[1:]) + 0.05, (with_region, without)


def test_a_region_away_from_the_first_estimate_is_not_used():
    """A template's region elsewhere than the tracker starts (another frame's, a model placed
    elsewhere) teaches nothing: the refinement starts from the estimate, as without one."""
    far = [p + [0.0, 200.0] for p in R.mask_polygons(c_shape())]
    assert run_refiner(far) == pytest.approx(run_refiner(None))


# ---------------------------------------------------------------------------------------------
# The outline written


def test_simplified_outline_keeps_the_corners_a_ragged_boundary_would_lose():
    """A star whose boundary follows single pixels: 24 points at its corners fill it better
    than 24 equally spaced along its steps."""
    t = np.linspace(0, 2 * np.pi, 10, endpoint=False)
    r = np.where(np.arange(10) % 2 == 0, 50.0, 18.0)
    star = np.column_stack([80 + r * np.sin(t), 60 - r * np.cos(t)])
    m = outline_mask(star, SIZE)
    boundary = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0][0][:, 0, :]
    simple = R.simplify_closed(boundary.astype(float), 24)
    spaced = R.resample_closed(boundary.astype(float), 24)
    assert simple.shape == (24, 2)
    j_simple = region_similarity(outline_mask(simple, SIZE), m)
    j_spaced = region_similarity(outline_mask(spaced, SIZE), m)
    assert j_simple > 0.95 and j_simple > j_spaced + 0.03, (j_simple, j_spaced)
    # clockwise on screen (positive shoelace sum with y down), from the top
    x, y = simple[:, 0], simple[:, 1]
    assert np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
    assert simple[0, 1] == pytest.approx(simple[:, 1].min())
    assert R.simplify_closed(boundary.astype(float), 200).shape == (200, 2)


# ---------------------------------------------------------------------------------------------
# Colours that follow the object


def disc(cx: float, cy: float = 60.0, r: float = 22.0) -> np.ndarray:
    m = np.zeros(SIZE, np.uint8)
    cv2.circle(m, (int(round(cx)), int(round(cy))), int(r), 1, -1)
    return m.astype(bool)


def circle(cx: float, cy: float = 60.0, r: float = 24.0) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def fading_run(rate: float, n: int = 40, twin: bool = False):
    """J per frame of a red disc whose colour turns slowly to blue (light changing) as it drifts
    right; with ``twin``, a look-alike of its first colour stands just below-right of it throughout."""
    rng = np.random.default_rng(5)
    ref = R.OutlineRefiner(settings(colour_rate=rate), start=R.mask_polygons(disc(50)))
    js, leaks = [], []
    for k in range(n):
        u = k / (n - 1)
        obj = (40 + 150 * u, 40, 200 - 150 * u)  # BGR: red to blue
        m = disc(50 + k)
        img = frame(m, rng, obj=obj)
        if twin:
            other = disc(50 + k + 44, 60 + 30, 16)
            img[other] = np.clip(np.array([40, 40, 200]) + rng.normal(0, 6, (int(other.sum()), 3)), 0, 255)
        fit = ref(img, circle(50 + k), confidence=0.9)
        got = outline_mask(fit.outline, SIZE)
        js.append(region_similarity(got, m))
        if twin:
            leaks.append(np.count_nonzero(got & other) / np.count_nonzero(other))
    return js, leaks


def test_the_colours_follow_the_object_through_a_change_of_light():
    """Learned on the first frame only, the colours no longer tell the object once its light
    changed: the outline falls back on the priors (here a circle a little larger than the disc).
    Moved slowly toward each frame held with confidence, they still do."""
    held, _ = fading_run(0.1)
    fixed, _ = fading_run(0.0)
    assert min(held) > 0.9, held
    assert np.mean(held[-10:]) > np.mean(fixed[-10:]) + 0.03, (held[-10:], fixed[-10:])


def test_the_colour_update_does_not_drift_onto_a_look_alike_beside_the_object():
    """A look-alike of the object's first colours beside it: the updated model follows the
    object, and its region does not take in the look-alike."""
    js, leaks = fading_run(0.1, twin=True)
    assert min(js) > 0.85, js
    assert max(leaks) < 0.05, leaks


# ---------------------------------------------------------------------------------------------
# A region that vouches for a frame


def test_contrast_is_high_on_the_object_and_low_on_background_or_half_on_it():
    rng = np.random.default_rng(2)
    m = disc(60)
    img = frame(m, rng)
    model = R.ColourModel.learn(img, m)
    on = R.contrast(img, circle(60, r=22), model)
    half = R.contrast(img, circle(82, r=22), model)
    off = R.contrast(img, circle(125, 35, r=15), model)
    assert on > 5.0 and half < 3.0 and off < 1.0, (on, half, off)
    assert np.isnan(R.contrast(img, np.zeros((5, 2)), model))


class _LostTracker:
    """A stand-in tracker whose estimate is a circle at ``xs[k]`` on frame ``k``, always reported lost."""

    def __init__(self, xs):
        self.xs = list(xs)

    def step(self, frame):
        from trackcli.trackers.base import FrameResult

        c = circle(self.xs[frame.index], r=26)
        return FrameResult(index=frame.index, time=frame.time, X=np.zeros(2), X_std=np.zeros(2), contour=c,
                           centroid=c.mean(axis=0), bbox=(0.0, 0.0, 1.0, 1.0), n_found=0, n_normals=24,
                           gate_rms=10.0, lost=True, confidence=0.2)


@pytest.mark.parametrize("xs, threshold, lost", [
    ((60, 60, 60), 3.0, (False, False, False)),    # on the object: the region vouches
    ((60, 60, 60), 0.0, (True, True, True)),       # lost_contrast 0: the tracker's verdict
    ((125, 125, 125), 3.0, (True, True, True)),    # on the background: nothing stands out
    ((60, 104, 104), 3.0, (False, True, True)),    # beside the object: the region stays on it
])
def test_a_region_that_stands_out_overrules_the_trackers_lost(xs, threshold, lost):
    """The refined region on the object, standing out in its colours, overrules the tracker's
    ``lost`` (a contour that does not fit a deforming object), unless ``lost_contrast`` is 0.  An
    estimate on the background stays lost; so does one that left the object, though the region
    (moved by the flow, in the object's colours) stays on it: a region that no longer agrees with
    the estimate vouches for neither."""
    from trackcli.trackers.base import FrameData, run_tracker

    rng = np.random.default_rng(4)
    m = disc(60)
    frames = [FrameData(k, k / 25, frame(m, rng), np.zeros(SIZE, np.float32)) for k in range(3)]
    ref = R.OutlineRefiner(settings(lost_contrast=threshold), start=R.mask_polygons(m))
    results = list(run_tracker(_LostTracker(xs), frames, refiner=ref))
    assert tuple(r.lost for r in results) == lost
    if xs[-1] == 104:
        assert region_similarity(outline_mask(results[-1].outline, SIZE), m) > 0.9
        assert results[-1].region_agreement < R.HOLD_AGREEMENT


def test_an_estimate_shrunk_onto_a_part_does_not_pull_the_outline_after_it():
    """The prior's width is a share of the object's size, the largest of its priors': when the
    tracker's estimate shrinks onto a part of the object (a car's wheel) while the last outline,
    moved by the flow, still covers all of it, the outline stays on the whole object.  With the
    size of the estimate alone the prior fell off within a wheel's width and the outline
    followed the estimate onto the wheel."""
    rng = np.random.default_rng(5)
    m = np.zeros(SIZE, np.uint8)
    cv2.rectangle(m, (20, 40), (139, 79), 1, -1)  # the body, 120 x 40
    m = m.astype(bool)
    img = frame(m, rng)
    model = R.ColourModel.learn(img, m)
    t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    wheel = np.column_stack([120 + 12 * np.cos(t), 68 + 12 * np.sin(t)])  # the estimate, on a corner
    whole = R.mask_polygons(m)[0]
    alone = R.refine(img, wheel, model, sigma=0.5)
    both = R.refine(img, wheel, model, sigma=0.5, others=((whole, 1.0),))
    assert region_similarity(outline_mask(alone.outline, SIZE), m) < 0.6  # the estimate alone: a part
    assert region_similarity(outline_mask(both.outline, SIZE), m) > 0.9


def test_a_large_object_refined_on_the_shrunk_frame_gives_the_same_outline():
    """``work_size``: the region of a large object found on the ROI shrunk to that size is, in
    the frame's pixels, the one found at full size (to a pixel or so)."""
    rng = np.random.default_rng(8)
    m = np.zeros(SIZE, np.uint8)
    cv2.ellipse(m, ((80, 60), (120, 90), 20.0), 1, -1)
    m = m.astype(bool)
    img = frame(m, rng)
    model = R.ColourModel.learn(img, m)
    est = ellipse_about(m)
    full = R.refine(img, est, model, sigma=0.5)
    small = R.refine(img, est, model, sigma=0.5, work_size=50.0)
    assert full.scale == 1.0 and small.scale < 0.6
    assert small.mask.shape[0] < 0.6 * full.mask.shape[0]
    j = region_similarity(outline_mask(small.outline, SIZE), outline_mask(full.outline, SIZE))
    assert j > 0.95 and region_similarity(outline_mask(small.outline, SIZE), m) > 0.95, j


# ---------------------------------------------------------------------------------------------
# An object in pieces


def test_joined_outline_fills_every_piece_and_little_else():
    m = np.zeros(SIZE, bool)
    m[10:50, 10:50] = True
    m[60:100, 20:40] = True
    m[20:40, 100:150] = True
    m[105:110, 120:125] = True
    pieces = R.outer_pieces(m)
    assert len(pieces) == 4
    joined = R.joined_outline(pieces)
    filled = outline_mask(joined, SIZE)
    assert np.all(filled[m])
    # beyond the pieces, only the bridges' lines (about 120 px of them, two pixels wide at most)
    assert np.count_nonzero(filled & ~m) < 2 * 125
    np.testing.assert_array_equal(R.joined_outline(pieces[:1]), pieces[0])


def test_joined_outline_walks_each_piece_once_round_and_crosses_each_bridge_there_and_back():
    m = np.zeros(SIZE, bool)
    m[10:50, 10:50] = True
    m[60:100, 20:40] = True
    m[20:40, 100:150] = True
    pieces = R.outer_pieces(m)
    joined = R.joined_outline(pieces)
    # every boundary point once, plus the point each bridge leaves from again on the way back
    assert len(joined) == sum(len(p) for p in pieces) + len(pieces) - 1
    rows = {tuple(q) for q in joined}
    assert all(tuple(q) in rows for p in pieces for q in p)
    # the walk starts where the largest piece starts, and its steps are a pixel except at bridges
    np.testing.assert_array_equal(joined[0], pieces[0][0])
    steps = np.hypot(*np.diff(joined, axis=0).T)
    assert np.count_nonzero(steps > 1.5) == 2 * (len(pieces) - 1)


def test_the_colour_log_ratio_is_the_same_compiled_and_on_a_mask():
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (60, 80, 3), dtype=np.uint8)
    model = R.ColourModel(rng.random(R.BINS ** 3), rng.random(R.BINS ** 3))
    lut = np.clip(np.log(model.fg + 1e-4) - np.log(model.bg + 1e-4), -R.L_MAX, R.L_MAX).astype(np.float32)
    roi = image[5:50, 7:70]  # a view with strides, as the refinement reads its ROI
    q = roi.astype(np.int64) * R.BINS // 256
    expected = lut[(q[..., 0] * R.BINS + q[..., 1]) * R.BINS + q[..., 2]]
    np.testing.assert_array_equal(model.log_ratio(roi), expected)
    mask = rng.random(roi.shape[:2]) > 0.6
    np.testing.assert_array_equal(model.log_ratio(roi, mask), expected[mask])
    np.testing.assert_array_equal(model.log_ratio(roi.astype(np.float64)), expected)  # not compiled
    model.blend(R.ColourModel(model.bg, model.fg), 0.5)  # new histograms: a new table
    assert np.all(np.abs(model.log_ratio(roi)) < 1e-6)


def test_an_object_a_pole_cuts_in_two_is_outlined_whole():
    """A pole in front of the object cuts its region in two; both parts are on the estimate, and
    the outline takes both in (before: only the larger)."""
    rng = np.random.default_rng(6)
    m = np.zeros(SIZE, np.uint8)
    cv2.ellipse(m, ((75, 60), (90, 50), 0.0), 1, -1)
    m[:, 88:96] = 0  # the pole
    m = m.astype(bool)
    img = frame(m, rng)
    img[:, 88:96] = (200, 200, 200)
    ref = R.OutlineRefiner(settings(), start=R.mask_polygons(m))
    for _ in range(3):
        fit = ref(img, ellipse_about(m))
    assert len(fit.pieces) == 2
    assert region_similarity(outline_mask(fit.outline, SIZE), m) > 0.9


def test_a_region_that_holds_the_whole_object_vouches_for_an_estimate_shrunk_onto_a_part():
    """The lost verdict's agreement: an estimate shrunk onto a part of the object (a wheel), which
    the region covers, is held by it though their IoU is small; one beside the object is not."""
    rng = np.random.default_rng(5)
    m = np.zeros(SIZE, np.uint8)
    cv2.rectangle(m, (20, 40), (139, 79), 1, -1)
    m = m.astype(bool)
    img = frame(m, rng)
    t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    ref = R.OutlineRefiner(settings(), start=R.mask_polygons(m))
    ref(img, R.mask_polygons(m)[0], 0.9)  # the first frame: the colours, the region
    wheel = ref(img, np.column_stack([120 + 12 * np.cos(t), 68 + 12 * np.sin(t)]), 0.2)
    assert wheel.agreement < R.HOLD_AGREEMENT and wheel.covers > 0.9 and ref.holds(wheel)


def test_edge_strength_is_higher_along_the_objects_boundary_than_across_flat_colour():
    rng = np.random.default_rng(2)
    m = np.zeros(SIZE, np.uint8)
    cv2.rectangle(m, (40, 30), (119, 89), 1, -1)
    img = frame(m.astype(bool), rng)
    on = np.array([[40, 30], [119, 30], [119, 89], [40, 89]], float)
    off = np.array([[25, 15], [134, 15], [134, 104], [25, 104]], float)  # 15 px out, flat background
    s_on, s_off, s_none = R.edge_strength(img, [on, off, np.full((3, 2), np.nan)])
    assert s_on > 5 * s_off and np.isnan(s_none)
