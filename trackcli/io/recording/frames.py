"""Frame loggers: how each video frame goes into a recording.

Made by :meth:`trackcli.io.recording.Recording.frame_logger`; called as
``log_video(index, image_bgr, encoded)`` after :meth:`~trackcli.io.recording.Recording.set_frame`.

- :class:`FrameLogger`: a reference into a video asset embedded once (``AssetVideo`` +
  ``VideoFrameReference``), or a JPEG image per frame (``EncodedImage``).
- :class:`VideoStreamLogger`: the frames encoded as AV1 as they come
  (:class:`trackcli.io.encode.AV1Samples`) and logged as a ``VideoStream``: the codec once
  (static), then one sample per frame at that frame's time on both timelines, sent in
  columns every :data:`SEND_FRAMES` frames.  The overlays logged at a frame's time show on
  that frame.  When the encoder cannot take the frames (too small), every frame goes in as
  JPEG instead, as :class:`FrameLogger` stores them.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from trackcli.errors import DataError

log = logging.getLogger(__name__)

#: Frames whose AV1 samples are sent to the recording together (one chunk).
SEND_FRAMES = 25


class FrameLogger:
    """Logs one video frame per call, either as a reference into a video asset or as JPEG.

    Made by :meth:`Recording.frame_logger`.  Call it as ``log_video(index, image_bgr)``
    after :meth:`Recording.set_frame`.

    Attributes
    ----------
    kind : {"asset", "jpeg"}
        ``"asset"``: the clip was embedded once as an ``AssetVideo`` and each call logs a
        ``VideoFrameReference`` (the image argument is ignored); ``"jpeg"``: each call
        encodes the image.
    timestamps_ns : ndarray of shape (F,), int64, or None
        Presentation time of each frame in the asset (``"asset"`` only).
    """

    def __init__(self, recording: Any, entity: str, quality: int,
                 timestamps_ns: np.ndarray | None, *, keep_jpeg: bool = False) -> None:
        self._recording = recording
        self._entity = entity
        self._quality = quality
        self._keep_jpeg = keep_jpeg
        self.timestamps_ns = timestamps_ns
        self.kind = "jpeg" if timestamps_ns is None else "asset"

    def __call__(self, index: int, image_bgr: np.ndarray | None = None, encoded: bytes | None = None) -> None:
        """Log frame ``index`` (0-based, in decoding order).

        With an asset, frames past its last timestamp fall back to JPEG when an image is
        given (decoders may disagree on a clip's final frames).  ``encoded``: the frame's
        JPEG as its source stores it (:attr:`trackcli.io.video.Frame.encoded`), stored as it
        is, without encoding the image again, when the logger keeps source JPEGs.
        """
        ts = self.timestamps_ns
        if ts is not None and 0 <= index < len(ts):
            self._recording.log_frame_ref(int(ts[index]), entity=self._entity)
            return
        if encoded is not None and self._keep_jpeg:
            self._recording.log_jpeg(encoded, entity=self._entity)
            return
        if image_bgr is None:
            if ts is None:
                raise DataError("a JPEG frame logger needs the image for every frame")
            raise DataError(
                f"frame index {index} is outside the video asset (0..{len(ts) - 1}) "
                "and no image was given"
            )
        self._recording.log_frame(image_bgr, quality=self._quality, entity=self._entity)



class VideoStreamLogger:
    """Logs frames as an AV1 ``VideoStream`` (see the module docstring).

    Attributes
    ----------
    kind : {"av1", "jpeg"}
        ``"jpeg"`` once the encoder refused the frames and JPEG is stored instead.
    samples, sample_bytes : int
        AV1 samples sent so far and their total size.
    """

    def __init__(self, recording: Any, entity: str, quality: int, *, keep_jpeg: bool = False,
                 fps: float = 25.0) -> None:
        self._recording = recording
        self._entity = entity
        self._fps = fps
        self._encoder: Any = None
        self._held: list[tuple[tuple[int, float], bytes, bool]] = []
        self._fallback = FrameLogger(recording, entity, quality, None, keep_jpeg=keep_jpeg)
        self.kind = "av1"
        self.samples = 0
        self.sample_bytes = 0

    def __call__(self, index: int, image_bgr: np.ndarray | None = None, encoded: bytes | None = None) -> None:
        """Encode frame ``index`` (at the recording's current time) and send the samples that are ready."""
        if self.kind == "jpeg":
            self._fallback(index, image_bgr, encoded)
            return
        if image_bgr is None:
            raise DataError("an AV1 frame logger needs the image of every frame")
        when = self._recording.current_time()
        if when is None or when[0] != index:
            raise DataError(f"set the recording's time to frame {index} before logging it")
        if self._encoder is None:
            if not self._start(image_bgr):
                self._fallback(index, image_bgr, encoded)
                return
        self._held += self._encoder.encode(image_bgr, when)
        if len(self._held) >= SEND_FRAMES:
            self._send()

    def _start(self, image: np.ndarray) -> bool:
        import rerun as rr

        from trackcli.io.encode import AV1Samples, EncoderUnavailable

        try:
            self._encoder = AV1Samples((image.shape[1], image.shape[0]), self._fps)
        except EncoderUnavailable as exc:
            log.info("storing frames as JPEG: %s", exc)
            self.kind = "jpeg"
            return False
        self._recording._note(self._entity)
        self._recording.stream.log(self._entity, rr.VideoStream(codec=rr.VideoCodec.AV1), static=True)
        return True

    def finish(self, *, send: bool = True) -> None:
        """Send the samples still held, with those inside the encoder (called when the recording
        closes); ``send=False`` (a recording that failed) only stops the encoder."""
        if self._encoder is not None:
            encoder, self._encoder = self._encoder, None
            self._held += encoder.flush()
        if send:
            self._send()
        else:
            self._held = []

    def _send(self) -> None:
        if not self._held:
            return
        import rerun as rr

        held, self._held = self._held, []
        frames = np.array([w[0] for w, _, _ in held], dtype=np.int64)
        times = np.array([w[1] for w, _, _ in held], dtype=float)
        self._recording.stream.send_columns(
            self._entity,
            indexes=[rr.TimeColumn("frame", sequence=frames), rr.TimeColumn("video_time", duration=times)],
            columns=rr.VideoStream.columns(sample=[s for _, s, _ in held], is_keyframe=[k for _, _, k in held]))
        self.samples += len(held)
        self.sample_bytes += sum(len(s) for _, s, _ in held)


__all__ = ["FrameLogger", "SEND_FRAMES", "VideoStreamLogger"]
