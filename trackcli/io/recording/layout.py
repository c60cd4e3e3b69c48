"""The layout of a recording: entity paths, colours, blueprints, and how frames are stored.

Pure helpers (no recording open): the colour ramp of weights, the histogram heat-map, the saved
layouts (blueprints) of each command and the choice of frame storage
(:func:`frame_storage`).  See :mod:`trackcli.io.recording` for the entity layout.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from trackcli.errors import ConfigError, DataError

VIDEO = "video"
SERIES = "series"
HISTOGRAM = "histogram"
PARAMS = "params"
TEXT_LOG = "log"
LABELS = "labels"

BLUEPRINTS = ("track", "draw", "simulate")
FRAME_STORAGE = ("auto", "av1", "jpeg", "asset")
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


def frame_storage(mode: str, *, codec: str, embeddable: bool, whole_clip: bool,
                  av1: bool | None = None) -> tuple[str, str]:
    """Decide how a clip's frames go into a recording: ``("av1" | "jpeg" | "asset", reason)``.

    Parameters
    ----------
    mode : {"auto", "av1", "jpeg", "asset"}
        The ``output.frames`` setting.  ``auto``: embed an AV1 MP4 recorded whole as it is
        (the native viewer decodes AV1 by itself, :data:`NATIVE_VIEWER_CODECS`), else encode
        the frames as AV1, else JPEG.  ``av1``: encode the frames as AV1 whatever the clip.
        ``jpeg``: JPEG frames (every viewer shows them).  ``asset``: embed the clip as an
        ``AssetVideo`` when Rerun accepts it (MP4 with H.264, H.265, VP9 or AV1), whatever
        viewer may have to decode it, else as ``auto``.
    codec : str
        The clip's video codec as a FOURCC (``"vp09"``, ``"avc1"``, ``"av01"``; empty for
        image folders).
    embeddable : bool
        Whether Rerun accepts the file as an asset (see ``Video.is_rerun_video_asset``).
    whole_clip : bool
        Whether every frame of the clip is recorded; an asset embeds the whole file, so a
        selection is never stored as one.
    av1 : bool, optional
        Whether the AV1 encoder is there (default: ask :mod:`trackcli.io.encode`).  Without
        it, ``auto`` and ``av1`` store JPEG frames.  The frame logger falls back to JPEG too
        when the frames are smaller than the encoder takes.
    """
    if mode not in FRAME_STORAGE:
        raise ConfigError(f"output.frames: expected one of {', '.join(FRAME_STORAGE)}, got {mode!r}")
    if mode == "jpeg":
        return "jpeg", "output.frames is jpeg"
    c = codec.strip().lower()
    if mode != "av1" and embeddable and whole_clip and (mode == "asset" or c in NATIVE_VIEWER_CODECS):
        return "asset", f"codec {c or '?'} embedded as a video asset"
    if av1 is None:
        from trackcli.io.encode import AV1_ENCODER, encoder_available

        av1 = encoder_available(AV1_ENCODER)
    if not av1:
        return "jpeg", "no AV1 encoder here (PyAV with libsvtav1: pip install av)"
    why = ("output.frames is av1" if mode == "av1" else
           "only part of the clip is recorded (an asset would embed all of it)" if embeddable and not whole_clip else
           "the clip is not an MP4 Rerun can embed" if not embeddable else
           f"codec {c or '?'} needs FFmpeg or a web viewer to play in Rerun; set output.frames: asset to embed it")
    return "av1", f"frames encoded as AV1 video ({why})"


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

