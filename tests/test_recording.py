"""Tests for trackcli.io.recording: write .rrd files, read them back, verify with the rerun CLI."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import warnings

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import rrd_utils as ru
from trackcli.errors import ConfigError, DataError, TrackcliError
from trackcli.io.recording import (
    BLUEPRINTS,
    Recording,
    histogram_image,
    make_blueprint,
    weight_colors,
)

N_FRAMES = 5
FPS = 25.0
H, W = 48, 64
M = 12  # samples per contour
K = 6  # weighted contours per frame
EDGES = np.linspace(-10.0, 10.0, 9)  # 8 bins


def _rgba(packed: int) -> tuple[int, int, int, int]:
    """Unpack Rerun's 0xRRGGBBAA colour."""
    return tuple(int(b) for b in packed.to_bytes(4, "big"))


def _synthetic_frame(i: int) -> np.ndarray:
    """A BGR frame with a bright disc moving right on a gradient."""
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 1] = np.linspace(0, 120, W, dtype=np.uint8)[None, :]
    cv2.circle(img, (12 + 6 * i, H // 2), 9, (40, 40, 230), -1)
    return img


def _write_vp9(path, n: int = N_FRAMES) -> bool:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"vp09"), FPS, (W, H))
    if not writer.isOpened():
        return False
    for i in range(n):
        writer.write(_synthetic_frame(i))
    writer.release()
    return path.exists() and path.stat().st_size > 0


def _circle(center, radius: float, m: int = M) -> np.ndarray:
    s = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    return np.column_stack([center[0] + radius * np.cos(s), center[1] + radius * np.sin(s)])


@pytest.fixture(scope="module", params=[False, True], ids=["one-by-one", "batched"])
def full(tmp_path_factory, request):
    """A 5-frame recording with every kind of data; returns (path, what was logged).

    Made twice: logging every call at once, and with the frames and overlays held and sent
    as columns (``batch_overlays``; flushed after frame 2 and when the recording closes),
    which must give the same rows.
    """
    rng = np.random.default_rng(7)
    folder = tmp_path_factory.mktemp("full")
    path = folder / "run.rrd"
    params = {"seed": 7, "tracker": "condensation", "dynamics": {"beta": 0.5, "f": 1.25},
              "shape": [3, 4], "note": None}
    logged = {"params": params, "estimate": [], "particles": [], "weights": [], "points": [],
              "starts": [], "ends": [], "hist": [], "frames": [], "ess": []}
    frames = np.arange(N_FRAMES)
    times = frames / FPS
    translation = rng.normal(size=(N_FRAMES, 2))
    hist_matrix = rng.random((N_FRAMES, len(EDGES) - 1))
    with Recording(path, blueprint="track", recording_id="test-run") as rec:
        rec.log_params("params", params)
        if request.param:
            rec.batch_overlays()
        log_video = rec.frame_logger(None, quality=95)
        for i in frames:
            if request.param and i == 3:
                rec.flush_overlays()
            rec.set_frame(int(i), float(times[i]))
            img = _synthetic_frame(int(i))
            log_video(int(i), img)
            est = _circle((12 + 6 * i, H / 2), 9)
            rec.log_contour("video/estimate", est, color=(255, 0, 0), width=2.0)
            curves = est[None] + rng.normal(scale=2.0, size=(K, M, 2))
            w = rng.random(K)
            rec.log_contours("video/particles", curves, w)
            pts = rng.random((4, 2)) * [W, H]
            rec.log_points("video/features", pts, colors=weight_colors(rng.random(4)), radii=1.5)
            starts, ends = est[:5], est[:5] + 3.0
            rec.log_segments("video/normals", starts, ends)
            rec.log_scalar("series/ess", 10.0 * (i + 1), names="ESS", colors=[(0, 128, 255)])
            counts = rng.integers(0, 20, size=len(EDGES) - 1)
            rec.log_histogram("histogram/tx", counts, EDGES)
            rec.log_text("log", f"frame {i}", level="debug")
            for key, value in [("estimate", est), ("particles", curves), ("weights", w),
                               ("points", pts), ("starts", starts), ("ends", ends),
                               ("hist", counts), ("frames", img), ("ess", 10.0 * (i + 1))]:
                logged[key].append(value)
        rec.send_series("series/translation", frames, times, translation, names=["tx", "ty"],
                        colors=[(255, 0, 0), (0, 160, 0)])
        rec.send_series("series/gate", frames, times, translation[:, 0] ** 2)
        rec.log_histogram_image("histogram/tx_over_time", hist_matrix, EDGES)
    logged.update(times=times, translation=translation, hist_matrix=hist_matrix)
    return path, logged


# ---------------------------------------------------------------------------
# The full recording, read back
# ---------------------------------------------------------------------------


def test_file_is_complete_and_alone(full):
    path, _ = full
    assert sorted(p.name for p in path.parent.iterdir()) == ["run.rrd"]
    assert ru.application_id(path) == "trackcli"
    assert ru.blueprint_count(path) == 1


def test_rerun_cli_verifies_file(full):
    path, _ = full
    result = ru.verify(path)
    assert result.returncode == 0, result.stderr


def test_entities(full):
    path, _ = full
    assert ru.entity_paths(path) == {
        "video", "video/estimate", "video/particles", "video/features", "video/normals",
        "series/ess", "series/translation", "series/gate", "histogram/tx",
        "histogram/tx_over_time", "params", "log",
    }


def test_one_closed_contour_per_frame(full):
    path, logged = full
    rows = ru.read_rows(path, "video/estimate", "LineStrips2D:strips")
    assert [ix for ix, _ in rows] == list(range(N_FRAMES))
    for (_, cell), est in zip(rows, logged["estimate"], strict=True):
        assert len(cell) == 1
        strip = np.array(cell[0])
        assert strip.shape == (M + 1, 2)
        np.testing.assert_allclose(strip[:-1], est, atol=1e-4)
        np.testing.assert_array_equal(strip[-1], strip[0])
    colors = ru.read_column(path, "video/estimate", "LineStrips2D:colors")
    assert all(_rgba(c[0]) == (255, 0, 0, 255) for c in colors)
    radii = ru.read_column(path, "video/estimate", "LineStrips2D:radii")
    assert radii == [[1.0]] * N_FRAMES  # half the 2-pixel width


def test_weighted_contours_heaviest_last_and_most_opaque(full):
    path, logged = full
    strips = ru.read_column(path, "video/particles", "LineStrips2D:strips")
    colors = ru.read_column(path, "video/particles", "LineStrips2D:colors")
    assert len(strips) == N_FRAMES
    for cell, cols, curves, w in zip(strips, colors, logged["particles"], logged["weights"],
                                     strict=True):
        assert len(cell) == K
        order = np.argsort(w)
        np.testing.assert_allclose(np.array(cell[-1])[:-1], curves[order[-1]], atol=1e-4)
        alphas = [_rgba(c)[3] for c in cols]
        assert alphas == sorted(alphas)
        assert alphas[-1] == 255


def test_points_and_segments(full):
    path, logged = full
    pts = ru.read_column(path, "video/features", "Points2D:positions")
    for cell, expected in zip(pts, logged["points"], strict=True):
        np.testing.assert_allclose(np.array(cell), expected, atol=1e-4)
    assert ru.read_column(path, "video/features", "Points2D:radii") == [[1.5]] * N_FRAMES
    segs = ru.read_column(path, "video/normals", "LineStrips2D:strips")
    for cell, a, b in zip(segs, logged["starts"], logged["ends"], strict=True):
        seg = np.array(cell)
        assert seg.shape == (5, 2, 2)
        np.testing.assert_allclose(seg[:, 0], a, atol=1e-4)
        np.testing.assert_allclose(seg[:, 1], b, atol=1e-4)


def test_series_sent_as_columns(full):
    path, logged = full
    values = ru.read_column(path, "series/translation", "Scalars:scalars")
    np.testing.assert_array_equal(np.array(values), logged["translation"])
    assert ru.read_index(path, "series/translation", "Scalars:scalars") == list(range(N_FRAMES))
    ns = ru.read_index(path, "series/translation", "Scalars:scalars", timeline="video_time")
    np.testing.assert_allclose(np.array(ns) * 1e-9, logged["times"], atol=1e-9)
    assert ru.read_column(path, "series/translation", "SeriesLines:names") == [["tx", "ty"]]
    assert ru.is_static(path, "series/translation", "SeriesLines:names")
    gate = ru.read_column(path, "series/gate", "Scalars:scalars")
    np.testing.assert_array_equal(np.ravel(gate), logged["translation"][:, 0] ** 2)
    assert ru.count_rows(path, "series/gate", "SeriesLines:names") == 0


def test_per_frame_scalars_styled_once(full):
    path, logged = full
    assert ru.read_column(path, "series/ess", "Scalars:scalars") == [[v] for v in logged["ess"]]
    assert ru.read_column(path, "series/ess", "SeriesLines:names") == [["ESS"]]
    assert [_rgba(c[0]) for c in ru.read_column(path, "series/ess", "SeriesLines:colors")] == [
        (0, 128, 255, 255)
    ]


def test_bar_chart_per_frame(full):
    path, logged = full
    values = ru.read_column(path, "histogram/tx", "BarChart:values")
    assert len(values) == N_FRAMES
    for cell, counts in zip(values, logged["hist"], strict=True):
        assert cell[0]["shape"] == [len(counts)]
        np.testing.assert_array_equal(cell[0]["buffer"], counts)
    abscissa = ru.read_column(path, "histogram/tx", "BarChart:abscissa")[0][0]["buffer"]
    np.testing.assert_allclose(abscissa, 0.5 * (EDGES[:-1] + EDGES[1:]))
    widths = ru.read_column(path, "histogram/tx", "BarChart:widths")[0]
    np.testing.assert_allclose(widths, np.diff(EDGES))


def test_histogram_image_static_and_placed(full):
    path, logged = full
    entity = "histogram/tx_over_time"
    assert ru.is_static(path, entity, "Image:buffer")
    fmt = ru.read_column(path, entity, "Image:format")[0][0]
    assert (fmt["width"], fmt["height"]) == (len(EDGES) - 1, N_FRAMES)
    buffer = np.array(ru.read_column(path, entity, "Image:buffer")[0][0], dtype=np.uint8)
    np.testing.assert_array_equal(buffer, histogram_image(logged["hist_matrix"]).ravel())
    assert ru.read_column(path, entity, "Transform3D:translation") == [[[EDGES[0], 0.0, 0.0]]]
    step = EDGES[1] - EDGES[0]
    np.testing.assert_allclose(ru.read_column(path, entity, "Transform3D:scale")[0][0],
                               [step, 1.0, 1.0])
    np.testing.assert_allclose(ru.read_column(path, entity, "x_edges")[0], EDGES)


def test_a_one_frame_histogram_image_keeps_its_colours(tmp_path):
    # an image one row high reads as one channel in Rerun (a warning, and a wrong image): a
    # one-frame clip's heat-map goes in as two rows of half a frame
    path = tmp_path / "one.rrd"
    matrix = np.array([[0.0, 2.0, 1.0, 4.0]])
    edges = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with Recording(path, app_id="trackcli") as rec:
            rec.log_histogram_image("h", matrix, edges, first_frame=5)
    fmt = ru.read_column(path, "h", "Image:format")[0][0]
    assert (fmt["width"], fmt["height"]) == (4, 2)
    buffer = np.array(ru.read_column(path, "h", "Image:buffer")[0][0], dtype=np.uint8).reshape(2, 4, 3)
    np.testing.assert_array_equal(buffer, np.repeat(histogram_image(matrix), 2, axis=0))
    assert ru.read_column(path, "h", "Transform3D:translation") == [[[0.0, 5.0, 0.0]]]
    np.testing.assert_allclose(ru.read_column(path, "h", "Transform3D:scale")[0][0], [1.0, 0.5, 1.0])


def test_params_values_and_yaml(full):
    path, logged = full
    assert ru.read_column(path, "params", "seed") == [[7]]
    assert ru.read_column(path, "params", "dynamics.beta") == [[0.5]]
    assert ru.read_column(path, "params", "shape") == [[3, 4]]
    assert ru.count_rows(path, "params", "note") == 0
    text = ru.read_column(path, "params", "TextDocument:text")[0][0]
    assert text.startswith("```yaml\n") and text.endswith("```")
    assert yaml.safe_load(text.removeprefix("```yaml\n").removesuffix("```")) == logged["params"]


def test_jpeg_frames_decode_to_the_input(full):
    path, logged = full
    blobs = ru.read_column(path, "video", "EncodedImage:blob")
    media = ru.read_column(path, "video", "EncodedImage:media_type")
    assert len(blobs) == N_FRAMES and media[0] == ["image/jpeg"]
    for cell, original in zip(blobs, logged["frames"], strict=True):
        decoded = cv2.imdecode(np.array(cell[0], dtype=np.uint8), cv2.IMREAD_COLOR)
        assert decoded.shape == original.shape
        assert np.mean(np.abs(decoded.astype(float) - original)) < 3.0


def test_text_log(full):
    path, _ = full
    assert ru.read_column(path, "log", "TextLog:level") == [["DEBUG"]] * N_FRAMES
    assert ru.read_column(path, "log", "TextLog:text")[-1] == [f"frame {N_FRAMES - 1}"]


# ---------------------------------------------------------------------------
# Video assets
# ---------------------------------------------------------------------------


def test_vp9_mp4_is_embedded_as_asset(tmp_path):
    clip = tmp_path / "clip.mp4"
    if not _write_vp9(clip):
        pytest.skip("this OpenCV build cannot write VP9")
    out = tmp_path / "asset.rrd"
    with Recording(out, blueprint="draw") as rec:
        log_video = rec.frame_logger(clip)
        assert log_video.kind == "asset"
        for i in range(N_FRAMES):
            rec.set_frame(i, i / FPS)
            log_video(i, None)
    expected_ns = [round(i * 1e9 / FPS) for i in range(N_FRAMES)]
    assert log_video.timestamps_ns.tolist() == expected_ns
    assert ru.read_column(out, "video", "VideoFrameReference:timestamp") == [
        [ts] for ts in expected_ns
    ]
    assert ru.is_static(out, "video", "AssetVideo:blob")
    blob = ru.read_column(out, "video", "AssetVideo:blob")[0][0]
    assert bytes(blob) == clip.read_bytes()
    assert ru.count_rows(out, "video", "EncodedImage:blob") == 0
    assert ru.verify(out).returncode == 0


def test_frames_past_the_asset_fall_back_to_jpeg(tmp_path):
    clip = tmp_path / "short.mp4"
    if not _write_vp9(clip, n=2):
        pytest.skip("this OpenCV build cannot write VP9")
    out = tmp_path / "mixed.rrd"
    with Recording(out) as rec:
        log_video = rec.frame_logger(clip)
        for i in range(3):
            rec.set_frame(i, i / FPS)
            log_video(i, _synthetic_frame(i))
        with pytest.raises(DataError, match="outside the video asset"):
            log_video(5)
    assert ru.read_index(out, "video", "VideoFrameReference:timestamp") == [0, 1]
    assert ru.read_index(out, "video", "EncodedImage:blob") == [2]


@pytest.mark.parametrize(("name", "fourcc"), [("clip.mp4", "mp4v"), ("clip.avi", "MJPG")])
def test_unsupported_videos_fall_back_to_jpeg(tmp_path, name, fourcc):
    clip = tmp_path / name
    writer = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*fourcc), FPS, (W, H))
    for i in range(2):
        writer.write(_synthetic_frame(i))
    writer.release()
    out = tmp_path / "fallback.rrd"
    with Recording(out) as rec:
        log_video = rec.frame_logger(clip)
        assert log_video.kind == "jpeg" and log_video.timestamps_ns is None
        rec.set_frame(0, 0.0)
        log_video(0, _synthetic_frame(0))
        with pytest.raises(DataError, match="needs the image"):
            log_video(1)
    assert ru.count_rows(out, "video", "AssetVideo:blob") == 0
    assert ru.count_rows(out, "video", "EncodedImage:blob") == 1


# ---------------------------------------------------------------------------
# Atomic output
# ---------------------------------------------------------------------------


def test_held_rows_are_sent_by_size_or_count_and_all_arrive(tmp_path):
    """``flush_overlays(min_bytes, max_rows)`` sends an entity's rows once they hold that much
    data or that many rows, keeps the others, and the recording ends with every row."""
    out = tmp_path / "held.rrd"
    n = 12
    with Recording(out) as rec:
        rec.batch_overlays()
        for i in range(n):
            rec.set_frame(i, i / FPS)
            rec.log_frame(_synthetic_frame(i))  # a JPEG of ~1 kB a frame
            rec.log_points("video/centroid", np.array([[float(i), 1.0]]))  # 8 bytes a frame
            if i % 2 == 1:
                rec.flush_overlays(min_bytes=1000, max_rows=8)
                held = {key[0]: len(rows) for key, rows in rec._batch.items()}
                assert "video" not in held  # two frames of images are over 1000 bytes
                # the centroid's rows wait until there are 8 of them
                assert held.get("video/centroid", 0) == (i + 1) % 8
    assert len(ru.read_column(out, "video", "EncodedImage:blob")) == n
    assert ru.read_column(out, "video/centroid", "Points2D:positions") == [[[float(i), 1.0]] for i in range(n)]


def test_exception_leaves_no_file(tmp_path):
    out = tmp_path / "sub" / "broken.rrd"
    with pytest.raises(RuntimeError, match="tracker blew up"):
        with Recording(out, blueprint="track") as rec:
            for i in range(3):
                rec.set_frame(i, i / FPS)
                rec.log_frame(_synthetic_frame(i))
            assert rec.tmp_path.exists()
            raise RuntimeError("tracker blew up")
    assert list(out.parent.iterdir()) == []


def test_failed_run_keeps_previous_file_and_success_replaces_it(tmp_path):
    out = tmp_path / "run.rrd"
    with Recording(out, recording_id="first") as rec:
        rec.set_frame(0, 0.0)
        rec.log_scalar("series/a", 1.0)
    first = out.read_bytes()
    with pytest.raises(DataError):
        with Recording(out, recording_id="second") as rec:
            rec.set_frame(0, 0.0)
            rec.log_contour("video/bad", np.zeros((4, 3)))
    assert out.read_bytes() == first
    with Recording(out, recording_id="third") as rec:
        rec.set_frame(0, 0.0)
        rec.log_scalar("series/a", 2.0)
    assert ru.read_column(out, "series/a", "Scalars:scalars") == [[2.0]]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.rrd"]


def test_use_outside_with_block_is_an_error(tmp_path):
    rec = Recording(tmp_path / "x.rrd")
    with pytest.raises(TrackcliError, match="not open"):
        rec.set_frame(0, 0.0)
    assert list(tmp_path.iterdir()) == []


def test_import_does_not_load_rerun_or_cv2():
    code = "import sys, trackcli.io.recording; print('rerun' in sys.modules, 'cv2' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


# ---------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------


def test_blueprints():
    import rerun.blueprint as rrb

    for name in BLUEPRINTS:
        assert isinstance(make_blueprint(name), rrb.Blueprint)
    assert make_blueprint(None) is None
    with pytest.raises(ConfigError, match="'tracking'.*track, draw, simulate"):
        make_blueprint("tracking")
    with pytest.raises(ConfigError):
        Recording("x.rrd", blueprint="tracking")


@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        (lambda r: r.log_contour("c", np.zeros((5, 3))), DataError, r"\(\.\.\., 2\)"),
        (lambda r: r.log_contour("c", np.zeros((5, 2)), color=(300, 0, 0)), DataError, "0..255"),
        (lambda r: r.log_contour("c", np.zeros((5, 2)), width=0.0), DataError, "positive"),
        (lambda r: r.log_contours("c", np.zeros((3, 5, 2)), np.ones(4)), DataError, r"\(3,\)"),
        (lambda r: r.log_contours("c", np.zeros((3, 5, 2)), -np.ones(3)), DataError,
         "non-negative"),
        (lambda r: r.log_points("p", np.zeros((3, 2)), colors=np.zeros((2, 3))), DataError,
         r"\(3, 3 or 4\)"),
        (lambda r: r.log_segments("s", np.zeros((3, 2)), np.zeros((4, 2))), DataError,
         "same shape"),
        (lambda r: r.log_frame(np.zeros((4, 4, 3))), DataError, "uint8"),
        (lambda r: r.log_frame(np.zeros((4, 4, 3), np.uint8), quality=0), ConfigError, "1..100"),
        (lambda r: r.send_series("s", np.arange(3), np.arange(4.0), np.zeros(3)), DataError,
         r"times must have shape \(3,\)"),
        (lambda r: r.send_series("s", np.arange(3.0), np.arange(3.0), np.zeros(3)), DataError,
         "integers"),
        (lambda r: r.send_series("s", np.arange(3), np.arange(3.0), np.zeros((3, 2)),
                                 names=["a"]), DataError, "1 names given for 2 lines"),
        (lambda r: r.log_histogram("h", np.ones(3), np.arange(3.0)), DataError, r"\(4,\)"),
        (lambda r: r.log_histogram_image("h", np.ones((2, 3)), [0.0, 1.0, 3.0, 4.0]), DataError,
         "equally spaced"),
        (lambda r: r.log_text("l", "hi", level="LOUD"), ConfigError, "CRITICAL, ERROR"),
        (lambda r: r.set_frame(-1, 0.0), DataError, "non-negative"),
    ],
)
def test_bad_values_raise_clear_errors(tmp_path, call, error, match):
    with Recording(tmp_path / "v.rrd") as rec:
        with pytest.raises(error, match=match):
            call(rec)


# ---------------------------------------------------------------------------
# Pure helpers
# ---------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(np.float64, st.integers(1, 30),
                  elements=st.floats(0.0, 1e6, allow_nan=False, allow_infinity=False)))
def test_weight_colors_monotone_in_weight(w):
    colors = weight_colors(w)
    assert colors.shape == (len(w), 4) and colors.dtype == np.uint8
    order = np.argsort(w, kind="stable")
    for channel in (0, 3):  # red and alpha rise with weight
        assert np.all(np.diff(colors[order, channel].astype(int)) >= 0)
    if w.max() > 0:
        assert colors[np.argmax(w), 3] == 255
    np.testing.assert_array_equal(weight_colors(3.0 * w), colors)  # only ratios matter


def test_histogram_image_rows_scaled_to_their_maximum():
    rng = np.random.default_rng(3)
    m = rng.random((6, 10))
    m[2] *= 1000.0  # totals differ wildly between frames
    m[4] = 0.0
    img = histogram_image(m)
    assert img.shape == (6, 10, 3) and img.dtype == np.uint8
    top = histogram_image(np.array([[1.0]]))[0, 0]
    bottom = histogram_image(np.array([[0.0, 1.0]]))[0, 0]
    for t in (0, 1, 2, 3, 5):
        np.testing.assert_array_equal(img[t, np.argmax(m[t])], top)
    assert np.all(img[4] == bottom)
    # brightness (luma) increases with the value within a row
    luma = img.astype(float) @ [0.299, 0.587, 0.114]
    for t in (0, 1, 2):
        order = np.argsort(m[t])
        assert np.all(np.diff(luma[t, order]) >= -1.0)


def test_unwritable_output_is_a_clear_error(tmp_path):
    (tmp_path / ".blocked.rrd.part").mkdir()  # the temporary file cannot be created
    with pytest.raises(TrackcliError, match="cannot write recording"):
        with Recording(tmp_path / "blocked.rrd"):
            pass
    assert not (tmp_path / "blocked.rrd").exists()


def test_histogram_rows_kept_compactly_give_the_same_heat_map():
    """``track`` keeps each frame's histogram as its heat-map row (uint8); the image is the same."""
    from trackcli.io.recording import histogram_grey

    rng = np.random.default_rng(3)
    m = rng.random((40, 64)) * rng.choice([0.0, 1e-6, 1.0, 1e6], size=(40, 1))
    rows = np.vstack([histogram_grey(r[None])[0] for r in m])
    assert rows.dtype == np.uint8
    np.testing.assert_array_equal(histogram_image(rows), histogram_image(m))


@pytest.mark.parametrize("preset, expected", [(None, "0"), ("250", "250")])
def test_rerun_s_allocator_returns_freed_memory_at_once_unless_told_otherwise(preset, expected):
    """Importing the recording module sets mimalloc's purge delay to 0 (read when Rerun loads),
    so that a long recorded run does not keep freed pages; a value in the environment wins."""
    env = {k: v for k, v in os.environ.items() if k != "MIMALLOC_PURGE_DELAY"}
    if preset is not None:
        env["MIMALLOC_PURGE_DELAY"] = preset
    code = "import os, trackcli.io.recording; print(os.environ['MIMALLOC_PURGE_DELAY'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == expected


@pytest.mark.parametrize("check", ["0", None])
def test_pandas_is_imported_by_a_recording_only_where_the_check_is_kept(tmp_path, check):
    """With TRACKCLI_PANDAS_CHECK=0 (what the ``trackcli`` command sets) a recording is
    written without pyarrow importing pandas, and pandas still imports afterwards; unset
    (a library user), pyarrow's own check runs and imports pandas."""
    if importlib.util.find_spec("pandas") is None:
        pytest.skip("pandas is not installed, so pyarrow cannot import it either way")
    env = {k: v for k, v in os.environ.items() if k != "TRACKCLI_PANDAS_CHECK"}
    if check is not None:
        env["TRACKCLI_PANDAS_CHECK"] = check
    code = (
        "import sys, numpy as np\n"
        "from trackcli.io.recording import Recording\n"
        f"with Recording({str(tmp_path / 'r.rrd')!r}, properties={{'seed': '1'}}) as rec:\n"
        "    rec.set_frame(0, 0.0)\n"
        "    rec.log_contour('video/estimate', np.zeros((5, 2)))\n"
        "    rec.log_scalar('series/x', 1.0)\n"
        "print('pandas' in sys.modules)\n"
        "import pandas, pyarrow\n"
        "print(pyarrow.array(pandas.Series([1.0, 2.0])).to_pylist())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    imported, values = out.stdout.split("\n")[:2]
    assert imported == ("False" if check == "0" else "True")
    assert values == "[1.0, 2.0]"
    assert (tmp_path / "r.rrd").stat().st_size > 0


# ---------------------------------------------------------------------------
# Frames kept as their source's JPEG
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("frames_mode", ["auto", "jpeg"])
def test_track_keeps_the_source_jpeg_frames_unless_asked_to_encode(tmp_path, ellipse_clip, frames_mode,
                                                                    monkeypatch):
    """Under ``output.frames: auto`` without an AV1 encoder, the recording of an MJPG clip holds
    each frame's stored JPEG byte for byte (no encoding again); ``jpeg`` encodes every frame at
    ``jpeg_quality``."""
    from click.testing import CliRunner

    from trackcli.cli import cli
    from trackcli.io import encode
    from trackcli.io.video import open_video

    monkeypatch.setattr(encode, "encoder_available", lambda name: False)

    template, out = tmp_path / "t.yaml", tmp_path / "out"
    config = tmp_path / "c.yaml"
    config.write_text(f"output:\n  frames: {frames_mode}\n  jpeg_quality: 30\n")
    for args in (["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", template],
                 ["track", ellipse_clip, "--template", template, "-c", config, "-o", out]):
        result = CliRunner().invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    stored = [f.encoded for f in open_video(ellipse_clip).frames(encoded=True)]
    assert all(s is not None for s in stored)
    blobs = [bytes(cell[0]) for cell in ru.read_column(out / "ellipse.condensation.rrd", "video", "EncodedImage:blob")]
    assert len(blobs) == len(stored)
    if frames_mode == "auto":
        assert blobs == stored
    else:
        assert all(b != s and len(b) < len(s) for b, s in zip(blobs, stored, strict=True))
