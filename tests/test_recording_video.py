"""Frames in recordings as AV1 video (a Rerun ``VideoStream``), and the fallbacks to JPEG.

The samples are read back from the file and decoded with PyAV's AV1 decoder (dav1d): each
frame's sample must sit at that frame's time and decode to that frame, so that the overlays
logged at a frame's time are drawn over the right picture.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

import rrd_utils as ru
from trackcli.cli import cli
from trackcli.io import encode
from trackcli.io.recording import Recording

av = pytest.importorskip("av")
if not encode.encoder_available(encode.AV1_ENCODER):
    pytest.skip("PyAV has no AV1 encoder here", allow_module_level=True)

FPS = 25.0


def _frame(i: int, size=(854, 480)) -> np.ndarray:
    """A textured frame with a bright square that moves 7 px a frame (each frame told apart)."""
    w, h = size
    rng = np.random.default_rng(5)
    texture = cv2.GaussianBlur(rng.integers(0, 255, (h, w, 3), dtype=np.uint8), (0, 0), 3)
    img = np.roll(texture, 3 * i, axis=1)
    cv2.rectangle(img, (20 + 7 * i, 40), (60 + 7 * i, 80), (255, 255, 255), -1)
    return img


def _decode(samples: list[bytes]) -> list[np.ndarray]:
    dec = av.CodecContext.create("libdav1d", "r")
    out = []
    for data in [*samples, None]:
        for f in dec.decode(av.Packet(data) if data is not None else None):
            out.append(f.to_ndarray(format="bgr24"))
    return out


def _record(path, frames, **kw):
    with Recording(path, blueprint="track") as rec:
        rec.batch_overlays()
        log_video = rec.frame_logger(None, av1=True, **kw)
        for i, img in enumerate(frames):
            rec.set_frame(i, i / FPS)
            log_video(i, img)
            rec.log_points("video/centroid", np.array([[40.0 + 7 * i, 60.0]]))
    return log_video


def test_frames_are_av1_samples_at_their_own_times(tmp_path):
    frames = [_frame(i) for i in range(30)]
    out = tmp_path / "av1.rrd"
    logger = _record(out, frames)
    assert logger.kind == "av1" and logger.samples == 30
    assert ru.verify(out).returncode == 0
    assert ru.is_static(out, "video", "VideoStream:codec")
    assert ru.read_column(out, "video", "VideoStream:codec") == [[int(0x61763031)]]  # 'av01'
    rows = ru.read_rows(out, "video", "VideoStream:sample")
    assert [ix for ix, _ in rows] == list(range(30))
    times = ru.read_index(out, "video", "VideoStream:sample", timeline="video_time")
    assert times == [round(i / FPS * 1e9) for i in range(30)]
    keys = ru.read_column(out, "video", "VideoStream:is_keyframe")
    assert keys[0] == [True]
    decoded = _decode([bytes(cell[0]) for _, cell in rows])
    assert len(decoded) == 30
    for i, img in enumerate(decoded):
        # the picture decoded at frame i is frame i (the square has moved 7 px a frame)
        errors = [np.mean(np.abs(img.astype(float) - f)) for f in frames]
        assert int(np.argmin(errors)) == i
        assert cv2.PSNR(img, frames[i]) > 28
    # the overlay of frame i is at frame i too
    assert ru.read_index(out, "video/centroid", "Points2D:positions") == list(range(30))


def test_av1_frames_stay_within_the_budget_at_854x480(tmp_path):
    frames = [_frame(i) for i in range(40)]
    logger = _record(tmp_path / "size.rrd", frames)
    assert logger.sample_bytes / logger.samples <= 12 * 1024
    jpeg = np.mean([len(cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, 80])[1]) for f in frames])
    assert logger.sample_bytes / logger.samples < jpeg / 3


def test_odd_sizes_are_padded_and_decode_at_their_own_size(tmp_path):
    frames = [_frame(i, (161, 121)) for i in range(5)]
    out = tmp_path / "odd.rrd"
    logger = _record(out, frames)
    assert logger.kind == "av1"
    decoded = _decode([bytes(c[0]) for c in ru.read_column(out, "video", "VideoStream:sample")])
    assert decoded[0].shape[:2] in ((121, 161), (122, 162))
    assert cv2.PSNR(decoded[2][:121, :161], frames[2]) > 25


def test_frames_too_small_for_the_encoder_go_in_as_jpeg(tmp_path):
    out = tmp_path / "small.rrd"
    logger = _record(out, [_frame(i, (60, 40)) for i in range(3)])
    assert logger.kind == "jpeg"
    assert ru.count_rows(out, "video", "VideoStream:sample") == 0
    assert ru.read_index(out, "video", "EncodedImage:blob") == [0, 1, 2]


def test_without_the_encoder_the_run_records_jpeg(tmp_path, ellipse_clip, monkeypatch):
    """``output.frames: auto`` encodes AV1 when PyAV has the encoder, and falls back to JPEG
    (here the MJPG clip's own JPEG frames) when it has not."""
    template = tmp_path / "t.yaml"
    runner = CliRunner()
    res = runner.invoke(cli, ["draw", str(ellipse_clip), "--ellipse", "70,60,28,36", "-o", str(template)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["track", str(ellipse_clip), "--template", str(template), "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    rrd = tmp_path / "a" / "ellipse.condensation.rrd"
    n = ru.count_rows(rrd, "video/estimate", "LineStrips2D:strips")
    assert ru.read_index(rrd, "video", "VideoStream:sample") == list(range(n))
    assert ru.count_rows(rrd, "video", "EncodedImage:blob") == 0
    monkeypatch.setattr(encode, "encoder_available", lambda name: False)
    res = runner.invoke(cli, ["track", str(ellipse_clip), "--template", str(template), "-o", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    rrd = tmp_path / "b" / "ellipse.condensation.rrd"
    assert ru.count_rows(rrd, "video", "VideoStream:sample") == 0
    assert ru.read_index(rrd, "video", "EncodedImage:blob") == list(range(n))


def test_pixel_traced_outlines_keep_only_their_corners(tmp_path):
    """A contour traced along pixels (straight runs of unit steps) is stored by its corners:
    the same line, half the points or fewer."""
    square = np.array([[x, 10] for x in range(10, 30)] + [[30, y] for y in range(10, 30)]
                      + [[x, 30] for x in range(30, 10, -1)] + [[10, y] for y in range(30, 10, -1)], float)
    out = tmp_path / "c.rrd"
    with Recording(out) as rec:
        rec.set_frame(0, 0.0)
        rec.log_contour("video/outline", square)
        rec.log_contour("video/open", square[:25], closed=False)
    strip = np.array(ru.read_column(out, "video/outline", "LineStrips2D:strips")[0][0])
    np.testing.assert_array_equal(strip, [[10, 10], [30, 10], [30, 30], [10, 30], [10, 10]])
    strip = np.array(ru.read_column(out, "video/open", "LineStrips2D:strips")[0][0])
    np.testing.assert_array_equal(strip, [[10, 10], [30, 10], [30, 14]])


def _write_blob_clip(folder, n: int, size=(854, 480)) -> None:
    """``n`` JPEG frames: a dark blob with a wavy rim gliding over a textured background."""
    w, h = size
    rng = np.random.default_rng(11)
    texture = cv2.GaussianBlur(rng.integers(60, 200, (h, w, 3), dtype=np.uint8), (0, 0), 2)
    folder.mkdir()
    angles = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    for i in range(n):
        img = np.roll(texture, 2 * i, axis=1).copy()
        radius = 90 + 8 * np.sin(7 * angles + 0.2 * i)
        rim = np.column_stack([300 + 4 * i + 1.3 * radius * np.cos(angles), 240 + radius * np.sin(angles)])
        cv2.fillPoly(img, [np.round(rim).astype(np.int32)], (40, 30, 30))
        cv2.imwrite(str(folder / f"{i:05d}.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 90])


def test_a_tracked_854x480_clip_records_at_most_12_kb_a_frame(tmp_path):
    """The whole recording of a default run (frames, particles, estimate, refined outline,
    series, layout) stays within 12 KB a frame at 854x480 (it took about 30 before)."""
    n = 40
    clip = tmp_path / "blob"
    _write_blob_clip(clip, n)
    template = tmp_path / "t.yaml"
    runner = CliRunner()
    res = runner.invoke(cli, ["draw", str(clip), "--ellipse", "300,240,117,90", "-o", str(template)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["track", str(clip), "--template", str(template), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    rrd = tmp_path / "out" / "blob.condensation.rrd"
    # what a user sees is all there: the frames, the particles, the estimate and the outline
    for entity, component in (("video", "VideoStream:sample"), ("video/particles", "LineStrips2D:strips"),
                              ("video/estimate", "LineStrips2D:strips"), ("video/outline", "LineStrips2D:strips")):
        assert ru.read_index(rrd, entity, component) == list(range(n)), entity
    assert ru.count_rows(rrd, "series/translation", "Scalars:scalars") == n
    assert rrd.stat().st_size / n <= 12_000


def test_a_dense_curve_is_stored_within_its_tolerance(tmp_path):
    """``log_contour(..., tolerance=t)`` keeps few of a dense circle's points, each a given
    point, and the line stays within ``t`` pixels of every point given."""
    a = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    circle = np.column_stack([200 + 80 * np.cos(a), 150 + 80 * np.sin(a)])
    out = tmp_path / "c.rrd"
    with Recording(out) as rec:
        rec.set_frame(0, 0.0)
        rec.log_contour("video/estimate", circle, tolerance=0.75)
        rec.log_contour("video/exact", circle)
    strip = np.array(ru.read_column(out, "video/estimate", "LineStrips2D:strips")[0][0])
    assert len(strip) < 400 / 5
    np.testing.assert_array_equal(strip[-1], strip[0])
    kept = {tuple(p) for p in np.float32(circle).tolist()}
    assert all(tuple(p) in kept for p in strip.tolist())
    # the chords' farthest point from the circle: their midpoints, 80 - |midpoint - centre|
    mid = 0.5 * (strip[1:] + strip[:-1])
    assert np.max(80 - np.hypot(mid[:, 0] - 200, mid[:, 1] - 150)) <= 0.75
    assert len(ru.read_column(out, "video/exact", "LineStrips2D:strips")[0][0]) == 401
