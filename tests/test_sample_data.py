"""Tests of the synthetic sample clips and their ground truth (trackcli.sample_data)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli import sample_data as sd
from trackcli.sample_data import scene
from trackcli.errors import ConfigError, InputError

COMMITTED = Path(__file__).resolve().parent.parent / "sample_data"


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.suffix in (".csv", ".json")}


def _mask(poly: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Pixels whose centre lies inside ``poly``, by cv2.pointPolygonTest (independent of
    the renderer's fillPoly)."""
    h, w = shape
    lo = np.maximum(np.floor(poly.min(axis=0)).astype(int), 0)
    hi = np.minimum(np.ceil(poly.max(axis=0)).astype(int), [w - 1, h - 1])
    contour = poly.astype(np.float32).reshape(-1, 1, 2)
    out = np.zeros((h, w), bool)
    for y in range(lo[1], hi[1] + 1):
        for x in range(lo[0], hi[0] + 1):
            out[y, x] = cv2.pointPolygonTest(contour, (float(x), float(y)), False) > 0
    return out


def _grey(frame: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY).astype(float)


def _object_centroid(frame: np.ndarray, threshold: float = 168.0) -> tuple[np.ndarray, float]:
    """Centroid and area of the dark object on the light, clean train background."""
    dark = (_grey(frame) < threshold).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(dark, connectivity=8)
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    region = (labels == largest).astype(np.uint8)
    # fill any holes left by bright texture inside the object
    contours, _ = cv2.findContours(region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(region)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    ys, xs = np.nonzero(filled)
    return np.array([xs.mean(), ys.mean()]), float(xs.size)


# ---------------------------------------------------------------------------------------------
# Geometry


def test_base_outline_is_dense_centred_counter_clockwise_and_evenly_spaced():
    base = sd.head_and_shoulders()
    assert base.shape == (sd.N_OUTLINE_POINTS, 2)
    assert sd.polygon_area(base) < 0  # counter-clockwise on the screen (y down)
    np.testing.assert_allclose(sd.polygon_centroid(base), 0.0, atol=1e-4)
    gaps = np.hypot(*np.diff(np.vstack([base, base[:1]]), axis=0).T)
    assert gaps.max() < 1.1 * gaps.mean() and gaps.min() > 0.5 * gaps.mean()
    width, height = base.max(axis=0) - base.min(axis=0)
    assert 100 < width < 125 and 115 < height < 140
    assert base[0, 1] == base[:, 1].min() or abs(base[0, 1] - base[:, 1].min()) < 0.1  # starts on top
    assert base[1, 0] < base[0, 0]  # then heads left


def test_circle_outline_area_and_orientation():
    c = sd.circle_outline(16.0)
    assert sd.polygon_area(c) < 0
    assert abs(-sd.polygon_area(c) - math.pi * 16.0**2) < 0.01 * math.pi * 16.0**2


@settings(max_examples=60, deadline=None)
@given(
    tx=st.floats(-500, 500),
    ty=st.floats(-500, 500),
    angle=st.floats(-math.pi, math.pi),
    scale=st.floats(0.2, 3.0),
)
def test_true_outline_is_the_stated_similarity(tx, ty, angle, scale):
    base = sd.head_and_shoulders(64)
    row = {"tx": tx, "ty": ty, "angle": angle, "scale": scale}
    poly = sd.true_outline(row, base)
    np.testing.assert_allclose(sd.polygon_centroid(poly), [tx, ty], atol=1e-3 * max(1.0, scale))
    assert sd.polygon_area(poly) == pytest.approx(scale**2 * sd.polygon_area(base), rel=1e-9)
    # angle runs from +x towards +y: the first edge direction turns by exactly `angle`
    d0, d1 = base[1] - base[0], poly[1] - poly[0]
    turn = math.atan2(d0[0] * d1[1] - d0[1] * d1[0], d0 @ d1)
    assert math.isclose(math.remainder(turn - angle, 2 * math.pi), 0.0, abs_tol=1e-6)


# ---------------------------------------------------------------------------------------------
# Determinism and the committed set


def test_same_seed_gives_identical_truth_files_and_different_seed_differs(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    sd.generate(a, seed=7, truth_only=True)
    sd.generate(b, seed=7, truth_only=True)
    sd.generate(c, seed=8, truth_only=True)
    fa, fb, fc = _files(a), _files(b), _files(c)
    assert len(fa) == 2 * len(sd.CLIP_NAMES)
    assert fa == fb
    for name in sd.CLIP_NAMES:
        if name != "bouncing_ball":  # the ball's flight has no random part
            assert fa[f"{name}.truth.csv"] != fc[f"{name}.truth.csv"], name
    assert not list(a.glob(".*")), "temporary files left behind"


def test_shortened_clip_is_the_start_of_the_full_clip():
    for name in sd.CLIP_NAMES:
        full = sd.clip_truth(name, seed=3)
        short = sd.clip_truth(name, seed=3, n_frames=12)
        n = len(short)
        assert short.n_frames == 12
        for col in sd.TRUTH_COLUMNS:
            np.testing.assert_array_equal(getattr(short, col), getattr(full, col)[:n], err_msg=f"{name}.{col}")


def test_committed_truth_matches_the_generator(tmp_path):
    written = sd.generate(tmp_path, seed=sd.DEFAULT_SEED, truth_only=True)
    for path in written:
        committed = COMMITTED / path.name
        assert committed.is_file(), f"missing {committed}; regenerate with python -m trackcli.sample_data sample_data"
        assert committed.read_bytes() == path.read_bytes(), f"{path.name} differs from the generator"


def test_committed_videos_read_back_with_the_stated_size_and_length():
    for name in sd.CLIP_NAMES:
        outline = sd.load_outline(COMMITTED / f"{name}.outline.json")
        cap = cv2.VideoCapture(str(COMMITTED / outline.video))
        assert cap.isOpened(), outline.video
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == outline.n_frames
        assert (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))) == sd.FRAME_SIZE
        cap.release()
    total = sum(p.stat().st_size for p in COMMITTED.rglob("*") if p.is_file())
    assert total <= 10 * 1024 * 1024


# ---------------------------------------------------------------------------------------------
# Files


def test_truth_and_outline_round_trip(tmp_path):
    video, truth_path, outline_path = sd.write_clip("three_heads", tmp_path, seed=5, n_frames=6)
    assert video.suffix in (".mp4", ".avi")
    loaded = sd.load_truth(truth_path)
    direct = sd.clip_truth("three_heads", seed=5, n_frames=6)
    for col in sd.TRUTH_COLUMNS:
        np.testing.assert_array_equal(getattr(loaded, col), getattr(direct, col), err_msg=col)
    assert loaded.objects == (0, 1, 2) and loaded.n_frames == 6 and len(loaded) == 18
    outline = sd.load_outline(outline_path)
    assert (outline.clip, outline.video, outline.n_frames, outline.seed) == ("three_heads", video.name, 6, 5)
    assert (outline.width, outline.height, outline.fps) == (*sd.FRAME_SIZE, sd.FPS)
    assert len(outline.objects) == 3
    np.testing.assert_array_equal(outline.points, sd.head_and_shoulders())
    # the truth's centroid and box are those of the base outline under the truth's similarity
    for i in range(len(loaded)):
        row = loaded.row(i)
        poly = sd.true_outline(row, outline)
        np.testing.assert_allclose(sd.polygon_centroid(poly), [row["cx"], row["cy"]], atol=2e-4)
        np.testing.assert_allclose(poly.min(axis=0), [row["bbox_x"], row["bbox_y"]], atol=2e-4)
        np.testing.assert_allclose(np.ptp(poly, axis=0), [row["bbox_w"], row["bbox_h"]], atol=3e-4)
    assert np.all((loaded.visible >= 0) & (loaded.visible <= 1))
    assert (tmp_path / "three_heads.truth.csv").read_text().splitlines()[0] == ",".join(sd.TRUTH_COLUMNS)


def test_load_truth_and_outline_reject_malformed_files(tmp_path):
    bad = tmp_path / "bad.truth.csv"
    bad.write_text("frame,cx,cy\n0,1,2\n")
    with pytest.raises(InputError, match="header"):
        sd.load_truth(bad)
    bad.write_text(",".join(sd.TRUTH_COLUMNS) + "\n0,0,0,1,2,3,4,5,6,7,8,x,1,1\n")
    with pytest.raises(InputError, match="line 2"):
        sd.load_truth(bad)
    with pytest.raises(InputError, match="cannot read"):
        sd.load_truth(tmp_path / "missing.csv")
    js = tmp_path / "bad.outline.json"
    js.write_text(json.dumps({"format": 2, "points": []}))
    with pytest.raises(InputError, match="format must be 1"):
        sd.load_outline(js)
    js.write_text(json.dumps({"format": 1, "points": [[0, 0]]}))
    with pytest.raises(InputError, match="lacks field 'clip'"):
        sd.load_outline(js)
    js.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        sd.load_outline(js)


def test_invalid_arguments_name_the_value_and_the_choices(tmp_path):
    with pytest.raises(ConfigError, match="'walk'.*train, test, three_heads, bouncing_ball"):
        sd.generate(tmp_path, clips=["walk"])
    with pytest.raises(ConfigError, match="seed"):
        sd.clip_truth("train", seed=-1)
    with pytest.raises(ConfigError, match="n_frames"):
        sd.clip_truth("train", n_frames=0)
    with pytest.raises(ConfigError, match="no object 3"):
        sd.clip_truth("train", n_frames=2).select(3)
    assert not list(tmp_path.iterdir())  # nothing written before the check


def test_generate_reports_progress_and_writes_readable_video(tmp_path):
    calls = []
    paths = sd.generate(tmp_path, seed=11, clips=["bouncing_ball"], n_frames=6,
                        progress=lambda *a: calls.append(a))  # fmt: skip
    assert [p.name for p in paths][1:] == ["bouncing_ball.truth.csv", "bouncing_ball.outline.json"]
    assert calls == [("bouncing_ball", k, 6) for k in range(6)]
    cap = cv2.VideoCapture(str(paths[0]))
    frames = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    assert len(frames) == 6 and frames[0].shape == (360, 480, 3)
    rendered = list(sd.render_frames("bouncing_ball", seed=11, n_frames=6))
    # lossy, but close to what was rendered
    assert np.mean([np.abs(f.astype(float) - r).mean() for f, r in zip(frames, rendered)]) < 6.0


# ---------------------------------------------------------------------------------------------
# The truth agrees with the pictures


def test_train_frames_match_their_truth():
    truth = sd.clip_truth("train", n_frames=40)
    base = sd.head_and_shoulders()
    kernel = np.ones((3, 3), np.uint8)
    for k, frame in enumerate(sd.render_frames("train", n_frames=40)):
        if k % 8:
            continue
        row = truth.row(k)
        poly = sd.true_outline(row, base)
        centre, area = _object_centroid(frame)
        assert np.hypot(*(centre - [row["cx"], row["cy"]])) < 0.3, k
        assert area == pytest.approx(-sd.polygon_area(poly), rel=0.03)
        inside = _mask(poly, frame.shape[:2]).astype(np.uint8)

        def grown(n: int) -> np.ndarray:
            op = cv2.dilate if n > 0 else cv2.erode
            return op(inside, kernel, iterations=abs(n)).astype(bool)

        band_in = grown(-1) & ~grown(-4)  # 1 to 4 px inside the true outline
        band_out = grown(5) & ~grown(1)  # 1 to 5 px outside
        grey = _grey(frame)
        assert grey[band_out].mean() - grey[band_in].mean() > 40, k


def test_decoded_train_video_keeps_the_object_where_the_truth_says(tmp_path):
    video, truth_path, _ = sd.make_train(tmp_path, seed=21, n_frames=8)
    truth = sd.load_truth(truth_path)
    cap = cv2.VideoCapture(str(video))
    for k in range(8):
        ok, frame = cap.read()
        assert ok, k
        centre, _ = _object_centroid(frame)
        assert np.hypot(centre[0] - truth.cx[k], centre[1] - truth.cy[k]) < 0.3, k
    assert not cap.read()[0]


def test_renderer_coverage_has_the_outline_area_and_centroid():
    """A flat shape on a flat canvas: the coverage integrates to the polygon's area and its
    centroid is the polygon's, to a few hundredths of a pixel, at any sub-pixel pose."""
    rng = np.random.default_rng(4)
    base = sd.head_and_shoulders()
    perimeter = np.hypot(*np.diff(np.vstack([base, base[:1]]), axis=0).T).sum()
    ys, xs = np.mgrid[0:360, 0:480]
    for _ in range(5):
        pose = (rng.uniform(150, 330), rng.uniform(120, 240), rng.uniform(-0.5, 0.5), rng.uniform(0.7, 1.3))
        canvas = np.full((360, 480, 3), 200.0, np.float32)
        scene._composite(canvas, scene._Item(base, scene._flat_sprite((50, 50, 50)), pose))
        alpha = (200.0 - canvas[..., 0]) / 150.0
        poly = sd.similarity(base, *pose)
        area = -sd.polygon_area(poly)
        assert abs(alpha.sum() - area) < 0.015 * perimeter * pose[3]  # mean edge offset < 0.015 px
        centroid = np.array([(alpha * xs).sum(), (alpha * ys).sum()]) / alpha.sum()
        np.testing.assert_allclose(centroid, pose[:2], atol=0.02)


def test_rendered_edge_lies_on_the_true_outline():
    """Sub-pixel check on a train frame: the grey level along each outline normal crosses
    half-way between inside and outside close to the outline.  (The object's rim is shaded
    darker, which moves the half-way crossing outwards by about 0.1 px.)"""
    truth = sd.clip_truth("train", n_frames=1)
    frame = next(sd.render_frames("train", n_frames=1))
    grey = cv2.GaussianBlur(_grey(frame).astype(np.float32), (0, 0), 0.7)
    poly = sd.true_outline(truth.row(0), sd.head_and_shoulders())
    tangent = np.roll(poly, -1, axis=0) - np.roll(poly, 1, axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)  # outward for this orientation
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    u = np.linspace(-4, 4, 81)
    pts = poly[:, None, :] + u[None, :, None] * normal[:, None, :]
    prof = cv2.remap(grey, pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32), cv2.INTER_LINEAR)
    offsets = []
    for p in prof:
        lo_, hi_ = p[15:26].mean(), p[55:66].mean()  # 1.5 to 2.5 px inside (dark), outside (light)
        if hi_ - lo_ < 40:
            continue
        half = 0.5 * (lo_ + hi_)
        j = np.nonzero((p[:-1] < half) & (p[1:] >= half))[0]
        if len(j) == 1:
            j = j[0]
            offsets.append(u[j] + (half - p[j]) / (p[j + 1] - p[j]) * (u[j + 1] - u[j]))
    assert len(offsets) > 150
    assert abs(np.median(offsets)) < 0.25
    assert np.percentile(np.abs(offsets), 90) < 0.6


def test_visible_fraction_of_the_occluded_test_frames(tmp_path):
    """The pole hides the object for about ten frames; the visible fraction agrees with an
    independent point-sampling estimate."""
    truth_path, outline_path = sd.make_test(tmp_path, truth_only=True)
    truth = sd.load_truth(truth_path)
    with_bar = np.nonzero(truth.visible < 0.995)[0]
    occ = sd.load_outline(outline_path).motion["occluder"]
    k0 = occ["crosses_at_frame"]
    near = with_bar[np.abs(with_bar - k0) <= 12]
    assert 8 <= len(near) <= 12 and k0 in near
    assert truth.visible[k0] < 0.9
    base = sd.head_and_shoulders()
    nrm = np.array([math.cos(occ["angle"]), math.sin(occ["angle"])])
    W, H = sd.FRAME_SIZE
    for k in (k0 - 2, k0, k0 + 2):
        poly = sd.true_outline(truth.row(k), base)
        centre = np.asarray(occ["centre_at_crossing"]) + (k - k0) * np.asarray(occ["velocity_px_per_frame"])
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        step = 0.5
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0], step) + step / 4, np.arange(lo[1], hi[1], step) + step / 4)
        contour = poly.astype(np.float32).reshape(-1, 1, 2)
        inside = np.array([cv2.pointPolygonTest(contour, (float(x), float(y)), False) > 0
                           for x, y in zip(xs.ravel(), ys.ravel())])  # fmt: skip
        pts = np.column_stack([xs.ravel(), ys.ravel()])
        in_frame = (pts[:, 0] >= -0.5) & (pts[:, 0] < W - 0.5) & (pts[:, 1] >= -0.5) & (pts[:, 1] < H - 0.5)
        hidden = np.abs((pts - centre) @ nrm) < occ["width"] / 2
        estimate = (inside & in_frame & ~hidden).sum() / inside.sum()
        assert truth.visible[k] == pytest.approx(estimate, abs=0.01), k


def test_walker_passes_in_front_of_the_still_heads():
    truth = sd.clip_truth("three_heads")
    still = [truth.select(0), truth.select(1)]
    walker = truth.select(2)
    for s in still:
        assert np.ptp(s.tx) < 6 and np.ptp(s.ty) < 6
        assert s.visible.min() < 0.6  # hidden behind the walker for a while
        overlap = np.abs(walker.tx - s.tx) < 20
        assert overlap.any() and np.all(s.visible[overlap] < 0.8)
    assert walker.tx[0] > 400 and walker.tx[-1] < 80  # right to left
    assert np.all(np.diff(walker.tx) < 0)
    # drawn on top: only leaving the image can hide it
    inside = (walker.bbox_x >= 0) & (walker.bbox_x + walker.bbox_w <= sd.FRAME_SIZE[0] - 1)
    assert np.all(walker.visible[inside] == 1.0)


def test_ball_bounces_with_energy_loss(tmp_path):
    truth_path, outline_path = sd.make_bouncing_ball(tmp_path, truth_only=True)
    truth = sd.load_truth(truth_path)
    motion = sd.load_outline(outline_path).motion
    rest_y = motion["floor_y"] - motion["radius"]
    assert truth.cy.max() <= rest_y + 1e-3
    vy = np.diff(truth.cy)
    bounces = np.nonzero((vy[:-1] > 0) & (vy[1:] < 0))[0] + 1
    assert len(bounces) >= 3
    assert np.all(np.abs(vy[bounces - 1]) > 8)  # fast downwards just before each bounce
    # apex heights above the resting centre shrink by about restitution² per bounce
    apex = [rest_y - truth.cy[a:b].min() for a, b in zip(bounces[:-1], bounces[1:])]
    ratios = np.array(apex[1:]) / np.array(apex[:-1])
    np.testing.assert_allclose(ratios, motion["restitution"] ** 2, rtol=0.08)
    # free flight between bounces is a parabola with the stated gravity
    a, b = bounces[0] + 1, bounces[1] - 1
    acc = np.diff(truth.cy[a : b + 1], 2)
    np.testing.assert_allclose(acc, motion["g_px_per_frame2"], atol=1e-3)
    assert np.all(truth.visible == 1.0)


def test_train_motion_recovers_its_ar2_coefficients(tmp_path):
    """Least squares on the truth recovers the AR(2) coefficients it was simulated with."""
    truth_path, outline_path = sd.make_train(tmp_path, truth_only=True)
    truth = sd.load_truth(truth_path)
    params = sd.load_outline(outline_path).motion["parameters"]
    for name in ("tx", "ty", "angle", "scale"):
        y = getattr(truth, name) - params[name]["mean"]
        design = np.column_stack([y[1:-1], y[:-2]])
        a1, a2 = np.linalg.lstsq(design, y[2:], rcond=None)[0]
        assert a1 == pytest.approx(params[name]["a1"], abs=0.08), name
        assert a2 == pytest.approx(params[name]["a2"], abs=0.08), name
    speed = np.hypot(np.diff(truth.tx), np.diff(truth.ty))
    assert speed.max() <= 3.0 + 1e-3
    assert np.degrees(np.abs(truth.angle)).max() == pytest.approx(8.0, abs=0.01)
    assert np.abs(truth.scale - 1).max() == pytest.approx(0.08, abs=1e-4)


def test_test_clip_is_agile():
    truth = sd.clip_truth("test")
    v = np.diff(np.column_stack([truth.tx, truth.ty]), axis=0)
    speed = np.hypot(*v.T)
    assert 10 <= speed.max() <= 15
    # sudden direction changes: the velocity turns by more than 90° within 3 frames, often
    turns = [k for k in range(len(v) - 3) if speed[k] > 4 and speed[k + 3] > 4 and v[k] @ v[k + 3] < 0]
    assert len(turns) >= 5
    # mostly inside the image whenever it is not behind the pole
    assert truth.visible.min() > 0.5
