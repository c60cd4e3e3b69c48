"""Rerun recordings (``.rrd`` files) of a run: frames, overlays, time series, histograms.

This is the only module that imports ``rerun`` (rerun-sdk 0.41), and it does so lazily,
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
codec support table).  JPEG frames (``EncodedImage``) show in every viewer, so they are the
default; a clip is embedded as a video asset only when asked, or (``auto``) when it is AV1.
Under ``auto``, frames that are JPEG at the source (a folder of ``.jpg`` images, an MJPG
video) are stored as the source's JPEG, neither encoded again nor losing quality a second time.
An asset always holds the whole file, so it is used only when every frame of the clip is
recorded; a selection (``--start/--end/--step``) stores only its own frames, as JPEG.

Timelines: ``frame`` (sequence, the frame index) and ``video_time`` (duration, seconds
from the start of the clip).  The wall-clock ``log_time`` timeline is switched off: it
says nothing about the data.

One module (over 600 lines): every entity path, colour and blueprint of a recording is
defined here, so that the recording's layout can be read in one place.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import uuid
from collections.abc import Mapping, Sequence
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np

from trackcli.errors import ConfigError, DataError, InputError, TrackcliError

log = logging.getLogger(__name__)

# Rerun's native library allocates with mimalloc, which keeps freed pages a while before it
# returns them.  While a long clip was tracked and recorded, the process grew by about 2 KB a
# frame; returning them at once (read when Rerun loads, which is only ever from this module)
# made it 0.8 KB a frame at the same speed (bench/track_memory.py).  A value the user set wins.
os.environ.setdefault("MIMALLOC_PURGE_DELAY", "0")

#: Environment variable: ``0`` makes :class:`Recording` let pyarrow's check for pandas fail
#: at once (:func:`skip_pandas_check`).  pyarrow checks once per process whether pandas is
#: installed, by importing it, when it first converts data for Rerun: about 0.25 s, a sixth
#: of a short ``track`` run, and trackcli never hands pandas objects to pyarrow.  The
#: ``trackcli`` command sets it to 0 for itself and the processes it starts (batch workers)
#: unless it is set; code that imports trackcli as a library keeps pyarrow's behaviour.
PANDAS_CHECK_ENV = "TRACKCLI_PANDAS_CHECK"
_pandas_check_done = False


def skip_pandas_check() -> None:
    """Let pyarrow's one-time check for pandas find none, unless pandas is already imported.

    pyarrow remembers the answer for the process: its pandas conversions (``from_pandas``,
    ``to_pandas``) are then unavailable in this process.  pandas itself still imports.
    Only the first call in a process does anything.
    """
    global _pandas_check_done
    if _pandas_check_done or "pandas" in sys.modules:
        return
    _pandas_check_done = True

    class _NoPandas:
        def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
            if name == "pandas" or name.startswith("pandas."):
                raise ModuleNotFoundError(f"{name} is not imported in this process", name=name)
            return None

    import pyarrow as pa

    blocker = _NoPandas()
    sys.meta_path.insert(0, blocker)
    try:
        pa.array([0.0])  # the first conversion makes the check
    finally:
        sys.meta_path.remove(blocker)

VIDEO = "video"
SERIES = "series"
HISTOGRAM = "histogram"
PARAMS = "params"
TEXT_LOG = "log"
LABELS = "labels"

BLUEPRINTS = ("track", "draw", "simulate")
FRAME_STORAGE = ("auto", "jpeg", "asset")
#: Codecs (OpenCV FOURCC, lower case) the native viewer decodes without extra installs.
NATIVE_VIEWER_CODECS = frozenset({"av01"})
#: How series units are named in the layout, in the order their plots are stacked.
UNIT_TITLES = {"px": "pixels", "count": "count", "samples": "effective sample size",
               "log-likelihood": "log-likelihood", "probability": "label posterior"}
TEXT_LEVELS = ("CRITICAL", "ERROR", "WARN", "INFO", "DEBUG", "TRACE")
VIDEO_ASSET_SUFFIXES = (".mp4",)

#: Colour ramp for weights, from low (dim blue) to high (yellow), RGB.
_LOW_RGB = np.array([40.0, 90.0, 255.0])
_HIGH_RGB = np.array([255.0, 225.0, 0.0])


# ---------------------------------------------------------------------------
# Pure helpers
# ---------------------------------------------------------------------------


def weight_colors(weights: np.ndarray) -> np.ndarray:
    """RGBA colours that shade items by weight: heavier is brighter, yellower, more opaque.

    Parameters
    ----------
    weights : ndarray of shape (K,)
        Non-negative, finite weights (normalised or not; only ratios matter).  Pass
        ``np.exp(logw - logw.max())`` for log weights.

    Returns
    -------
    colors : ndarray of shape (K, 4), uint8
        The item with the largest weight gets alpha 255, a zero weight alpha 30.
    """
    w = np.asarray(weights, dtype=float)
    if w.ndim != 1:
        raise DataError(f"weights must have shape (K,), got shape {w.shape}")
    if w.size and (not np.all(np.isfinite(w)) or np.any(w < 0)):
        raise DataError("weights must be finite and non-negative")
    top = w.max() if w.size else 0.0
    r = w / top if top > 0 else np.ones_like(w)
    rgb = _LOW_RGB + r[:, None] * (_HIGH_RGB - _LOW_RGB)
    alpha = 30.0 + 225.0 * r
    return np.rint(np.column_stack([rgb, alpha])).astype(np.uint8)


def histogram_image(matrix: np.ndarray) -> np.ndarray:
    """Colour a time × bins matrix as an image, each row scaled to its own maximum.

    Row-wise scaling keeps every frame visible whatever its total count, so that a
    second mode shows as a second bright ridge.

    Parameters
    ----------
    matrix : ndarray of shape (T, B)
        Non-negative counts or weights; row ``t`` is frame ``t``.

    Returns
    -------
    image : ndarray of shape (T, B, 3), uint8
        RGB image (viridis colour map); rows whose maximum is 0 are the map's darkest
        colour.
    """
    import cv2

    bgr = cv2.applyColorMap(histogram_grey(matrix), cv2.COLORMAP_VIRIDIS)
    return np.ascontiguousarray(bgr[..., ::-1])


def histogram_grey(matrix: np.ndarray) -> np.ndarray:
    """The grey levels of :func:`histogram_image`: each row of ``matrix`` (T, B) scaled to its
    own maximum, 0–255 as uint8 (rows whose maximum is 0 are 0).  Rows of grey levels are their
    own grey levels, so a long run can keep these (B bytes a frame) instead of the counts."""
    m = np.asarray(matrix, dtype=float)
    if m.ndim != 2 or m.shape[0] < 1 or m.shape[1] < 1:
        raise DataError(f"histogram matrix must have shape (T, B) with T, B >= 1, got {m.shape}")
    if not np.all(np.isfinite(m)) or np.any(m < 0):
        raise DataError("histogram matrix must be finite and non-negative")
    top = m.max(axis=1, keepdims=True)
    scaled = np.divide(m, top, out=np.zeros_like(m), where=top > 0)
    return np.rint(255.0 * scaled).astype(np.uint8)


def frame_storage(mode: str, *, codec: str, embeddable: bool, whole_clip: bool) -> tuple[str, str]:
    """Decide how a clip's frames go into a recording: ``("jpeg" | "asset", reason)``.

    Parameters
    ----------
    mode : {"auto", "jpeg", "asset"}
        The ``output.frames`` setting.  ``jpeg``: always JPEG frames (every viewer shows
        them).  ``asset``: embed the clip as an ``AssetVideo`` when Rerun accepts it (MP4 with
        H.264, H.265, VP9 or AV1), whatever viewer may have to decode it.  ``auto``: embed only
        a clip the native viewer decodes by itself (:data:`NATIVE_VIEWER_CODECS`, AV1).
    codec : str
        The clip's video codec as a FOURCC (``"vp09"``, ``"avc1"``, ``"av01"``; empty for
        image folders).
    embeddable : bool
        Whether Rerun accepts the file as an asset (see ``Video.is_rerun_video_asset``).
    whole_clip : bool
        Whether every frame of the clip is recorded; an asset embeds the whole file, so a
        selection is always stored as JPEG frames of the selected frames.
    """
    if mode not in FRAME_STORAGE:
        raise ConfigError(f"output.frames: expected one of {', '.join(FRAME_STORAGE)}, got {mode!r}")
    if mode == "jpeg":
        return "jpeg", "output.frames is jpeg"
    if not embeddable:
        return "jpeg", "the clip is not an MP4 Rerun can embed"
    if not whole_clip:
        return "jpeg", "only part of the clip is recorded (an asset would embed all of it)"
    c = codec.strip().lower()
    if mode == "auto" and c not in NATIVE_VIEWER_CODECS:
        return "jpeg", (f"codec {c or '?'} needs FFmpeg or a web viewer to play in Rerun; "
                        "set output.frames: asset to embed it anyway")
    return "asset", f"codec {c or '?'} embedded as a video asset"


def make_blueprint(kind: str | None, content: Mapping[str, Any] | None = None) -> Any:
    """The saved layout for a command: ``"track"``, ``"draw"``, ``"simulate"`` or None.

    - ``track``: a large 2-D view of ``video`` with its overlays; beside it the time series,
      one plot per unit, above tabs for the translation histogram (bar chart and over-time
      image), the parameters and the text log.
    - ``draw``: the 2-D view only.
    - ``simulate``: the 2-D view and the time series.

    Parameters
    ----------
    kind : str or None
    content : mapping, optional
        What was logged (see :meth:`Recording.content`): ``series`` (a mapping of unit, or
        None, to entity paths) and ``roots`` (top-level entities with data).  Views without
        data are left out.  None: every view of the layout.

    Returns a ``rerun.blueprint.Blueprint``, or None when ``kind`` is None (the viewer
    then lays the recording out by itself).
    """
    if kind is None:
        return None
    if kind not in BLUEPRINTS:
        raise ConfigError(f"unknown blueprint {kind!r}; valid: {', '.join(BLUEPRINTS)} or None")
    import rerun.blueprint as rrb

    image_view = rrb.Spatial2DView(origin=VIDEO, name="video")
    if kind == "draw":
        return rrb.Blueprint(image_view)
    if content is None:
        series_views = [rrb.TimeSeriesView(origin=SERIES, name="time series")]
        roots = {HISTOGRAM, PARAMS, TEXT_LOG}
    else:
        series_views = _series_views(content.get("series", {}))
        roots = set(content.get("roots", ()))
    if kind == "simulate":
        if not series_views:
            return rrb.Blueprint(image_view)
        side = series_views[0] if len(series_views) == 1 else rrb.Vertical(*series_views)
        return rrb.Blueprint(rrb.Horizontal(image_view, side, column_shares=[1, 1]))
    tabs = []
    if HISTOGRAM in roots:
        tabs += [rrb.BarChartView(origin=HISTOGRAM, name="histogram"),
                 rrb.Spatial2DView(origin=HISTOGRAM, name="histogram over time")]
    if PARAMS in roots:
        tabs.append(rrb.TextDocumentView(origin=PARAMS, name="parameters"))
    if LABELS in roots:
        tabs.insert(0, rrb.Spatial2DView(origin=LABELS, name="labels over time"))
    if TEXT_LOG in roots:
        tabs.append(rrb.TextLogView(origin=TEXT_LOG, name="log"))
    side_parts = [*series_views] + ([rrb.Tabs(*tabs)] if tabs else [])
    if not side_parts:
        return rrb.Blueprint(image_view)
    side = side_parts[0] if len(side_parts) == 1 else rrb.Vertical(*side_parts)
    return rrb.Blueprint(rrb.Horizontal(image_view, side, column_shares=[3, 2]))


def _series_views(series: Mapping[str | None, Sequence[str]]) -> list[Any]:
    """One time-series plot per unit (known units first, in :data:`UNIT_TITLES` order)."""
    import rerun.blueprint as rrb

    views = []
    known = [u for u in UNIT_TITLES if series.get(u)]
    other = sorted(u for u in series if u is not None and u not in UNIT_TITLES and series[u])
    for unit in known + other:
        entities = list(series[unit])
        views.append(rrb.TimeSeriesView(origin=SERIES, contents=[f"/{e.strip('/')}" for e in entities],
                                        name=UNIT_TITLES.get(unit, unit)))
    for entity in series.get(None, ()):  # series without a unit: a plot each
        name = entity.strip("/").split("/", 1)[-1]
        views.append(rrb.TimeSeriesView(origin=f"/{entity.strip('/')}", name=name))
    return views


def _points(value: Any, name: str, *, leading: int | None = None) -> np.ndarray:
    """Validate an array of 2-D points of shape (..., 2) and return it as float32."""
    a = np.asarray(value, dtype=np.float32)
    if a.ndim < 1 or a.shape[-1] != 2:
        raise DataError(f"{name} must have shape (..., 2) in (x, y) order, got shape {a.shape}")
    if leading is not None and a.ndim != leading + 1:
        raise DataError(
            f"{name} must have {leading + 1} dimensions ending in 2, got shape {a.shape}"
        )
    return a


def _nbytes(value: Any) -> int:
    """The size of a held component's data, roughly (arrays and byte strings exactly)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, (bytes, str)):
        return len(value)
    if isinstance(value, (list, tuple)):
        return sum(_nbytes(v) for v in value)
    return 8


def _strips_arrow(blocks: Sequence[np.ndarray]) -> Any:
    """Line strips as the Arrow array of Rerun's ``LineStrip2D`` batch.

    ``blocks`` are float32 arrays of shape (K, n, 2): K strips of n points each (the K
    particle contours of a frame, say), in order.  Built from one buffer of points and the
    strips' offsets; Rerun's own conversion takes each strip separately, twenty times slower
    for the particle contours of a frame.
    """
    import pyarrow as pa
    from rerun.components import LineStrip2DBatch

    kind = LineStrip2DBatch._ARROW_DATATYPE
    lengths = (np.concatenate([np.full(b.shape[0], b.shape[1], np.int32) for b in blocks]) if len(blocks)
               else np.zeros(0, np.int32))
    offsets = np.zeros(lengths.size + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    flat = (np.concatenate([np.asarray(b, dtype=np.float32).reshape(-1) for b in blocks]) if len(blocks)
            else np.zeros(0, np.float32))
    points = pa.FixedSizeListArray.from_arrays(pa.array(flat, type=pa.float32()), type=kind.value_type)
    return pa.ListArray.from_arrays(pa.array(offsets), points, type=kind)


def _tensors_arrow(rows: Sequence[np.ndarray]) -> Any:
    """1-D tensors (one per row, as float64) as the Arrow array of Rerun's ``TensorData`` batch.

    Rerun's Python side converts one tensor per call only; bar charts sent as columns need
    the batch, built here from the same Arrow type (shape, no names, an ``F64`` buffer).
    """
    import pyarrow as pa
    from rerun.components import TensorDataBatch

    kind = TensorDataBatch._ARROW_DATATYPE
    union = kind.field("buffer").type
    n = len(rows)
    values = [np.asarray(r, dtype=np.float64).reshape(-1) for r in rows]
    lengths = np.fromiter((v.size for v in values), dtype=np.int64, count=n)
    shape = pa.ListArray.from_arrays(pa.array(np.arange(n + 1, dtype=np.int32)),
                                     pa.array(lengths.astype(np.uint64), type=pa.uint64()),
                                     type=kind.field("shape").type)
    offsets = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    flat = np.concatenate(values) if n else np.zeros(0)
    children, code = [], None
    for i in range(union.num_fields):
        field = union.field(i)
        if field.name == "F64":
            children.append(pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, type=pa.float64()),
                                                     type=field.type))
            code = union.type_codes[i]
        else:
            children.append(pa.array([], type=field.type))
    buffer = pa.Array.from_buffers(union, n, [None, pa.py_buffer(np.full(n, code, np.int8)),
                                              pa.py_buffer(np.arange(n, dtype=np.int32))], children=children)
    return pa.StructArray.from_arrays([shape, pa.nulls(n, type=kind.field("names").type), buffer],
                                      fields=[kind.field(i) for i in range(kind.num_fields)])


def _color(value: Any, name: str = "color") -> np.ndarray:
    """Validate one RGB or RGBA colour given as integers 0–255."""
    c = np.asarray(value)
    if c.shape not in ((3,), (4,)) or np.any(c < 0) or np.any(c > 255):
        raise DataError(f"{name} must be 3 or 4 integers in 0..255 (RGB or RGBA), got {value!r}")
    return c.astype(np.uint8)


def _flatten(params: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested mappings to dotted keys with values Rerun's AnyValues accepts."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{name}."))
        elif value is None:
            continue
        elif isinstance(value, int) and not isinstance(value, bool) and not -2**63 <= value < 2**63:
            flat[name] = str(value)  # beyond int64 (e.g. a seed of 2**70): kept exactly, as text
        elif isinstance(value, (bool, int, float, str)):
            flat[name] = value
        elif isinstance(value, np.generic):
            flat[name] = value.item()
        elif isinstance(value, (np.ndarray, list, tuple)):
            arr = np.asarray(value)
            items = arr.ravel()
            flat[name] = items.tolist() if arr.dtype.kind in "biuf" else [str(v) for v in items]
        else:
            flat[name] = str(value)
    return flat


def _plain(value: Any) -> Any:
    """Convert numpy values and paths to plain Python for YAML output."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


# ---------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------


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

    def __init__(self, recording: Recording, entity: str, quality: int,
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


# ---------------------------------------------------------------------------
# The recording
# ---------------------------------------------------------------------------


class Recording:
    """One ``.rrd`` file written atomically; use as a context manager.

    Parameters
    ----------
    path : str or Path
        Output file (conventionally ``*.rrd``).  Missing parent folders are created.
    app_id : str
        Rerun application id; recordings with the same id share blueprints in the viewer.
    recording_id : str, optional
        A readable name for the run (e.g. ``CLIP-TRACKER-seedS``): shown as the recording's
        name in the viewer and used as the prefix of its id.  The id itself always ends in a
        random suffix, so two runs opened together never merge into one recording.
    properties : mapping, optional
        Recording properties (``trackcli`` in the viewer's recording properties), e.g. the
        seed; flat keys, values Rerun's ``AnyValues`` accepts.
    blueprint : {"track", "draw", "simulate"} or None
        Saved layout, see :func:`make_blueprint`.

    Notes
    -----
    Every ``log_*`` method logs at the time set by the last :meth:`set_frame`, except the
    ones documented as static.  Colours are RGB or RGBA integers 0–255; widths and radii
    are in image pixels.

    Reproducibility: the same calls give a recording with the same content
    (``rerun rrd compare`` finds no difference): chunks are cut by size only, never by a
    timer, and no wall-clock start time is stored.  The bytes still differ from run to run,
    because Rerun stamps every chunk and row id (TUID) with the wall-clock time it was made
    and the recording id is unique.
    """

    def __init__(self, path: str | os.PathLike[str], *, app_id: str = "trackcli",
                 recording_id: str | None = None, blueprint: str | None = None,
                 properties: Mapping[str, Any] | None = None) -> None:
        self.path = Path(path)
        if self.path.name in ("", ".", ".."):
            raise ConfigError(f"recording path {str(path)!r} does not name a file")
        self.tmp_path = self.path.with_name(f".{self.path.name}.part")
        self.app_id = app_id
        self.name = recording_id
        self.recording_id = f"{recording_id or 'trackcli'}-{uuid.uuid4().hex}"
        self.properties = dict(properties or {})
        make_blueprint(blueprint)  # validates the name early
        self._kind = blueprint
        self._stream: Any = None
        self._styled: set[str] = set()
        self._series: dict[str | None, list[str]] = {}
        self._roots: set[str] = set()
        self._bar_edges: dict[str, np.ndarray] = {}
        self._frame: tuple[int, float] | None = None
        self._batch: dict[tuple[str, str, tuple[str, ...]], list[tuple[int, float, tuple]]] | None = None

    # -- lifecycle ---------------------------------------------------------

    def __enter__(self) -> Recording:
        import rerun as rr

        if self._stream is not None:
            raise TrackcliError(f"recording {self.path} is already open")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.tmp_path, "wb"):  # fail here, with a clear message, if it cannot be written
                pass
        except OSError as exc:
            raise InputError(f"{self.path}: cannot write recording ({exc.strerror or exc})") from None
        stream = None
        try:
            # chunks cut by size only (no timer): the same calls give the same chunks
            batcher = rr.ChunkBatcherConfig(flush_tick=timedelta(days=1), flush_num_bytes=1 << 20)
            stream = rr.RecordingStream(self.app_id, recording_id=self.recording_id, send_properties=False,
                                        batcher_config=batcher)
            if not stream.is_enabled():
                raise TrackcliError(
                    f"cannot write recording {self.path}: Rerun logging is disabled "
                    "(RERUN=off in the environment?)"
                )
            if os.environ.get(PANDAS_CHECK_ENV, "1") == "0":
                skip_pandas_check()
            stream.set_log_time_enabled(False)
            try:
                stream.save(self.tmp_path)
            except RuntimeError as exc:  # e.g. the folder is not writable
                raise InputError(f"{self.path}: cannot write recording ({exc})") from None
            self._stream = stream
            if self.name:
                stream.send_recording_name(self.name)
            flat = _flatten(self.properties)
            if flat:
                import pyarrow as pa

                # explicit Arrow arrays: Rerun would otherwise fix each key's type for the whole
                # process on first use, and a "seed" of another type elsewhere would be dropped
                stream.send_property("trackcli", rr.AnyValues(**{k: pa.array(v if isinstance(v, list) else [v])
                                                                  for k, v in flat.items()}))
        except BaseException:
            self._stream = None
            if stream is not None:
                with contextlib.suppress(Exception):
                    stream.disconnect()
            self.tmp_path.unlink(missing_ok=True)
            raise
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        stream = self._stream
        if stream is None:
            return
        try:
            try:
                if exc_type is None:
                    self.flush_overlays(last=True)
                    if self._kind is not None:
                        stream.send_blueprint(make_blueprint(self._kind, self.content()), make_active=True,
                                              make_default=True)
            finally:
                self._stream, self._batch = None, None
                stream.disconnect()
            if exc_type is None:
                if not self.tmp_path.exists():
                    raise TrackcliError(f"Rerun wrote nothing for recording {self.path}")
                os.replace(self.tmp_path, self.path)
        except BaseException:
            self.tmp_path.unlink(missing_ok=True)
            raise
        if exc_type is not None:
            self.tmp_path.unlink(missing_ok=True)

    def content(self) -> dict[str, Any]:
        """What has been logged so far, for :func:`make_blueprint`.

        ``series``: unit (or None) → series entities, in logging order; ``roots``: the
        top-level entities that received data (``video``, ``histogram``, ``params``, ``log`` …).
        """
        return {"series": {u: list(e) for u, e in self._series.items()}, "roots": sorted(self._roots)}

    def _note(self, entity: str) -> None:
        self._roots.add(entity.strip("/").split("/", 1)[0])

    def _note_series(self, entity: str, unit: str | None) -> None:
        self._note(entity)
        for u, entities in self._series.items():
            if entity in entities:
                if u != unit:
                    raise DataError(f"{entity}: logged with unit {u!r} before, now {unit!r}")
                return
        self._series.setdefault(unit, []).append(entity)

    @property
    def stream(self) -> Any:
        """The underlying ``rerun.RecordingStream`` (only inside the ``with`` block)."""
        if self._stream is None:
            raise TrackcliError(f"recording {self.path} is not open; use it in a 'with' block")
        return self._stream

    # -- time --------------------------------------------------------------

    def set_frame(self, index: int, time_s: float) -> None:
        """Set the ``frame`` (sequence) and ``video_time`` (seconds) timelines."""
        if int(index) != index or index < 0:
            raise DataError(f"frame index must be a non-negative integer, got {index!r}")
        if not np.isfinite(time_s):
            raise DataError(f"frame time must be finite, got {time_s!r}")
        self.stream.set_time("frame", sequence=int(index))
        self.stream.set_time("video_time", duration=float(time_s))
        self._frame = (int(index), float(time_s))

    # -- batches of frames ---------------------------------------------------

    def batch_overlays(self) -> None:
        """From now on, hold the per-frame images and overlays and send them as columns.

        :meth:`log_frame`, :meth:`log_contour`, :meth:`log_contours`, :meth:`log_points`
        and :meth:`log_segments` then keep their data, at the time of the last
        :meth:`set_frame`, until :meth:`flush_overlays` sends each entity's rows with one
        ``send_columns`` call.  The recording holds the same rows as when they are logged
        one by one (the same components at the same times); building one archetype per
        call and frame cost more than a millisecond per frame of Python.
        """
        if self._batch is None:
            self._batch = {}

    def flush_overlays(self, *, last: bool = False, min_bytes: int = 0, max_rows: int = 0) -> None:
        """Send the rows held since :meth:`batch_overlays` (or the last flush).

        With ``last``, send everything and go back to logging every call at once.  Otherwise
        an entity's rows are sent once they hold at least ``min_bytes`` of data or
        ``max_rows`` rows (either 0: no limit of that kind), and kept otherwise.  Every send
        makes a chunk, and the recording's file writer keeps about a kilobyte of every chunk
        in memory until the file is closed: holding the light entities (a centroid, a
        histogram) for more frames than the images keeps that growth small.
        """
        if last or (min_bytes <= 0 and max_rows <= 0):
            batch, self._batch = self._batch, (None if last else {})
        else:
            batch = {}
            for key, rows in list((self._batch or {}).items()):
                if ((max_rows > 0 and len(rows) >= max_rows)
                        or (min_bytes > 0 and sum(_nbytes(row[2]) for row in rows) >= min_bytes)):
                    batch[key] = self._batch.pop(key)
        if not batch:
            return
        import rerun as rr

        for (entity, kind, names), rows in batch.items():
            archetype = getattr(rr, kind)
            frames = np.fromiter((r[0] for r in rows), dtype=np.int64, count=len(rows))
            times = np.fromiter((r[1] for r in rows), dtype=float, count=len(rows))
            values: dict[str, Any] = {}
            lengths: dict[str, Any] = {}
            for j, name in enumerate(names):
                parts = [r[2][j] for r in rows]
                if name in ("blob", "media_type"):  # one per row
                    values[name], lengths[name] = parts, np.ones(len(parts), int)
                elif name in ("values", "abscissa"):  # one 1-D tensor per row
                    values[name], lengths[name] = _tensors_arrow(parts), np.ones(len(parts), int)
                else:
                    lengths[name] = [len(v) for v in parts]
                    if name == "strips":
                        values[name] = _strips_arrow(parts)
                    elif name == "colors":  # RGB and RGBA rows together: RGB is RGBA with alpha 255
                        values[name] = np.concatenate(
                            [v if v.shape[-1] == 4 else np.concatenate([v, np.full((len(v), 1), 255, np.uint8)], axis=1)
                             for v in parts])
                    else:
                        values[name] = np.concatenate(parts)
            # one call for all components (some archetypes check one against another), then
            # each component cut into the rows by its own lengths
            columns = [col.partition(lengths[col.component_descriptor().component.rsplit(":", 1)[-1]])
                       for col in archetype.columns(**values)]
            self.stream.send_columns(entity, indexes=[rr.TimeColumn("frame", sequence=frames),
                                                      rr.TimeColumn("video_time", duration=times)],
                                     columns=columns)

    def _emit(self, entity: str, kind: str, **components: Any) -> None:
        """Log one archetype (``rr.<kind>``) now, or hold it for the batch (components not None)."""
        import rerun as rr

        if self._batch is None or self._frame is None:
            if "strips" in components:
                components["strips"] = _strips_arrow([components["strips"]])
            self.stream.log(entity, getattr(rr, kind).from_fields(**components))
            return
        names = tuple(k for k, v in components.items() if v is not None)
        self._batch.setdefault((entity, kind, names), []).append(
            (self._frame[0], self._frame[1], tuple(components[k] for k in names)))

    # -- frames ------------------------------------------------------------

    def log_video_asset(self, video_path: str | os.PathLike[str], *,
                        entity: str = VIDEO) -> np.ndarray:
        """Embed a video file once (static ``AssetVideo``) and return its frame timestamps.

        Rerun accepts MP4 with H.264, H.265, VP9 or AV1; it rejects MPEG-4 part 2
        (``mp4v``), AVI and MKV with a ``RuntimeError`` before anything is logged.

        Returns
        -------
        timestamps_ns : ndarray of shape (F,), int64
            Presentation time of each frame in nanoseconds, in decoding order (the order
            OpenCV reads them).
        """
        import rerun as rr

        asset = rr.AssetVideo(path=Path(video_path))
        timestamps = np.asarray(asset.read_frame_timestamps_nanos(), dtype=np.int64)
        self._note(entity)
        self.stream.log(entity, asset, static=True)
        return timestamps

    def log_frame_ref(self, ts_ns: int, *, entity: str = VIDEO) -> None:
        """Show the asset's frame at presentation time ``ts_ns`` (nanoseconds)."""
        import rerun as rr

        self.stream.log(entity, rr.VideoFrameReference(nanoseconds=int(ts_ns)))

    def log_frame(self, image_bgr: np.ndarray, *, quality: int = 85, entity: str = VIDEO) -> None:
        """Log an image as JPEG (``EncodedImage``).

        Parameters
        ----------
        image_bgr : ndarray of shape (H, W, 3) or (H, W), uint8
            Colour image in OpenCV's BGR order, or grayscale.
        quality : int
            JPEG quality 1–100.
        """
        import cv2

        img = np.asarray(image_bgr)
        shape_ok = img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (1, 3))
        if img.dtype != np.uint8 or not shape_ok:
            raise DataError(
                f"frame must be a uint8 array of shape (H, W) or (H, W, 3), "
                f"got {img.dtype} of shape {img.shape}"
            )
        q = _check_quality(quality)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, q])
        if not ok:
            raise DataError(f"JPEG encoding failed for a frame of shape {img.shape}")
        self.log_jpeg(buf.tobytes(), entity=entity)

    def log_jpeg(self, data: bytes, *, entity: str = VIDEO) -> None:
        """Log a frame that is JPEG already (``EncodedImage``), as it is."""
        self._note(entity)
        self._emit(entity, "EncodedImage", blob=bytes(data), media_type="image/jpeg")

    def frame_logger(self, video_path: str | os.PathLike[str] | None, *, quality: int = 85,
                     entity: str = VIDEO, keep_jpeg: bool = False) -> FrameLogger:
        """Choose how frames are stored: embedded video when possible, JPEG otherwise.

        An ``.mp4`` whose codec Rerun supports (H.264, VP9 …) is embedded once, byte for
        byte, as an ``AssetVideo``: the recording grows by the clip's size (usually a
        fraction of the JPEG frames) and logging a frame costs ~0.03 ms instead of
        ~0.6 ms.  For anything else (image folders, AVI, ``mp4v``, None) or on any
        error, frames are JPEG-encoded; with ``keep_jpeg``, a frame that comes with its
        source's JPEG (an image folder of JPEGs, an MJPG video) is stored as that JPEG, not
        encoded again (no second loss of quality, and no encoding time: 0.5 ms a
        320×240 frame).
        """
        q = _check_quality(quality)
        timestamps = None
        if video_path is not None and Path(video_path).suffix.lower() in VIDEO_ASSET_SUFFIXES:
            try:
                timestamps = self.log_video_asset(video_path, entity=entity)
            except Exception as exc:  # any rejection means: fall back to JPEG
                log.info("storing frames as JPEG: %s cannot be embedded (%s)", video_path, exc)
            else:
                if timestamps.size == 0:
                    log.info("storing frames as JPEG: %s has no frames Rerun can index", video_path)
                    timestamps = None
        return FrameLogger(self, entity, q, timestamps, keep_jpeg=keep_jpeg)

    # -- 2-D overlays --------------------------------------------------------

    def log_contour(self, entity: str, points: np.ndarray, color: Sequence[int] = (255, 64, 0),
                    width: float = 2.0, *, closed: bool = True) -> None:
        """Draw one curve through ``points``.

        Parameters
        ----------
        points : ndarray of shape (M, 2)
            Curve samples in image coordinates (x, y).
        width : float
            Line width in image pixels.
        closed : bool
            Join the last point back to the first.
        """
        pts = _points(points, "points", leading=1)
        if closed and len(pts) > 1:
            pts = np.concatenate([pts, pts[:1]])
        self._emit(entity, "LineStrips2D", strips=pts[None], colors=_color(color)[None],
                   radii=np.array([_half_width(width)], np.float32))

    def log_contours(self, entity: str, curves: np.ndarray, weights: np.ndarray | None = None,
                     width: float = 1.0, *, closed: bool = True) -> None:
        """Draw K curves shaded by weight (see :func:`weight_colors`), heaviest on top.

        Parameters
        ----------
        curves : ndarray of shape (K, M, 2)
            Curve samples in image coordinates.
        weights : ndarray of shape (K,), optional
            Non-negative weights; equal weights if None.
        """
        c = _points(curves, "curves", leading=2)
        k = c.shape[0]
        w = np.ones(k) if weights is None else np.asarray(weights, dtype=float)
        if w.shape != (k,):
            raise DataError(f"weights must have shape ({k},) to match curves, got {w.shape}")
        colors = weight_colors(w)
        order = np.argsort(w, kind="stable")
        c, colors = c[order], colors[order]
        if closed and c.shape[1] > 1:
            c = np.concatenate([c, c[:, :1]], axis=1)
        self._emit(entity, "LineStrips2D", strips=c, colors=colors, radii=np.array([_half_width(width)], np.float32))

    def log_points(self, entity: str, pts: np.ndarray, colors: Any = None,
                   radii: float | np.ndarray | None = None) -> None:
        """Draw P points (features, particle centroids …).

        Parameters
        ----------
        pts : ndarray of shape (P, 2)
            Positions in image coordinates.
        colors : ndarray of shape (P, 3 or 4) or one colour, optional
            E.g. ``weight_colors(w)``.
        radii : float or ndarray of shape (P,), optional
            In image pixels.
        """
        p = _points(pts, "pts", leading=1)
        if colors is not None:
            col = np.asarray(colors)
            if col.ndim == 1:
                col = _color(col, "colors")
            elif col.shape != (len(p), col.shape[-1]) or col.shape[-1] not in (3, 4):
                raise DataError(f"colors must have shape ({len(p)}, 3 or 4), got {col.shape}")
            elif np.any(col < 0) or np.any(col > 255):
                raise DataError("colors must be integers in 0..255")
            colors = col.astype(np.uint8)
        if radii is not None:
            r = np.asarray(radii, dtype=np.float32)
            if r.ndim > 1 or (r.ndim == 1 and r.shape != (len(p),)) or np.any(r <= 0):
                raise DataError(f"radii must be positive, one value or shape ({len(p)},)")
            radii = r
        if colors is not None and colors.ndim == 1:
            colors = colors[None]
        if radii is not None and radii.ndim == 0:
            radii = radii[None]
        self._emit(entity, "Points2D", positions=p, colors=colors, radii=radii)

    def log_segments(self, entity: str, starts: np.ndarray, ends: np.ndarray,
                     color: Sequence[int] = (0, 200, 255), width: float = 1.0) -> None:
        """Draw K straight segments, e.g. the measurement lines along the curve normals.

        Parameters
        ----------
        starts, ends : ndarray of shape (K, 2)
            End points in image coordinates.
        """
        a = _points(starts, "starts", leading=1)
        b = _points(ends, "ends", leading=1)
        if a.shape != b.shape:
            raise DataError(
                f"starts and ends must have the same shape, got {a.shape} and {b.shape}"
            )
        self._emit(entity, "LineStrips2D", strips=np.stack([a, b], axis=1), colors=_color(color)[None],
                   radii=np.array([_half_width(width)], np.float32))

    # -- time series ---------------------------------------------------------

    def log_scalar(self, entity: str, value: float | Sequence[float], *,
                   names: str | Sequence[str] | None = None,
                   colors: Any = None, unit: str | None = None) -> None:
        """Log one value (or k values, one line each) at the current frame.

        ``names``/``colors`` style the lines; they are logged once per entity (static).
        ``unit`` (e.g. ``"px"``) groups the series into one plot with the others of that
        unit; series without a unit get a plot each.
        """
        import rerun as rr

        v = np.atleast_1d(np.asarray(value, dtype=float))
        if v.ndim != 1:
            raise DataError(f"a scalar sample must be one value or shape (k,), got shape {v.shape}")
        self._style(entity, names, colors, v.size)
        self._note_series(entity, unit)
        self.stream.log(entity, rr.Scalars(v))

    def send_series(self, entity: str, frames: np.ndarray, times: np.ndarray, values: np.ndarray, *,
                    names: str | Sequence[str] | None = None, colors: Any = None,
                    unit: str | None = None) -> None:
        """Send a whole time series at once (``send_columns``; far faster than per frame).

        Parameters
        ----------
        frames : ndarray of shape (T,), int
            Frame indices (the ``frame`` timeline).
        times : ndarray of shape (T,), float
            Seconds (the ``video_time`` timeline).
        values : ndarray of shape (T,) or (T, k)
            One line, or k lines plotted together (e.g. ``tx`` and ``ty``).
        names : str or sequence of k str, optional
            Legend names; with ``colors`` (k RGB(A) colours) logged once, static.
        unit : str, optional
            Groups the series into one plot with the others of that unit (see
            :meth:`log_scalar`).
        """
        import rerun as rr

        f = np.asarray(frames)
        t = np.asarray(times, dtype=float)
        v = np.asarray(values, dtype=float)
        n = f.shape[0] if f.ndim == 1 else -1
        if f.ndim != 1 or not np.issubdtype(f.dtype, np.integer):
            raise DataError(
                f"frames must be integers of shape (T,), got {f.dtype} of shape {f.shape}"
            )
        if t.shape != (n,):
            raise DataError(f"times must have shape ({n},) to match frames, got {t.shape}")
        if v.ndim not in (1, 2) or v.shape[0] != n:
            raise DataError(f"values must have shape ({n},) or ({n}, k), got {v.shape}")
        if not np.all(np.isfinite(t)):
            raise DataError("times must be finite")
        k = 1 if v.ndim == 1 else v.shape[1]
        self._style(entity, names, colors, k)
        if n == 0:
            return
        self._note_series(entity, unit)
        column = rr.Scalars.columns(scalars=v.reshape(-1)).partition(np.full(n, k))
        self.stream.send_columns(
            entity,
            indexes=[rr.TimeColumn("frame", sequence=f.astype(np.int64)),
                     rr.TimeColumn("video_time", duration=t)],
            columns=column,
        )

    def _style(self, entity: str, names: Any, colors: Any, k: int) -> None:
        """Log static ``SeriesLines`` names/colours the first time an entity gets them."""
        if (names is None and colors is None) or entity in self._styled:
            return
        import rerun as rr

        if names is not None:
            names = [names] if isinstance(names, str) else [str(s) for s in names]
            if len(names) != k:
                raise DataError(f"{entity}: {len(names)} names given for {k} lines")
        if colors is not None:
            col = np.asarray(colors)
            col = col[None] if col.ndim == 1 else col
            if col.ndim != 2 or col.shape[0] != k:
                raise DataError(
                    f"{entity}: colors must be {k} RGB(A) colours, got shape {col.shape}"
                )
            colors = np.stack([_color(c, "colors") for c in col])
        self.stream.log(entity, rr.SeriesLines(names=names, colors=colors), static=True)
        self._styled.add(entity)

    # -- histograms ----------------------------------------------------------

    def log_histogram(self, entity: str, counts: np.ndarray, x_edges: np.ndarray | None = None, *,
                      color: Sequence[int] | None = None) -> None:
        """Log a bar chart for the current frame.

        Parameters
        ----------
        counts : ndarray of shape (B,)
            Bar heights (counts or summed weights).
        x_edges : ndarray of shape (B + 1,), optional
            Bin edges; bars are placed at the bin centres with the bin widths.  Bars are
            at 0..B-1 if None.
        """
        c = np.asarray(counts, dtype=float)
        if c.ndim != 1:
            raise DataError(f"counts must have shape (B,), got {c.shape}")
        kwargs: dict[str, Any] = {}
        if x_edges is not None:
            e = _edges(x_edges, c.shape[0])
            # the bins' places and widths are logged again only when they change (the viewer
            # shows the latest ones): converting them took half the time of every frame's chart
            if not np.array_equal(self._bar_edges.get(entity), e):
                kwargs["abscissa"] = 0.5 * (e[:-1] + e[1:])
                kwargs["widths"] = np.diff(e).astype(np.float32)
                self._bar_edges[entity] = e
        if color is not None:
            kwargs["color"] = _color(color)[None]
        self._note(entity)
        self._emit(entity, "BarChart", values=c, **kwargs)

    def log_histogram_image(self, entity: str, matrix: np.ndarray, x_edges: np.ndarray, *,
                            first_frame: int = 0) -> None:
        """Log the static "histogram over time" heat-map (see :func:`histogram_image`).

        Row ``t`` is frame ``first_frame + t`` and runs down the image; column ``j`` is bin
        ``j``.  A transform places the image so that its 2-D coordinates read directly as
        (bin value, frame): pixel column ``j`` covers ``x_edges[j]..x_edges[j+1]``.  The
        edges are also stored on the entity (``x_edges``).

        Parameters
        ----------
        matrix : ndarray of shape (T, B)
            Non-negative counts per frame and bin.
        x_edges : ndarray of shape (B + 1,)
            Equally spaced bin edges.
        """
        import rerun as rr

        img = histogram_image(matrix)
        e = _edges(x_edges, img.shape[1])
        step = np.diff(e)
        if not np.allclose(step, step[0], rtol=1e-6, atol=0.0):
            raise DataError("x_edges must be equally spaced for the histogram image")
        # Rerun reads an image one row high as having one channel: a one-frame heat-map is
        # stored as two rows of half a frame each
        rows_per_frame = 2 if img.shape[0] == 1 else 1
        img = np.repeat(img, rows_per_frame, axis=0)
        self._note(entity)
        self.stream.log(entity, rr.Image(img, color_model="RGB"), static=True)
        self.stream.log(entity, rr.Transform3D(translation=[float(e[0]), float(first_frame), 0.0],
                                               scale=[float(step[0]), 1.0 / rows_per_frame, 1.0]), static=True)
        self.stream.log(entity, rr.AnyValues(x_edges=e.tolist(), first_frame=int(first_frame)),
                        static=True)

    def log_label_strip(self, entity: str, posterior: np.ndarray, names: Sequence[str], *,
                        first_frame: int = 0, row_height: int = 12) -> None:
        """Log the static label strip of a mixed-state run: one band per label, one column per
        frame, brighter where the label's posterior probability is higher (viridis: dark 0,
        yellow 1).  Pixel column ``t`` is frame ``first_frame + t``; the label names are stored
        on the entity (``labels``, top to bottom).

        Parameters
        ----------
        posterior : ndarray of shape (T, L)
            Per frame the posterior probability of each of the ``L`` labels.
        """
        import cv2
        import rerun as rr

        P = np.asarray(posterior, dtype=float)
        if P.ndim != 2 or P.shape[1] != len(names) or P.shape[0] < 1:
            raise DataError(f"posterior must have shape (T, {len(names)}), got {P.shape}")
        P = np.clip(np.nan_to_num(P, nan=0.0), 0.0, 1.0)
        grey = np.rint(255 * P.T).astype(np.uint8)  # (L, T)
        colour = cv2.applyColorMap(np.repeat(grey, row_height, axis=0), cv2.COLORMAP_VIRIDIS)[..., ::-1]
        self._note(entity)
        self.stream.log(entity, rr.Image(np.ascontiguousarray(colour), color_model="RGB"), static=True)
        self.stream.log(entity, rr.Transform3D(translation=[float(first_frame), 0.0, 0.0]), static=True)
        self.stream.log(entity, rr.AnyValues(labels=list(names), first_frame=int(first_frame)), static=True)

    # -- text ----------------------------------------------------------------

    def log_params(self, entity: str, params: Mapping[str, Any]) -> None:
        """Store the run's settings (static): as ``AnyValues`` and as a YAML document.

        Nested mappings become dotted keys (``dynamics.beta``); None values are left out
        of the ``AnyValues`` but kept in the YAML text.
        """
        import rerun as rr
        import yaml

        if not isinstance(params, Mapping):
            raise DataError(f"params must be a mapping, got {type(params).__name__}")
        text = yaml.safe_dump(_plain(params), sort_keys=False, default_flow_style=False)
        self._note(entity)
        self.stream.log(entity, rr.TextDocument(f"```yaml\n{text}```", media_type="text/markdown"),
                        static=True)
        flat = _flatten(params)
        if flat:
            self.stream.log(entity, rr.AnyValues(**flat), static=True)

    def log_text(self, entity: str, text: str, level: str = "INFO") -> None:
        """Log a message at the current frame, with a level from :data:`TEXT_LEVELS`."""
        import rerun as rr

        lv = str(level).upper()
        if lv not in TEXT_LEVELS:
            raise ConfigError(f"unknown text level {level!r}; valid: {', '.join(TEXT_LEVELS)}")
        self._note(entity)
        self.stream.log(entity, rr.TextLog(str(text), level=lv))


# ---------------------------------------------------------------------------
# Small validators
# ---------------------------------------------------------------------------


def _check_quality(quality: int) -> int:
    if isinstance(quality, bool) or int(quality) != quality or not 1 <= quality <= 100:
        raise ConfigError(f"JPEG quality must be an integer 1..100, got {quality!r}")
    return int(quality)


def _half_width(width: float) -> float:
    if not np.isfinite(width) or width <= 0:
        raise DataError(f"line width must be a positive number of pixels, got {width!r}")
    return 0.5 * float(width)


def _edges(x_edges: Any, bins: int) -> np.ndarray:
    e = np.asarray(x_edges, dtype=float)
    if e.shape != (bins + 1,):
        raise DataError(f"x_edges must have shape ({bins + 1},) for {bins} bins, got {e.shape}")
    if not np.all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
        raise DataError("x_edges must be finite and strictly increasing")
    return e


__all__ = [
    "BLUEPRINTS", "HISTOGRAM", "PARAMS", "SERIES", "TEXT_LEVELS", "TEXT_LOG", "VIDEO",
    "FrameLogger", "Recording", "histogram_grey", "histogram_image", "make_blueprint", "weight_colors",
]
