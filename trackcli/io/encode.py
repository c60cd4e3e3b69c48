"""Video out through PyAV (FFmpeg's libraries): H.264 MP4 files, and AV1 samples for recordings.

This is the only module that imports ``av`` (PyAV), and it does so lazily.  PyAV's wheels
carry FFmpeg with the x264 (H.264) and SVT-AV1 encoders, which the ``opencv-python`` wheels
lack: OpenCV writes VP9 or MPEG-4 part 2 into an MP4, and VP9 at 1280x720 encoded at 2.6
frames/s here and does not play in many common players.

- :class:`H264Writer` writes an MP4 that plays everywhere: H.264 (High profile), 4:2:0
  chroma (``yuv420p``), even width and height (an odd frame is padded by repeating its last
  row or column), the index at the front of the file (``+faststart``) so that browsers play
  it while it loads.  It is written under a temporary name and renamed when complete.
- :class:`AV1Samples` encodes frames one by one into AV1 *temporal units* in the
  low-overhead bitstream format (Section 5.2 of the AV1 specification), each holding
  exactly one shown frame, the keyframes with their sequence header: what Rerun's
  ``VideoStream`` expects.  The encoder runs in low-delay mode (no frame reordering, no
  look-ahead), so each frame's sample comes out as the frame goes in, and at a constant bit
  rate of :data:`AV1_BITS_PER_PIXEL` per pixel and frame (about 5-6 KB a frame at 854x480).

PyAV's API used here (``av.open``, ``add_stream``, ``CodecContext.create``,
``VideoFrame.from_ndarray``, ``Packet.is_keyframe``) is the same from PyAV 14 to 19.
"""

from __future__ import annotations

import logging
import os
from fractions import Fraction
from functools import lru_cache
from pathlib import Path

import numpy as np

from trackcli.errors import DataError, InputError

log = logging.getLogger(__name__)

# SVT-AV1 writes its banner and settings to stderr unless told otherwise (1 = errors only);
# read when the library first logs.  A value the user set wins.
os.environ.setdefault("SVT_LOG", "1")

#: Encoders (FFmpeg names) of the two products.
H264_ENCODER = "libx264"
AV1_ENCODER = "libsvtav1"

#: H.264 quality (x264's constant rate factor; 23 is its default, lower is better) and speed.
H264_CRF = 23
H264_PRESET = "superfast"

#: Bits per pixel and frame of the AV1 stream in recordings: 0.10 is 1 Mbit/s at 854x480
#: and 25 frames/s, about 5 KB a frame (5.8 KB with the first keyframe on a 75-frame clip).  On 8
#: DAVIS-2016 sequences at 854x480 constant rate factors gave 5-17 KB a frame depending on the
#: content; a constant bit rate keeps every clip near the budget.  A whole recording is to stay
#: within 12 KB a frame at 854x480 with its overlays; 0.146 (7.5 KB) left too little room for
#: them, and cost 0.9 dB of PSNR less than it bought (DAVIS boat: 33.0 dB at 0.146, 32.5 at
#: 0.12, 32.1 at 0.10).
AV1_BITS_PER_PIXEL = 0.10
#: SVT-AV1 speed preset (0 slowest ... 12; 12 is run as 11): 100-150 frames/s at 854x480 on two cores.
AV1_PRESET = 11
#: SVT-AV1's level of parallelism (its ``lp``): the encoder works in one thread.  It runs beside
#: the tracker, which keeps the cores busy; with its default (a pool per core) it took 12.6 ms of
#: processor time a frame at 854x480, with one thread 8.8-9.6, and the bytes it writes are the same.
AV1_THREADS = 1
#: A keyframe every this many seconds, so that the viewer can seek without decoding far back
#: (a keyframe takes 3-4 frames' bytes; at most 100 frames to decode when seeking at 25 frames/s).
AV1_KEYFRAME_SECONDS = 4.0
#: SVT-AV1 refuses frames narrower or lower than this.
AV1_MIN_SIDE = 64


class EncoderUnavailable(DataError):
    """PyAV, or the encoder asked for, is not installed here (callers fall back to another format)."""


@lru_cache(maxsize=None)
def encoder_available(name: str) -> bool:
    """Whether PyAV is installed and its FFmpeg has the encoder ``name`` (e.g. ``"libx264"``)."""
    try:
        import av
    except ImportError:
        return False
    try:
        av.codec.Codec(name, "w")
    except Exception:  # av.codec.codec.UnknownCodecError and friends
        return False
    return True


def _even(n: int) -> int:
    return n + (n % 2)


def _pad_even(image: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 3) with its last row and/or column repeated to make both sides even."""
    h, w = image.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return image
    return np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def _yuv420(image_bgr: np.ndarray):
    """A PyAV ``yuv420p`` frame of a BGR uint8 image (H, W, 3) or a grey one (H, W).

    OpenCV's conversion is BT.601 with limited range (Y 16-235), as FFmpeg's own (within half a
    grey level) at a fifth of its time.
    """
    import av
    import cv2

    img = np.asarray(image_bgr)
    if img.dtype != np.uint8 or img.ndim not in (2, 3):
        raise DataError(f"a frame must be a uint8 image (H, W) or (H, W, 3), got {img.dtype} of shape {img.shape}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    img = _pad_even(img)
    return av.VideoFrame.from_ndarray(cv2.cvtColor(img, cv2.COLOR_BGR2YUV_I420), format="yuv420p")


def _tag_bt601(ctx) -> None:
    """Say in the stream what :func:`_yuv420` made: BT.601 matrix, limited ("TV") range, so that
    a player of HD video does not take it for BT.709 (PyAV before 15 may lack the attributes)."""
    for name, value in (("colorspace", 6), ("color_range", 1)):  # AVCOL_SPC_SMPTE170M, AVCOL_RANGE_MPEG
        try:
            setattr(ctx, name, value)
        except (AttributeError, TypeError, ValueError):
            pass


def _rate(fps: float) -> Fraction:
    """A frame rate as a fraction (29.97 as 30000/1001)."""
    if not np.isfinite(fps) or fps <= 0:
        raise DataError(f"frame rate must be a positive number, got {fps!r}")
    return Fraction(float(fps)).limit_denominator(1001)


class H264Writer:
    """An H.264 MP4 written frame by frame, renamed into place by :meth:`close` (``ok=True``).

    Parameters
    ----------
    path : path
        The ``.mp4`` to write; its folder must exist.
    fps : float
        Frames per second of the video.
    size : (width, height)
        Frame size; odd sides are padded to even ones.

    Raises
    ------
    EncoderUnavailable
        PyAV or its x264 encoder is missing.
    InputError
        The file cannot be written.
    """

    codec = "h264"

    def __init__(self, path: str | os.PathLike[str], fps: float, size: tuple[int, int], *,
                 crf: int = H264_CRF, preset: str = H264_PRESET) -> None:
        if not encoder_available(H264_ENCODER):
            raise EncoderUnavailable("PyAV with an H.264 encoder (libx264) is not installed: pip install av")
        import av

        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.stem}.part{self.path.suffix}")
        width, height = (int(v) for v in size)
        try:
            self._container = av.open(str(self.tmp), "w", format="mp4", options={"movflags": "+faststart"})
        except OSError as exc:
            raise InputError(f"{self.path}: cannot write ({exc.strerror or exc})") from None
        try:
            stream = self._container.add_stream(H264_ENCODER, rate=_rate(fps))
            stream.width, stream.height = _even(width), _even(height)
            stream.pix_fmt = "yuv420p"
            _tag_bt601(stream.codec_context)
            stream.options = {"crf": str(int(crf)), "preset": preset, "profile": "high"}
            self._stream = stream
        except BaseException:
            self._container.close()
            self.tmp.unlink(missing_ok=True)
            raise
        self.frames = 0

    def write(self, image_bgr: np.ndarray) -> None:
        """Append one frame (BGR uint8, the size given)."""
        frame = _yuv420(image_bgr)
        frame.pts = self.frames
        for packet in self._stream.encode(frame):
            self._container.mux(packet)
        self.frames += 1

    def close(self, ok: bool) -> None:
        """Finish the file and rename it into place (``ok``), or delete it."""
        try:
            if ok:
                for packet in self._stream.encode(None):
                    self._container.mux(packet)
        finally:
            self._container.close()
        if ok:
            os.replace(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)


class AV1Samples:
    """Frames in, AV1 samples out: one temporal unit per frame, for a Rerun ``VideoStream``.

    Parameters
    ----------
    size : (width, height)
        Frame size (at least :data:`AV1_MIN_SIDE` each way; odd sides are padded).
    fps : float
        Frames per second (sets the keyframe interval; the bit rate is per frame).

    Call :meth:`encode` with each frame and a key of your choice (say, its index); it returns
    the samples that became ready, as ``(key, data, is_keyframe)``, and :meth:`flush` the rest.

    Raises
    ------
    EncoderUnavailable
        PyAV or its SVT-AV1 encoder is missing, or the frames are too small for it.
    """

    def __init__(self, size: tuple[int, int], fps: float, *, bits_per_pixel: float = AV1_BITS_PER_PIXEL,
                 preset: int = AV1_PRESET) -> None:
        width, height = (int(v) for v in size)
        if not encoder_available(AV1_ENCODER):
            raise EncoderUnavailable("PyAV with an AV1 encoder (libsvtav1) is not installed: pip install av")
        if min(width, height) < AV1_MIN_SIDE:
            raise EncoderUnavailable(f"{width}x{height} frames are too small for the AV1 encoder "
                                     f"(at least {AV1_MIN_SIDE}x{AV1_MIN_SIDE})")
        import av

        rate = _rate(fps)
        keyint = int(np.clip(round(AV1_KEYFRAME_SECONDS * float(rate)), 1, 600))
        kbps = max(20, int(round(bits_per_pixel * _even(width) * _even(height) * float(rate) / 1000)))
        ctx = av.CodecContext.create(AV1_ENCODER, "w")
        ctx.width, ctx.height, ctx.pix_fmt = _even(width), _even(height), "yuv420p"
        ctx.time_base, ctx.framerate = 1 / rate, rate
        _tag_bt601(ctx)
        # low delay (no reordering, which Rerun's VideoStream cannot take), constant bit rate
        ctx.options = {"preset": str(int(preset)),
                       "svtav1-params": f"pred-struct=1:lookahead=0:rc=2:tbr={kbps}:keyint={keyint}:lp={AV1_THREADS}"}
        try:
            ctx.open()
        except Exception as exc:
            raise EncoderUnavailable(f"the AV1 encoder refused {width}x{height} frames ({exc})") from None
        self._ctx = ctx
        self._keys: dict[int, object] = {}
        self._next = 0
        self.size = (width, height)

    def encode(self, image_bgr: np.ndarray, key: object) -> list[tuple[object, bytes, bool]]:
        """Encode one frame (BGR uint8 of the given size) and return the samples ready."""
        if image_bgr.shape[1] != self.size[0] or image_bgr.shape[0] != self.size[1]:
            raise DataError(f"a {image_bgr.shape[1]}x{image_bgr.shape[0]} frame in a "
                            f"{self.size[0]}x{self.size[1]} video")
        frame = _yuv420(image_bgr)
        frame.pts = self._next
        self._keys[self._next] = key
        self._next += 1
        return self._collect(self._ctx.encode(frame))

    def flush(self) -> list[tuple[object, bytes, bool]]:
        """The samples still inside the encoder; the encoder is finished afterwards."""
        return self._collect(self._ctx.encode(None))

    def _collect(self, packets) -> list[tuple[object, bytes, bool]]:
        return [(self._keys.pop(int(p.pts)), bytes(p), bool(p.is_keyframe)) for p in packets]


__all__ = ["AV1Samples", "AV1_BITS_PER_PIXEL", "EncoderUnavailable", "H264Writer", "encoder_available"]
