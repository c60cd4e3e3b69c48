"""Tests for trackcli.io.video: files, image folders, frame selection, random access, errors.

Clips are generated in temporary folders.  Every frame is a flat grey level that encodes
its index (``10 + 4 * index``), so the index of a decoded frame can be read back from its
mean even after JPEG compression.
"""

from __future__ import annotations

import gc
import logging
import weakref
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackcli.errors import ConfigError, VideoError
from trackcli.io.video import DEFAULT_FPS, Frame, Video, open_video

W, H = 64, 48
N = 30


def frame_image(i: int, size: tuple[int, int] = (W, H)) -> np.ndarray:
    return np.full((size[1], size[0], 3), 10 + 4 * i, np.uint8)


def frame_id(image: np.ndarray) -> int:
    return int(round((float(image.mean()) - 10) / 4))


def write_clip(path: Path, n: int = N, *, fourcc: str = "MJPG", fps: float = 25.0) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (W, H))
    if not writer.isOpened():
        pytest.skip(f"OpenCV cannot write {fourcc} here")
    for i in range(n):
        writer.write(frame_image(i))
    writer.release()
    return path


def write_folder(folder: Path, names: list[str], ids: list[int] | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for k, name in enumerate(names):
        i = k if ids is None else ids[k]
        assert cv2.imwrite(str(folder / name), frame_image(i))
    return folder


def movie_chunk_offsets(data: bytes) -> list[int]:
    """Byte offsets of the ``00dc`` frame chunks of an AVI (between ``movi`` and ``idx1``)."""
    stop = data.rfind(b"idx1")
    offsets, k = [], data.find(b"00dc", data.index(b"movi"))
    while 0 <= k < stop:
        offsets.append(k)
        k = data.find(b"00dc", k + 4)
    return offsets


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("clips")
    return {
        "file": write_clip(root / "clip.avi"),
        "folder": write_folder(root / "seq", [f"{i}.png" for i in range(N)]),
    }


# -- reading ------------------------------------------------------------------------------


def test_file_streams_every_frame_in_order(clips):
    video = open_video(clips["file"])
    assert isinstance(video, Video)
    assert (video.kind, video.fps, video.width, video.height) == ("file", 25.0, W, H)
    assert video.n_total == N and len(video) == N and video.indices == range(N)
    frames = list(video)
    assert [f.index for f in frames] == list(range(N))
    assert [frame_id(f.image) for f in frames] == list(range(N))
    assert [f.time for f in frames] == [i / 25.0 for i in range(N)]
    for f in frames:
        assert isinstance(f, Frame)
        assert f.image.shape == (H, W, 3) and f.image.dtype == np.uint8


def test_iterating_twice_gives_the_same_frames(clips):
    video = open_video(clips["file"], end=5)
    first = [f.image for f in video]
    second = [f.image for f in video]
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))


def test_fps_argument_overrides_the_file(clips):
    video = open_video(clips["file"], fps=10.0, start=3, end=6)
    assert video.fps == 10.0
    assert [f.time for f in video] == [0.3, 0.4, 0.5]


def test_folder_is_read_in_natural_order(tmp_path):
    names = ["10.png", "2.png", "1.png", "frame_9.png", "frame_10.png", "0.png"]
    # Natural order: 0, 1, 2, 10, frame_9, frame_10.
    ids = [3, 2, 1, 4, 5, 0]
    folder = write_folder(tmp_path / "seq", names, ids)
    video = open_video(folder, fps=30.0)
    assert (video.kind, video.fps, video.n_total, video.width, video.height) == (
        "folder", 30.0, 6, W, H)
    frames = list(video)
    assert [frame_id(f.image) for f in frames] == [0, 1, 2, 3, 4, 5]
    assert [f.time for f in frames] == [i / 30.0 for i in range(6)]


def test_folder_without_fps_assumes_default_and_warns(clips, caplog):
    with caplog.at_level(logging.WARNING, logger="trackcli.io.video"):
        video = open_video(clips["folder"])
    assert video.fps == DEFAULT_FPS == 25.0
    assert any("fps" in r.getMessage() and r.levelno == logging.WARNING for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="trackcli.io.video"):
        open_video(clips["folder"], fps=12.5)
    assert not caplog.records


def test_benchmark_layout_reads_the_img_subfolder(tmp_path):
    clip = tmp_path / "Crossing"
    write_folder(clip / "img", [f"{i:04d}.jpg" for i in range(1, 8)])
    (clip / "groundtruth_rect.txt").write_text("1\t2\t3\t4\n" * 7)
    video = open_video(clip, fps=30.0)
    assert video.kind == "folder" and video.path == clip and video.n_total == 7
    assert [frame_id(f.image) for f in video] == list(range(7))


def test_folder_takes_jpg_jpeg_png_in_any_case_and_ignores_other_files(tmp_path):
    folder = write_folder(tmp_path / "mixed", ["a1.JPG", "a2.jpeg", "a3.png", "a4.PNG"])
    (folder / "notes.txt").write_text("not a frame")
    (folder / "._a0.jpg").write_bytes(b"resource fork, not an image")
    (folder / "sub").mkdir()
    video = open_video(folder, fps=25.0)
    assert video.n_total == 4
    assert [frame_id(f.image) for f in video] == [0, 1, 2, 3]


def test_folder_takes_the_lossless_formats_of_older_datasets(tmp_path):
    names = ["f1.bmp", "f2.TIF", "f3.tiff", "f4.ppm", "f10.bmp"]
    video = open_video(write_folder(tmp_path / "lossless", names), fps=25.0)
    assert video.n_total == 5
    assert [frame_id(f.image) for f in video] == [0, 1, 2, 3, 4]  # natural order: f10 last


def test_grey_images_become_bgr(tmp_path):
    folder = tmp_path / "grey"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"{i}.png"), np.full((H, W), 50 * i + 7, np.uint8))
    for f in open_video(folder, fps=25.0):
        assert f.image.shape == (H, W, 3) and f.image.dtype == np.uint8
        assert np.all(f.image == 50 * f.index + 7)


# -- frame selection ----------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["file", "folder"])
@pytest.mark.parametrize(
    ("start", "end", "step", "expected"),
    [
        (0, None, 1, list(range(N))),
        (5, 12, 1, list(range(5, 12))),
        (3, None, 7, [3, 10, 17, 24]),
        (0, 10, 3, [0, 3, 6, 9]),
        (29, None, 1, [29]),
        (25, 100, 2, [25, 27, 29]),  # end beyond the clip is cut to it
    ],
)
def test_selection_keeps_original_indices_and_times(clips, kind, start, end, step, expected):
    video = open_video(clips[kind], fps=20.0, start=start, end=end, step=step)
    assert list(video.indices) == expected and len(video) == len(expected)
    frames = list(video)
    assert [f.index for f in frames] == expected
    assert [frame_id(f.image) for f in frames] == expected
    assert [f.time for f in frames] == [i / 20.0 for i in expected]


@settings(max_examples=30, deadline=None)
@given(
    kind=st.sampled_from(["file", "folder"]),
    start=st.integers(0, N - 1),
    length=st.one_of(st.none(), st.integers(1, N + 5)),
    step=st.integers(1, 9),
)
def test_selection_matches_range_semantics(clips, kind, start, length, step):
    end = None if length is None else start + length
    video = open_video(clips[kind], start=start, end=end, step=step)
    expected = list(range(N))[start:end:step]
    assert list(video.indices) == expected
    assert [(f.index, frame_id(f.image)) for f in video] == [(i, i) for i in expected]


# -- random access ------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["file", "folder"])
def test_read_returns_the_same_frame_as_streaming(clips, kind):
    streamed = {f.index: f.image for f in open_video(clips[kind])}
    with open_video(clips[kind], start=10, end=12) as video:
        for k in [17, 0, 29, 5, 6, 7, 29, 3]:  # outside the selection too, seeks both ways
            frame = video.read(k)
            assert frame.index == k and frame.time == k / video.fps
            assert np.array_equal(frame.image, streamed[k]), k


@pytest.mark.parametrize("kind", ["file", "folder"])
@pytest.mark.parametrize("bad", [-1, N, 1000])
def test_read_out_of_range_is_a_config_error(clips, kind, bad):
    video = open_video(clips[kind])
    with pytest.raises(ConfigError, match=rf"frame index {bad} is out of range .*0\.\.{N - 1}"):
        video.read(bad)


def test_closed_video_refuses_use(clips):
    with open_video(clips["file"]) as video:
        video.read(3)
    with pytest.raises(ValueError, match="closed"):
        video.read(3)
    with pytest.raises(ValueError, match="closed"):
        iter(video)


# -- memory -------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["file", "folder"])
def test_iteration_keeps_no_frames_alive(clips, kind):
    video = open_video(clips[kind])
    it = iter(video)
    first = next(it)
    ref = weakref.ref(first.image)
    del first
    next(it)
    gc.collect()
    assert ref() is None, "a streamed frame is still referenced after moving on"
    assert len(list(it)) == N - 2
    held = [v for v in vars(video).values() if isinstance(v, (list, tuple, np.ndarray))]
    assert not any(isinstance(v, np.ndarray) for v in held)
    assert not any(isinstance(x, np.ndarray) for v in held for x in v)


# -- bad input ----------------------------------------------------------------------------


def assert_one_line_naming(exc: pytest.ExceptionInfo, path: Path) -> None:
    msg = str(exc.value)
    assert "\n" not in msg and str(path) in msg, msg


def test_missing_path(tmp_path):
    path = tmp_path / "nowhere.mp4"
    with pytest.raises(VideoError, match="no such file") as exc:
        open_video(path)
    assert_one_line_naming(exc, path)
    assert isinstance(exc.value, OSError)


def test_text_file_named_mp4(tmp_path):
    path = tmp_path / "notes.mp4"
    path.write_text("this is not a video\n")
    with pytest.raises(VideoError, match="cannot open as a video") as exc:
        open_video(path)
    assert_one_line_naming(exc, path)


def test_empty_file(tmp_path):
    path = tmp_path / "empty.avi"
    path.write_bytes(b"")
    with pytest.raises(VideoError) as exc:
        open_video(path)
    assert_one_line_naming(exc, path)


def test_video_without_frames(tmp_path):
    path = write_clip(tmp_path / "none.avi", n=0)
    with pytest.raises(VideoError, match="no frame can be decoded") as exc:
        open_video(path)
    assert_one_line_naming(exc, path)


def test_empty_folder(tmp_path):
    folder = tmp_path / "empty"
    folder.mkdir()
    with pytest.raises(VideoError, match="no images") as exc:
        open_video(folder)
    assert_one_line_naming(exc, folder)


def test_folder_with_only_a_non_image(tmp_path):
    folder = tmp_path / "textonly"
    folder.mkdir()
    (folder / "readme.txt").write_text("frames go here")
    with pytest.raises(VideoError, match=r"no images .*found 1 other entry") as exc:
        open_video(folder)
    assert_one_line_naming(exc, folder)


def test_undecodable_image_mid_folder_names_the_frame(tmp_path):
    folder = write_folder(tmp_path / "seq", ["1.png", "2.png", "4.png"])
    bad = folder / "3.png"
    bad.write_text("not a png")
    video = open_video(folder, fps=25.0)
    seen = []
    with pytest.raises(VideoError, match="frame 2") as exc:
        for f in video:
            seen.append(f.index)
    assert seen == [0, 1]
    assert_one_line_naming(exc, bad)
    with pytest.raises(VideoError, match="frame 2"):
        video.read(2)


def test_first_image_undecodable_fails_at_open(tmp_path):
    folder = tmp_path / "seq"
    folder.mkdir()
    (folder / "0.jpg").write_bytes(b"\xff\xd8 truncated")
    with pytest.raises(VideoError, match="frame 0") as exc:
        open_video(folder, fps=25.0)
    assert_one_line_naming(exc, folder / "0.jpg")


def test_folder_frame_of_another_size(tmp_path):
    folder = write_folder(tmp_path / "seq", ["0.png", "1.png", "3.png"])
    odd = folder / "2.png"
    cv2.imwrite(str(odd), np.zeros((H + 2, W, 3), np.uint8))
    video = open_video(folder, fps=25.0)
    with pytest.raises(VideoError, match=rf"frame 2 is {W}x{H + 2} but the clip is {W}x{H}") as exc:
        list(video)
    assert_one_line_naming(exc, odd)


def test_truncated_file(tmp_path):
    data = write_clip(tmp_path / "whole.avi").read_bytes()
    assert len(movie_chunk_offsets(data)) == N
    path = tmp_path / "cut.avi"
    path.write_bytes(data[: movie_chunk_offsets(data)[20]])  # frames 0..19 remain
    video = open_video(path)
    assert video.n_total == N  # the header still claims every frame
    seen = []
    with pytest.raises(VideoError, match=rf"stops at frame 20 but the file reports {N}") as exc:
        for f in video:
            seen.append(f.index)
    assert seen == list(range(20))
    assert_one_line_naming(exc, path)
    # The frames before the damage stay usable.
    assert [frame_id(f.image) for f in open_video(path, end=20)] == list(range(20))


def test_missing_last_frame_counts_as_end_of_stream(tmp_path, caplog):
    data = write_clip(tmp_path / "whole.avi").read_bytes()
    path = tmp_path / "short.avi"
    path.write_bytes(data[: movie_chunk_offsets(data)[-1]])  # the last frame is gone
    video = open_video(path)
    assert video.n_total == N
    with caplog.at_level(logging.INFO, logger="trackcli.io.video"):
        frames = [f.index for f in video]
    assert frames == list(range(N - 1))
    assert any("reports" in r.getMessage() for r in caplog.records)


def test_corrupt_frame_mid_stream_names_the_frame(tmp_path):
    data = bytearray(write_clip(tmp_path / "whole.avi").read_bytes())
    chunk = movie_chunk_offsets(bytes(data))[12]
    size = int.from_bytes(data[chunk + 4 : chunk + 8], "little")
    data[chunk + 8 : chunk + 8 + size] = bytes(size)  # frame 12's JPEG data is wiped
    path = tmp_path / "corrupt.avi"
    path.write_bytes(bytes(data))
    seen = []
    with pytest.raises(VideoError, match=r"cannot decode frame 12 \(corrupt") as exc:
        for f in open_video(path):
            seen.append(f.index)
    assert seen == list(range(12))
    assert_one_line_naming(exc, path)
    # A selection that steps over the damaged frame still finds it.
    with pytest.raises(VideoError, match="frame 12"):
        list(open_video(path, start=10, step=5))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"start": -1}, "start must be >= 0, got -1"),
        ({"start": 10, "end": 5}, r"end \(5\) must be greater than start \(10\)"),
        ({"start": 4, "end": 4}, r"end \(4\) must be greater than start \(4\)"),
        ({"step": 0}, "step must be >= 1, got 0"),
        ({"start": 1.5}, "start must be an integer, got 1.5"),
        ({"end": "7"}, "end must be an integer, got '7'"),
        ({"step": True}, "step must be an integer, got True"),
        ({"fps": 0}, "fps must be a positive number, got 0"),
        ({"fps": float("nan")}, "fps must be a positive number, got nan"),
        ({"start": N}, rf"start \({N}\) is beyond the end of .* {N} frames"),
    ],
)
@pytest.mark.parametrize("kind", ["file", "folder"])
def test_bad_selection_values(clips, kind, kwargs, message):
    with pytest.raises(ConfigError, match=message) as exc:
        open_video(clips[kind], **kwargs)
    assert isinstance(exc.value, ValueError) and "\n" not in str(exc.value)


def test_numpy_integers_are_accepted(clips):
    video = open_video(clips["file"], start=np.int64(2), end=np.int32(5), step=np.uint8(2))
    assert list(video.indices) == [2, 4]


# -- Rerun video assets -------------------------------------------------------------------


def test_rerun_video_asset_detection(tmp_path, clips):
    vp9 = write_clip(tmp_path / "vp9.mp4", n=5, fourcc="vp09")
    assert open_video(vp9).is_rerun_video_asset()
    upper = vp9.rename(tmp_path / "VP9.MP4")
    assert open_video(upper).is_rerun_video_asset()
    mov = upper.rename(tmp_path / "vp9.mov")
    assert not open_video(mov).is_rerun_video_asset()
    mp4v = write_clip(tmp_path / "mpeg4.mp4", n=5, fourcc="mp4v")
    assert not open_video(mp4v).is_rerun_video_asset()
    assert not open_video(clips["file"]).is_rerun_video_asset()
    assert not open_video(clips["folder"]).is_rerun_video_asset()


# -- frames as the source stores them -------------------------------------------------------


def _jpeg(image: np.ndarray, quality: int = 90) -> bytes:
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return buf.tobytes()


def _segments(data: bytes) -> list[tuple[int, int]]:
    """(marker, offset) of a JPEG's segments up to its scan."""
    out, i = [], 2
    while data[i + 1] != 0xDA:
        out.append((data[i + 1], i))
        i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return out


def test_storable_jpeg_takes_plain_colour_and_grey_jpegs_only():
    from trackcli.io.video import storable_jpeg

    picture = np.random.default_rng(0).integers(0, 255, (24, 32, 3), dtype=np.uint8)
    colour, grey = _jpeg(picture), _jpeg(picture[..., 0])
    assert storable_jpeg(colour) and storable_jpeg(grey)
    progressive = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1].tobytes()
    assert storable_jpeg(progressive)
    ok, png = cv2.imencode(".png", picture)
    assert not storable_jpeg(png.tobytes())
    assert not storable_jpeg(b"") and not storable_jpeg(colour[:40])
    # Motion JPEG's convention of leaving out the Huffman tables: not shown by image viewers
    segs = _segments(colour)
    stripped = bytearray(colour)
    for marker, at in reversed(segs):
        if marker == 0xC4:
            length = 2 + int.from_bytes(colour[at + 2:at + 4], "big")
            del stripped[at:at + length]
    assert 0xC4 in dict(segs) and 0xC4 not in dict(_segments(bytes(stripped)))
    assert not storable_jpeg(bytes(stripped))
    # Exif (an orientation OpenCV applies and a viewer may not)
    exif = b"Exif\x00\x00" + b"MM\x00\x2a\x00\x00\x00\x08\x00\x00"
    with_exif = colour[:2] + b"\xff\xe1" + (len(exif) + 2).to_bytes(2, "big") + exif + colour[2:]
    assert cv2.imdecode(np.frombuffer(with_exif, np.uint8), cv2.IMREAD_COLOR) is not None
    assert not storable_jpeg(with_exif)


@pytest.mark.parametrize("start, step", [(0, 1), (11, 1), (3, 4)])
def test_mjpg_frames_come_with_their_stored_jpeg(clips, start, step):
    video = open_video(clips["file"], start=start, step=step)
    seen = 0
    for frame in video.frames(encoded=True):
        assert frame.encoded is not None and frame.encoded[:2] == b"\xff\xd8"
        stored = cv2.imdecode(np.frombuffer(frame.encoded, np.uint8), cv2.IMREAD_COLOR)
        assert frame_id(stored) == frame_id(frame.image) == frame.index
        seen += 1
    assert seen == len(video)
    assert all(f.encoded is None for f in video)  # plain iteration reads no packets


def test_folder_frames_come_with_their_jpeg_files(tmp_path):
    jpegs = write_folder(tmp_path / "jpg", [f"{i}.jpg" for i in range(4)])
    for frame in open_video(jpegs, fps=25).frames(encoded=True):
        assert frame.encoded == (jpegs / f"{frame.index}.jpg").read_bytes()
    pngs = write_folder(tmp_path / "png", [f"{i}.png" for i in range(4)])
    assert all(f.encoded is None for f in open_video(pngs, fps=25).frames(encoded=True))


def test_other_codecs_have_no_stored_jpeg(tmp_path):
    clip = write_clip(tmp_path / "clip.mp4", 5, fourcc="mp4v")
    frames = list(open_video(clip).frames(encoded=True))
    assert len(frames) == 5 and all(f.encoded is None for f in frames)
