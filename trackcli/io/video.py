"""Frames in: video files and image-sequence folders.

Every frame trackcli looks at enters through :func:`open_video`; this is the only module
that reads video or images with OpenCV.  A :class:`Video` streams frames one at a time, so
memory stays flat whatever the clip length, and reads one frame at random for tasks such
as drawing a template on frame ``k``.

Sources
-------
- A **video file**: anything OpenCV's FFmpeg backend decodes (MP4, AVI, MKV, ...).
- An **image folder**: the images in it (``*.jpg``, ``*.jpeg``, ``*.png``, and the lossless
  ``*.bmp``, ``*.tif``, ``*.tiff``, ``*.pgm``, ``*.ppm`` and ``*.webp`` some datasets use;
  case-insensitive, names starting with ``.`` ignored), in natural order (``2.png`` before ``10.png``).  A folder
  without images but with an ``img/`` sub-folder is read from there: the common tracking
  benchmark layout ``CLIP/img/0001.jpg`` (with ``CLIP/groundtruth_rect.txt`` beside it).
  Folders have no frame rate: pass ``fps``, or 25 fps is assumed with a warning.

Frames
------
A :class:`Frame` carries its *original* index in the clip, its time ``index / fps`` in
seconds, and the image as a BGR ``uint8`` array of shape ``(H, W, 3)`` (grey images are
converted to BGR).  Selecting frames with ``start``, ``end`` and ``step`` keeps those original
indices and times, so results can always be matched back to the clip.

Frame counts of video files
---------------------------
Containers report a frame count that may be wrong.  A file is therefore read until decoding
fails, and the failure is interpreted as follows:

- if a later frame still decodes, the frame is corrupt: :class:`~trackcli.errors.VideoError`
  naming the frame;
- if nothing decodes after it and at most :data:`END_SLACK` frames are missing from the
  reported count (or more frames than reported were read), it is the normal end of the clip;
- otherwise the file is truncated or corrupt: :class:`~trackcli.errors.VideoError`.

When the selection reaches the reported count (``end`` None or beyond it), iteration runs to
the true end of the stream, which may yield a few frames more or fewer than ``len(video)``; ``n_total``, ``indices`` and ``len`` are the best count
known when the clip is opened.  A file reporting no count at all is counted once, when
opened, by grabbing every frame.  Folders are exact: one image is one frame.
"""

from __future__ import annotations

import logging
import math
import operator
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from trackcli.errors import ConfigError, VideoError

log = logging.getLogger(__name__)

# Decoder chatter ("moov atom not found", "[ WARN...] cap.cpp ...") would print before
# trackcli's own one-line message about the same file.  Quiet by default; setting the
# variables in the environment shows it again.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET, read when FFmpeg is first used
if "OPENCV_LOG_LEVEL" not in os.environ:
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)

#: Suffixes (lower case) of the images read from a folder.
IMAGE_SUFFIXES: tuple[str, ...] = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")

#: Frame rate assumed for an image folder when none is given.
DEFAULT_FPS: float = 25.0

#: Frames a video file may fall short of its reported count and still be complete.
END_SLACK: int = 2

# After a failed decode, how many further grabs decide "corrupt frame" versus "end of stream".
_PROBE_GRABS = 3

#: Codecs (FOURCC, lower case) whose every frame is a whole JPEG image: Motion JPEG.
JPEG_CODECS = frozenset({"mjpg", "jpeg"})

# Codecs (as OpenCV reports FOURCC, compared in lower case) that Rerun's AssetVideo plays
# from an MP4 container: H.264, VP9 and AV1.
_RERUN_CODECS = frozenset({"avc1", "h264", "x264", "vp09", "vp90", "av01"})


@dataclass(frozen=True, eq=False)
class Frame:
    """One frame of a clip.

    Attributes
    ----------
    index : int
        Original frame number in the clip (0-based), whatever frames were selected.
    time : float
        Seconds from the start of the clip, ``index / fps``.
    image : ndarray of shape (H, W, 3), dtype uint8
        The picture in BGR channel order.
    """

    index: int
    time: float
    image: np.ndarray
    encoded: bytes | None = None
    """The frame as the source stores it, when that is a JPEG a viewer can show as it is (see
    :func:`storable_jpeg`): a ``.jpg`` of a folder or a frame of an MJPG video, read by
    :meth:`Video.frames` with ``encoded=True``; otherwise None."""


class Video:
    """A clip opened for streaming and random access; create it with :func:`open_video`.

    Iterating yields the selected frames in order, decoding one at a time; each iteration
    starts afresh.  :meth:`read` fetches any frame of the clip by its original index.  Use
    the object as a context manager (or call :meth:`close`) to release the decoder held for
    random access.  Attributes are read-only.

    Attributes
    ----------
    path : Path
        The file or folder as given to :func:`open_video`.
    kind : {"file", "folder"}
        A video file or an image folder.
    fps : float
        Frames per second, used for frame times.
    width, height : int
        Frame size in pixels.
    n_total : int
        Frames in the whole clip (exact for folders; the best known count for files).
    indices : range
        Original indices of the selected frames.
    """

    def __init__(
        self,
        *,
        path: Path,
        kind: Literal["file", "folder"],
        fps: float,
        width: int,
        height: int,
        n_total: int,
        indices: range,
        end: int | None,
        images: tuple[Path, ...] = (),
        fourcc: str = "",
    ) -> None:
        self.path = path
        self.kind = kind
        self.fps = fps
        self.width = width
        self.height = height
        self.n_total = n_total
        self.indices = indices
        self._end = end  # as requested, unclamped: files read on to the true end when None
        self._images = images
        self._fourcc = fourcc
        self._reader: cv2.VideoCapture | None = None
        self._reader_next = 0  # index the random-access reader decodes next
        self._closed = False

    # -- container protocol ---------------------------------------------------------------

    def __len__(self) -> int:
        return len(self.indices)

    def __iter__(self) -> Iterator[Frame]:
        return self.frames()

    def frames(self, *, encoded: bool = False) -> Iterator[Frame]:
        """Iterate over the selected frames, as ``iter(video)`` does.

        With ``encoded``, each frame also carries its JPEG as the source stores it
        (:attr:`Frame.encoded`) when the source is JPEG: a recording can then keep that JPEG
        instead of encoding the picture again.  For an MJPG video a second reader takes the
        stored frames alongside the decoded ones (demuxing only, about 0.02 ms a frame).
        """
        self._check_open()
        if self.kind == "folder":
            return self._iter_folder(encoded)
        return self._iter_file(encoded and self.codec in JPEG_CODECS)

    def __enter__(self) -> Video:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        r = self.indices
        return (
            f"Video({str(self.path)!r}, kind={self.kind!r}, {self.width}x{self.height}, "
            f"fps={self.fps:g}, n_total={self.n_total}, "
            f"indices=range({r.start}, {r.stop}, {r.step}))"
        )

    def close(self) -> None:
        """Release the random-access decoder; the video cannot be used afterwards."""
        if self._reader is not None:
            self._reader.release()
            self._reader = None
        self._closed = True

    # -- public queries -------------------------------------------------------------------

    def read(self, index: int) -> Frame:
        """Decode one frame by its original index in the clip.

        Parameters
        ----------
        index : int
            Frame number, ``0 <= index < n_total``; it need not be among ``indices``.

        Returns
        -------
        Frame
            The frame, its image of shape ``(height, width, 3)``.

        Raises
        ------
        ConfigError
            If ``index`` is not an integer in range.
        VideoError
            If the frame cannot be decoded.
        """
        self._check_open()
        index = _as_int("index", index)
        if not 0 <= index < self.n_total:
            raise ConfigError(
                f"frame index {index} is out of range for {self.path}: "
                f"valid 0..{self.n_total - 1}"
            )
        if self.kind == "folder":
            return self._frame(index, self._load_image(index))
        if self._reader is None:
            self._reader = _open_capture(self.path)
            self._reader_next = 0
        if index != self._reader_next:
            self._reader.set(cv2.CAP_PROP_POS_FRAMES, index)
        ok, image = self._reader.read()
        if not ok:
            self._reader_next = -1  # position unknown: seek next time
            raise VideoError(f"{self.path}: cannot decode frame {index}")
        self._reader_next = index + 1
        return self._frame(index, _as_bgr(image, f"{self.path} frame {index}"))

    @property
    def codec(self) -> str:
        """The video codec of a file as a lower-case FOURCC (``"vp09"``, ``"avc1"``, ``"av01"``); empty for folders."""
        return self._fourcc.strip().lower()

    def frame_name(self, index: int) -> str:
        """The name of frame ``index`` without a suffix: an image's own (``00042`` for
        ``00042.jpg``), or for a video file the index in five digits as DAVIS numbers frames
        (``00042``; more digits from frame 100 000 on).  Per-frame outputs are named by it."""
        index = _as_int("index", index)
        if not 0 <= index < self.n_total:
            raise ConfigError(f"frame index {index} is out of range for {self.path}: valid 0..{self.n_total - 1}")
        if self.kind == "folder":
            return self._images[index].stem
        return f"{index:05d}"

    @property
    def whole_clip(self) -> bool:
        """Whether the selection is every frame of the clip (no start, end or step)."""
        return self.indices == range(0, self.n_total, 1)

    def is_rerun_video_asset(self) -> bool:
        """Whether Rerun can play the file itself as a video asset.

        True for an MP4 file (``.mp4`` suffix and an ISO-BMFF ``ftyp`` box) whose video codec is
        H.264 (``avc1``), VP9 (``vp09``) or AV1 (``av01``); Rerun's ``AssetVideo`` rejects other codecs (e.g.
        ``mp4v``) and other containers (AVI, MKV).  Always False for image folders.
        """
        if self.kind != "file" or self.path.suffix.lower() != ".mp4":
            return False
        if self._fourcc.strip().lower() not in _RERUN_CODECS:
            return False
        try:
            with self.path.open("rb") as fh:
                head = fh.read(12)
        except OSError:
            return False
        return head[4:8] == b"ftyp"

    # -- streaming ------------------------------------------------------------------------

    def _frame(self, index: int, image: np.ndarray, encoded: bytes | None = None) -> Frame:
        if image.shape[:2] != (self.height, self.width):
            h, w = image.shape[:2]
            where = self._images[index] if self.kind == "folder" else self.path
            raise VideoError(
                f"{where}: frame {index} is {w}x{h} but the clip is "
                f"{self.width}x{self.height}; all frames must have the same size"
            )
        return Frame(index=index, time=index / self.fps, image=image, encoded=encoded)

    def _iter_folder(self, encoded: bool = False) -> Iterator[Frame]:
        for index in self.indices:
            if not encoded:
                yield self._frame(index, self._load_image(index))
                continue
            image, data = _read_image_data(self._images[index], index)
            yield self._frame(index, image, data if storable_jpeg(data) else None)

    def _load_image(self, index: int) -> np.ndarray:
        return _read_image(self._images[index], index)

    def _iter_file(self, encoded: bool = False) -> Iterator[Frame]:
        start, step, stop = self.indices.start, self.indices.step, self._end
        cap = _open_capture(self.path)
        stored = _open_stored_frames(self.path, start) if encoded else None
        try:
            if start > 0:
                cap.set(cv2.CAP_PROP_POS_FRAMES, start)
            position = start  # index of the frame the capture delivers next
            index = start
            while stop is None or index < stop:
                while position < index:  # skipped by `step`: demux and decode, no conversion
                    if not cap.grab():
                        self._stream_ended(cap, position)
                        return
                    if stored is not None and not stored.grab():
                        stored = _close_stored(stored)
                    position += 1
                ok, image = cap.read()
                if not ok:
                    self._stream_ended(cap, position)
                    return
                position += 1
                data = None
                if stored is not None:
                    ok, packet = stored.read()
                    data = packet.tobytes() if ok and packet is not None else None
                    if data is None or not storable_jpeg(data) or (index == start and not _same_picture(data, image)):
                        stored, data = _close_stored(stored), None  # from here on, encoded anew
                yield self._frame(index, _as_bgr(image, f"{self.path} frame {index}"), data)
                index += step
        finally:
            cap.release()
            if stored is not None:
                stored.release()

    def _stream_ended(self, cap: cv2.VideoCapture, index: int) -> None:
        """Decide whether a failed decode at ``index`` is the end of the clip or an error."""
        for _ in range(_PROBE_GRABS):
            if cap.grab():
                raise VideoError(
                    f"{self.path}: cannot decode frame {index} (corrupt data; later frames "
                    f"decode)"
                )
        if index < self.n_total - END_SLACK:
            raise VideoError(
                f"{self.path}: decoding stops at frame {index} but the file reports "
                f"{self.n_total} frames (truncated or corrupt; end={index} reads the frames "
                f"before it)"
            )
        if index != self.n_total:
            log.info("%s: stream ends at frame %d; the file reports %d", self.path, index,
                     self.n_total)

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError(f"video {self.path} is closed")


def open_video(
    path: str | Path,
    *,
    fps: float | None = None,
    start: int = 0,
    end: int | None = None,
    step: int = 1,
) -> Video:
    """Open a video file or an image folder for reading.

    Parameters
    ----------
    path : str or Path
        A video file, a folder of images, or a benchmark clip folder holding ``img/``.
    fps : float, optional
        Frames per second.  Overrides the rate a file reports; for a folder, 25 fps is
        assumed (with a warning) when it is not given.
    start : int, default 0
        First original index selected (inclusive); must lie inside the clip.
    end : int, optional
        Original index where the selection stops (exclusive); None reads to the end.
        An ``end`` beyond the clip is cut to the clip, as in slicing.
    step : int, default 1
        Take every ``step``-th frame from ``start``.

    Returns
    -------
    Video
        The opened clip.  The first frame has been decoded to check the source.

    Raises
    ------
    VideoError
        If the path is missing, unreadable, not a decodable video, an empty video, or a
        folder without images.
    ConfigError
        If ``fps``, ``start``, ``end`` or ``step`` is invalid.
    """
    path = Path(path)
    start = _as_int("start", start)
    step = _as_int("step", step)
    if end is not None:
        end = _as_int("end", end)
    if start < 0:
        raise ConfigError(f"start must be >= 0, got {start}")
    if step < 1:
        raise ConfigError(f"step must be >= 1, got {step}")
    if end is not None and end <= start:
        raise ConfigError(f"end ({end}) must be greater than start ({start})")
    if fps is not None:
        fps = _check_fps(fps)

    if not path.exists():
        raise VideoError(f"{path}: no such file or folder")
    if path.is_dir():
        video = _open_folder(path, fps, end)
    else:
        video = _open_file(path, fps, end)

    if start >= video.n_total:
        raise ConfigError(
            f"start ({start}) is beyond the end of {path}, which has {video.n_total} frames "
            f"(valid 0..{video.n_total - 1})"
        )
    stop = video.n_total if end is None else min(end, video.n_total)
    video.indices = range(start, stop, step)
    return video


# -- opening ------------------------------------------------------------------------------


def _open_folder(path: Path, fps: float | None, end: int | None) -> Video:
    images = _list_images(path)
    if not images and (path / "img").is_dir():
        images = _list_images(path / "img")
    if not images:
        others = sum(1 for p in path.iterdir() if not p.name.startswith("."))
        found = f"; found {others} other entr{'y' if others == 1 else 'ies'}" if others else ""
        raise VideoError(
            f"{path}: no images ({', '.join('*' + s for s in IMAGE_SUFFIXES)}) in the folder "
            f"or in its img/ sub-folder{found}"
        )
    if fps is None:
        log.warning("%s: an image folder has no frame rate; assuming %g fps", path,
                    DEFAULT_FPS)
        fps = DEFAULT_FPS
    first = _read_image(images[0], 0)
    height, width = first.shape[:2]
    return Video(
        path=path, kind="folder", fps=fps, width=width, height=height,
        n_total=len(images), indices=range(0), end=end, images=tuple(images),
    )


def _open_file(path: Path, fps: float | None, end: int | None) -> Video:
    if not path.is_file():
        raise VideoError(f"{path}: not a regular file or folder")
    try:
        with path.open("rb"):
            pass
    except OSError as exc:
        raise VideoError(f"{path}: cannot read the file ({exc.strerror})") from None
    cap = _open_capture(path)
    try:
        reported = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        file_fps = cap.get(cv2.CAP_PROP_FPS)
        fourcc = _fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
        ok, first = cap.read()
        if not ok:
            raise VideoError(f"{path}: no frame can be decoded (empty or corrupt video)")
        first = _as_bgr(first, f"{path} frame 0")
        if math.isfinite(reported) and reported >= 1:
            n_total = int(round(reported))
        else:
            n_total = 1
            while cap.grab():
                n_total += 1
            log.info("%s: the file reports no frame count; counted %d frames", path, n_total)
    finally:
        cap.release()

    if fps is None:
        if math.isfinite(file_fps) and file_fps > 0:
            fps = float(file_fps)
        else:
            log.warning("%s: the file reports no frame rate; assuming %g fps", path,
                        DEFAULT_FPS)
            fps = DEFAULT_FPS
    height, width = first.shape[:2]
    return Video(
        path=path, kind="file", fps=fps, width=width, height=height, n_total=n_total,
        indices=range(0), end=end, fourcc=fourcc,
    )


def _open_capture(path: Path) -> cv2.VideoCapture:
    """Open ``path`` with the FFmpeg backend, falling back to any backend OpenCV has."""
    for api in (cv2.CAP_FFMPEG, cv2.CAP_ANY):
        cap = cv2.VideoCapture(str(path), api)
        if cap.isOpened():
            return cap
        cap.release()
    raise VideoError(
        f"{path}: cannot open as a video (not a video file, or an unsupported format)"
    )


def _list_images(folder: Path) -> list[Path]:
    images = [
        p for p in folder.iterdir()
        if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".") and p.is_file()
    ]
    images.sort(key=_natural_key)
    return images


_DIGITS = re.compile(r"(\d+)", re.ASCII)


def _natural_key(p: Path) -> tuple[tuple[str | int, ...], str]:
    """Sort key putting ``img2.png`` before ``img10.png``; ties broken by the plain name."""
    parts = _DIGITS.split(p.name.lower())
    # re.split with one group alternates text (even positions) and digit runs (odd positions),
    # so tuples compare str with str and int with int.
    return tuple(int(t) if i % 2 else t for i, t in enumerate(parts)), p.name


# -- decoding helpers ---------------------------------------------------------------------


def _read_image(file: Path, index: int) -> np.ndarray:
    """Decode an image file to BGR uint8 of shape ``(H, W, 3)``."""
    return _read_image_data(file, index)[0]


def _read_image_data(file: Path, index: int) -> tuple[np.ndarray, bytes]:
    """Decode an image file: ``(BGR uint8 image (H, W, 3), the file's bytes)``."""
    try:
        raw = file.read_bytes()
    except OSError as exc:
        raise VideoError(f"{file}: cannot read image for frame {index} ({exc.strerror})") from None
    data = np.frombuffer(raw, dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        raise VideoError(
            f"{file}: cannot decode image for frame {index} (corrupt or not an image)"
        )
    return _as_bgr(image, f"{file} (frame {index})"), raw


def storable_jpeg(data: bytes) -> bool:
    """Whether ``data`` is a JPEG that any viewer shows as the frame it decodes to.

    Baseline, extended or progressive Huffman-coded JPEG with one (grey) or three colour
    components, its Huffman tables in the file.  Not: other data; arithmetic-coded or
    lossless JPEG; CMYK; Motion JPEG frames that leave out their Huffman tables (the AVI1
    convention; decoders of video supply the standard tables, image viewers may not); and
    any file with Exif data, whose orientation tag OpenCV applies when it decodes and a
    viewer may not.
    """
    n = len(data)
    if n < 4 or data[0] != 0xFF or data[1] != 0xD8:
        return False
    i, huffman, components = 2, False, 0
    while i + 4 <= n:
        if data[i] != 0xFF:
            return False
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # no length
            i += 2
            continue
        if marker in (0xD8, 0xD9):
            return False
        length = (data[i + 2] << 8) | data[i + 3]
        body = data[i + 4:i + 2 + length]
        if marker == 0xDA:  # start of scan: the tables come before it
            return huffman and components in (1, 3)
        if marker == 0xC4:
            huffman = True
        elif marker in (0xC0, 0xC1, 0xC2):
            components = body[5] if len(body) > 5 else 0
        elif 0xC3 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return False  # lossless, hierarchical or arithmetic-coded
        elif marker == 0xE1 and body[:6] == b"Exif\x00\x00":
            return False
        i += 2 + length
    return False


def _open_stored_frames(path: Path, start: int) -> cv2.VideoCapture | None:
    """A reader of a video's frames as stored (undecoded packets), at ``start``; None if the
    backend cannot give them."""
    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    if not cap.isOpened() or not cap.set(cv2.CAP_PROP_FORMAT, -1):
        cap.release()
        return None
    if start > 0:
        cap.set(cv2.CAP_PROP_POS_FRAMES, start)
    return cap


def _close_stored(cap: cv2.VideoCapture) -> None:
    cap.release()
    return None


def _same_picture(data: bytes, image: np.ndarray) -> bool:
    """Whether a stored JPEG decodes to (nearly) the decoded frame ``image``: the two readers
    are at the same frame.  Decoders differ by a grey level or two on average."""
    other = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if other is None or other.shape[:2] != image.shape[:2]:
        return False
    a = cv2.cvtColor(other, cv2.COLOR_GRAY2BGR) if other.ndim == 2 else other
    b = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image
    return a.shape == b.shape and float(cv2.absdiff(a, b).mean()) < 6.0


def _as_bgr(image: np.ndarray, what: str) -> np.ndarray:
    """Return ``image`` as BGR uint8 ``(H, W, 3)``, converting grey or BGRA."""
    if image.dtype != np.uint8:
        raise VideoError(f"{what}: unsupported pixel type {image.dtype}; expected 8-bit")
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    raise VideoError(f"{what}: unsupported image shape {image.shape}")


def _fourcc_text(code: float) -> str:
    """Four-character codec code from OpenCV's numeric CAP_PROP_FOURCC ('' if none)."""
    if not math.isfinite(code) or not 0 < code < 2**32:
        return ""
    raw = int(code).to_bytes(4, "little", signed=False)
    return raw.decode("ascii", errors="replace") if all(32 <= b < 127 for b in raw) else ""


def _as_int(name: str, value: object) -> int:
    if isinstance(value, bool):
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    try:
        return operator.index(value)
    except TypeError:
        raise ConfigError(f"{name} must be an integer, got {value!r}") from None


def _check_fps(fps: object) -> float:
    try:
        value = float(fps)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigError(f"fps must be a positive number, got {fps!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"fps must be a positive number, got {fps!r}")
    return value
