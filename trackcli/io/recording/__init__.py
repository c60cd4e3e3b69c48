"""Rerun recordings (``.rrd`` files) of a run: frames, overlays, time series, histograms.

This package is the only place that imports ``rerun`` (rerun-sdk 0.41), and it does so lazily,
inside functions, so that ``import trackcli`` and ``trackcli --help`` stay instant.

A :class:`Recording` writes one file and never spawns or connects to a viewer::

    with Recording("out/run.rrd", blueprint="track") as rec:
        rec.log_params("params", settings)
        log_video = rec.frame_logger("clip.mp4")      # AssetVideo or JPEG frames
        for i, (t, image) in enumerate(frames):
            rec.set_frame(i, t)
            log_video(i, image)
            rec.log_contour("video/estimate", points, color=(255, 64, 0))

Data go to a temporary file ``.NAME.part`` next to the output; only a clean exit from the
``with`` block renames it to the final name, and an exception deletes it, so a recording
on disk is never half-written.

Entity layout shared by all commands (the saved blueprints expect it):

- ``video`` — the 2-D image space (pixels, ``x`` right, ``y`` down, as everywhere in
  trackcli).  The frame itself is logged at ``video``; overlays go below it
  (``video/estimate``, ``video/particles``, ``video/normals`` …) so they share its
  coordinates.  Commands without frames (``simulate``) still draw curves there.
- ``series/…`` — scalar time series (translation, ESS, gate width …), each logged with a
  unit; the saved layout plots the series of one unit together and never mixes units on one
  axis.
- ``histogram/…`` — bar charts per frame and the static "histogram over time" image
  (time × bins heat-map, cf. paper 000 Fig 3, where multi-modality shows as several
  bright ridges).
- ``params`` — the run's settings; ``log`` — text messages.

The saved layout (blueprint) is written when the recording closes and holds only views that
have data: a Kalman run has no histogram tab, a run without text messages no log tab.

Frames
------
How frames are stored is chosen by :func:`frame_storage` (setting ``output.frames``).  The
native Rerun viewer (0.41) decodes only AV1 video by itself; H.264 and H.265 need an FFmpeg
(>= 5.1) on the viewer's PATH, and VP9 plays only in the web viewer (Rerun docs, "Video",
codec support table).  So by default (``auto``) the frames are encoded as AV1 while they are
recorded (:class:`~trackcli.io.recording.frames.VideoStreamLogger`, a ``VideoStream``: one
sample per frame at the frame's time, about 5-6 KB a frame at 854x480, against 40-120 KB as
JPEG), an AV1 MP4 recorded whole is embedded as it is (``AssetVideo``), and JPEG frames
(``EncodedImage``, which every viewer shows) are the fallback when PyAV or its AV1 encoder is
missing or the frames are smaller than the encoder takes; JPEG frames at the source (a folder
of ``.jpg`` images, an MJPG video) are then stored as they are, neither encoded again nor
losing quality a second time.  An asset always holds the whole file, so it is used only when
every frame of the clip is recorded.

Timelines: ``frame`` (sequence, the frame index) and ``video_time`` (duration, seconds
from the start of the clip).  The wall-clock ``log_time`` timeline is switched off: it
says nothing about the data.

The package's modules: :mod:`.layout` (entity paths, colours, blueprints, how frames are
stored), :mod:`.stream` (:class:`Recording`: the file, time, batching, frames),
:mod:`.drawing` (its overlays, series, histograms and text), :mod:`.frames` (the frame
loggers) and :mod:`.arrow` (Arrow conversions and validators).
"""

from __future__ import annotations

import os

# Rerun's native library allocates with mimalloc, which keeps freed pages a while before it
# returns them.  While a long clip was tracked and recorded, the process grew by about 2 KB a
# frame; returning them at once (read when Rerun loads, which is only ever from this package)
# made it 0.8 KB a frame at the same speed (bench/track_memory.py).  A value the user set wins.
os.environ.setdefault("MIMALLOC_PURGE_DELAY", "0")

from trackcli.io.recording.arrow import PANDAS_CHECK_ENV, skip_pandas_check  # noqa: E402
from trackcli.io.recording.frames import FrameLogger, VideoStreamLogger  # noqa: E402
from trackcli.io.recording.layout import (  # noqa: E402
    BLUEPRINTS, FRAME_STORAGE, HISTOGRAM, LABELS, NATIVE_VIEWER_CODECS, PARAMS, SERIES, TEXT_LEVELS, TEXT_LOG,
    UNIT_TITLES, VIDEO, VIDEO_ASSET_SUFFIXES, frame_storage, histogram_grey, histogram_image, make_blueprint,
    weight_colors,
)
from trackcli.io.recording.stream import Recording  # noqa: E402

__all__ = [
    "BLUEPRINTS", "FRAME_STORAGE", "HISTOGRAM", "LABELS", "NATIVE_VIEWER_CODECS", "PANDAS_CHECK_ENV", "PARAMS",
    "SERIES", "TEXT_LEVELS", "TEXT_LOG", "UNIT_TITLES", "VIDEO", "VIDEO_ASSET_SUFFIXES", "FrameLogger", "Recording",
    "VideoStreamLogger", "frame_storage", "histogram_grey", "histogram_image", "make_blueprint", "skip_pandas_check",
    "weight_colors",
]
