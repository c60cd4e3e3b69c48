"""trackcli render: the outline from the track CSV drawn on video files and image folders."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from conftest import CLIP_FRAMES, CLIP_SIZE
from trackcli.cli import cli
from trackcli.run.render import ESTIMATE_BGR, SUFFIX_CODECS, VIDEO_SUFFIXES, default_output, render, sheet_indices
from trackcli.io.tracks import read_outlines


def run(args, code: int):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert "Traceback" not in result.output
    return result


@pytest.fixture
def tracked(tmp_path, ellipse_clip):
    tmpl = tmp_path / "ellipse.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "--no-rrd", "-o", tmp_path / "out"], 0)
    return tmp_path / "out" / "ellipse.kalman.csv"


def clip_frames(path):
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(img)
    cap.release()
    return frames


def outline_pixels_are_drawn(img, original, outline):
    """Most outline points are painted the estimate colour; far from it the frame is untouched."""
    h, w = img.shape[:2]
    pts = np.rint(outline).astype(int)
    inside = (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)
    pts = pts[inside]
    colours = img[pts[:, 1], pts[:, 0]].astype(int)
    near = np.abs(colours - np.array(ESTIMATE_BGR)).max(axis=1) < 60
    mask = np.zeros((h, w), np.uint8)
    cv2.polylines(mask, [np.rint(outline).astype(np.int32)], True, 1, 12)
    cv2.circle(mask, tuple(np.rint(outline.mean(axis=0)).astype(int)), 8, 1, -1)
    far = mask == 0
    far[:30, :] = False  # the label
    return near.mean() > 0.8 and np.array_equal(img[far], original[far])


def test_png_frames_show_the_csv_outline(tmp_path, tracked, ellipse_clip):
    out = tmp_path / "frames"
    result = run(["render", tracked, ellipse_clip, "--png", "-o", out], 0)
    assert f"{CLIP_FRAMES} frames, {CLIP_FRAMES} with an estimate" in result.stdout
    files = sorted(out.glob("*.png"))
    assert [f.name for f in files] == [f"frame_{k:06d}.png" for k in range(CLIP_FRAMES)]
    _, outlines, _ = read_outlines(tracked)
    for k, (f, original) in enumerate(zip(files, clip_frames(ellipse_clip))):
        assert outline_pixels_are_drawn(cv2.imread(str(f)), original, outlines[k]), f.name
    # re-rendering into the same folder replaces it; a folder with other files is refused
    run(["render", tracked, ellipse_clip, "--png", "-o", out, "--end", "2"], 0)
    assert len(list(out.glob("*.png"))) == 2
    (out / "notes.txt").write_text("mine")
    err = run(["render", tracked, ellipse_clip, "--png", "-o", out], 4)
    assert err.stderr.startswith("Error: ") and "other files" in err.stderr


def test_image_folder_and_video_file_give_the_same_pictures(tmp_path, tracked, ellipse_clip):
    folder = tmp_path / "clipdir"
    folder.mkdir()
    for k, img in enumerate(clip_frames(ellipse_clip)):
        cv2.imwrite(str(folder / f"{k + 1}.png"), img)
    run(["render", tracked, folder, "--png", "-o", tmp_path / "a", "--fps", "25"], 0)
    run(["render", tracked, ellipse_clip, "--png", "-o", tmp_path / "b"], 0)
    for k in range(CLIP_FRAMES):
        a = cv2.imread(str(tmp_path / "a" / f"frame_{k:06d}.png"))
        b = cv2.imread(str(tmp_path / "b" / f"frame_{k:06d}.png"))
        assert np.array_equal(a, b)


def test_video_has_one_frame_per_selected_frame_and_default_name(tmp_path, tracked, ellipse_clip):
    result = run(["render", tracked, ellipse_clip, "--start", "1", "--end", "5", "--step", "2"], 0)
    out = default_output(tracked, "video")
    assert out == tracked.with_name("ellipse.kalman.mp4") and out.is_file()
    assert str(out) in result.stdout
    frames = clip_frames(out)
    assert len(frames) == 2 and frames[0].shape == (CLIP_SIZE[1], CLIP_SIZE[0], 3)
    assert not list(out.parent.glob(".*part*"))


@pytest.mark.parametrize("suffix", VIDEO_SUFFIXES)
def test_every_video_ending_offered_is_written_and_reads_back(tmp_path, tracked, ellipse_clip, suffix):
    """The endings render accepts each get a codec this OpenCV writes in that container."""
    out = tmp_path / f"overlay{suffix}"
    result = run(["render", tracked, ellipse_clip, "--end", "2", "-o", out], 0)
    codec = "h264" if suffix == ".mp4" else SUFFIX_CODECS[suffix][0]  # an MP4 is H.264 through PyAV
    assert f"video ({codec})" in result.stdout
    frames = clip_frames(out)
    assert len(frames) == 2 and frames[0].shape == (CLIP_SIZE[1], CLIP_SIZE[0], 3)  # --end is exclusive


def test_mp4_is_h264_that_plays_everywhere(tmp_path, tracked, ellipse_clip):
    """H.264 High profile, 4:2:0, the index before the data (a browser plays it while it loads),
    the frames as drawn; an odd frame size is padded to even sides."""
    av = pytest.importorskip("av")
    out = tmp_path / "overlay.mp4"
    run(["render", tracked, ellipse_clip, "-o", out, "--no-label"], 0)
    with av.open(str(out)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264"
        assert stream.codec_context.pix_fmt == "yuv420p"
        assert stream.codec_context.profile == "High"
        assert (stream.codec_context.width, stream.codec_context.height) == CLIP_SIZE
        assert stream.frames == CLIP_FRAMES
    data = out.read_bytes()
    assert data.index(b"moov") < data.index(b"mdat")
    drawn = sorted((tmp_path / "png").glob("*.png")) if run(
        ["render", tracked, ellipse_clip, "--png", "--no-label", "-o", tmp_path / "png"], 0) else []
    for frame, png in zip(clip_frames(out), drawn, strict=True):
        assert cv2.PSNR(frame, cv2.imread(str(png))) > 28
    from trackcli.io.encode import H264Writer

    odd = tmp_path / "odd.mp4"
    writer = H264Writer(odd, 25.0, (101, 77))
    for k in range(3):
        writer.write(np.full((77, 101, 3), 40 * k, np.uint8))
    writer.close(True)
    with av.open(str(odd)) as container:
        assert (container.streams.video[0].width, container.streams.video[0].height) == (102, 78)


def test_mp4_without_pyav_falls_back_to_opencv(tmp_path, tracked, ellipse_clip, monkeypatch, caplog):
    from trackcli.io import encode

    monkeypatch.setattr(encode, "encoder_available", lambda name: False)
    with caplog.at_level(logging.WARNING, logger="trackcli"):  # another test's -q may have raised its level
        result = run(["render", tracked, ellipse_clip, "--end", "2", "-o", tmp_path / "o.mp4"], 0)
    assert "video (vp09)" in result.stdout or "video (mp4v)" in result.stdout
    assert "libx264" in caplog.text and len(clip_frames(tmp_path / "o.mp4")) == 2


def test_contact_sheet(tmp_path, tracked, ellipse_clip):
    out = tmp_path / "sheet.png"
    run(["render", tracked, ellipse_clip, "--sheet", "4", "--tile-width", "80", "-o", out], 0)
    sheet = cv2.imread(str(out))
    # 4 tiles of 80x60, with 4 px gaps: 3 columns x 2 rows (the grid is a little wider than tall)
    assert sheet.shape == (2 * 60 + 3 * 4, 3 * 80 + 4 * 4, 3)
    assert sheet_indices(range(0, 6), 4) == [0, 2, 3, 5]
    assert sheet_indices(range(10, 41, 3), 3) == [10, 25, 40]
    assert sheet_indices(range(3), 10) == [0, 1, 2]


def test_interrupted_render_leaves_nothing(tmp_path, tracked, ellipse_clip):
    before = sorted(p.name for p in tmp_path.iterdir())
    for kind, out in (("video", tmp_path / "v.mp4"), ("frames", tmp_path / "f"), ("sheet", tmp_path / "s.png")):
        calls = []

        def progress(n):
            calls.append(n)
            if len(calls) == 3:
                raise KeyboardInterrupt

        with pytest.raises(KeyboardInterrupt):
            render(tracked, ellipse_clip, out, kind=kind, progress=progress)
        assert len(calls) == 3
        assert sorted(p.name for p in tmp_path.iterdir()) == before, kind


def test_render_errors_are_one_line(tmp_path, tracked, ellipse_clip):
    bare = tmp_path / "bare.csv"
    bare.write_text("frame,cx,cy\n0,1,2\n")
    err = run(["render", bare, ellipse_clip], 4)
    assert err.stderr.startswith("Error: ") and "no outline columns" in err.stderr
    assert len(err.stderr.splitlines()) == 1
    run(["render", tracked, ellipse_clip, "--sheet", "3", "--png"], 2)
    err = run(["render", tracked, tmp_path / "missing.mp4"], 4)
    assert "missing.mp4" in err.stderr
    err = run(["render", ellipse_clip, ellipse_clip], 4)  # the clip given as the track
    assert err.stderr.strip() == f"Error: {ellipse_clip}: not a text file (a track is the CSV written by 'trackcli track')"
    one = run(["render", tracked, ellipse_clip, "--start", "5", "--end", "6", "-o", tmp_path / "one.mp4"], 0)
    assert "of 1 frames, 1 with an estimate" in one.stdout
    late = tracked.with_name("late.csv")
    lines = tracked.read_text().splitlines()
    late.write_text("\n".join(lines[:3]) + "\n")  # frames 0 and 1 only
    err = run(["render", late, ellipse_clip, "--start", "3"], 5)
    assert "no estimate in the selected frames 3-5" in err.stderr
