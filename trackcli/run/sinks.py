"""What happens to a run's results: sinks fed by the one frame loop.

:func:`feed` drives a tracker's results (the iterator of
:func:`trackcli.trackers.base.run_tracker`) into a list of :class:`Sink`: the track CSV
(:class:`TrackCsv`), the Rerun recording (:class:`RecordingSink`), an offline smoother and
its CSV (:class:`SmootherSink`), a progress bar (:class:`Progress`) and the run's counts
(:class:`Tally`).  A new output is one more sink: a class with the three methods of
:class:`Sink`, added to the list :func:`trackcli.run.clips.run_clip` builds.
"""

from __future__ import annotations

import array
import logging
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from trackcli.errors import DataError
from trackcli.io.tracks import DrawnBox, TrackWriter
from trackcli.run.outline_columns import OutlineColumns
from trackcli.run.background import BackgroundRecorder

log = logging.getLogger(__name__)

#: Colours (RGB) used in recordings.
ESTIMATE_RGB = (255, 60, 40)
GATE_RGB = (255, 210, 0)
FEATURE_RGB = (0, 200, 255)
SMOOTHED_RGB = (255, 0, 255)
OUTLINE_RGB = (60, 255, 60)
#: How far (pixels) a curve drawn in a recording may stray from the one computed: the estimate
#: and the smoothed curve (dense polygons of a spline, drawn 2 px wide) are stored by the few
#: points that keep them within this, a fifth of the points or fewer (Douglas-Peucker).
CURVE_TOLERANCE = 0.75
#: The same for the refined outline, which is traced along pixels: its steps of a pixel are
#: the raster, not the shape; within 1.5 px it keeps a quarter of its points.
OUTLINE_TOLERANCE = 1.5


class Sink:
    """A consumer of a run's results, one frame at a time.

    :func:`feed` calls, from the loop's thread and in the order the sinks are listed:

    - :meth:`frame` after each frame's step, with ``frame`` the decoded frame the tracker saw
      (``index``, ``time``, ``image`` BGR, and ``encoded``, its JPEG bytes, when its source
      kept them) and ``result`` the :class:`~trackcli.trackers.base.FrameResult` (its
      ``contour`` the estimate's curve, its ``outline`` the refined outline or None);
    - :meth:`finish` once after the last frame, when every frame was tracked: write what
      needs the whole clip (a smoother's pass, summary plots);
    - :meth:`close` last, always, with the exception that stopped the run or None: commit the
      files on None, remove them otherwise.

    A sink that writes files writes them atomically (:mod:`trackcli.io.outputs`): nothing
    appears under their names before :meth:`close` is called with None, so that a run that
    fails leaves no half-written output.  The loop waits for every call: work that takes
    long goes to a thread of the sink's own (as the recording does).  ``close`` may be called
    without ``finish`` (an error), and must not raise when given an error.
    """

    def frame(self, frame: Any, result: Any) -> None:
        """One frame's result."""

    def finish(self) -> None:
        """After the last frame."""

    def close(self, error: BaseException | None) -> None:
        """Commit (``error`` None) or discard the outputs; free what the sink holds."""


def feed(results: Iterator[Any], frames: Any, sinks: Sequence[Sink]) -> float:
    """The frame loop: every result of ``results`` to every sink, then ``finish`` and ``close``.

    ``frames`` is what the results were made from (:class:`trackcli.run.background.DecodeAhead`):
    each result goes to the sinks with the frame of its ``index`` (``frames.frame_at``; the
    tracker may have taken the next frame already, as it does while the outline of the last is
    refined, :func:`trackcli.trackers.base.run_tracker`), or with ``frames.current`` when
    ``frames`` cannot look frames up.  Returns the seconds spent in the
    tracker's steps (waiting for decoded frames included).  An exception from the tracker or
    a sink closes ``results`` (a generator's threads stop) and every sink with it (they remove
    their files) and is raised again; sinks are closed in reverse order.
    """
    step_seconds = 0.0
    frame_at = getattr(frames, "frame_at", None)
    try:
        while True:
            t0 = time.perf_counter()
            try:
                r = next(results)
            except StopIteration:
                break
            finally:
                step_seconds += time.perf_counter() - t0
            frame = frame_at(r.index) if frame_at is not None else frames.current
            for sink in sinks:
                sink.frame(frame, r)
        for sink in sinks:
            sink.finish()
    except BaseException as exc:
        close = getattr(results, "close", None)  # a generator's own threads stop with it
        if close is not None:
            try:
                close()
            except Exception:  # the run's error is the one to report
                pass
        _close(sinks, exc)
        raise
    _close(sinks, None)
    return step_seconds


def _close(sinks: Sequence[Sink], error: BaseException | None) -> None:
    """Close every sink, the last first; a sink that fails to commit makes the rest discard."""
    first: BaseException | None = None
    for sink in reversed(sinks):
        try:
            sink.close(error if error is not None else first)
        except BaseException as exc:
            if error is None and first is None:
                first = exc
    if error is None and first is not None:
        raise first


class Tally(Sink):
    """The run's counts: frames, frames lost, the share of normals with a feature, the ESS."""

    def __init__(self) -> None:
        self.frames = self.lost = 0
        self.found_sum = 0.0
        self.ess_sum, self.ess_count = 0.0, 0

    def frame(self, frame: Any, r: Any) -> None:
        self.frames += 1
        self.lost += int(r.lost)
        self.found_sum += r.n_found / max(r.n_normals, 1)
        if np.isfinite(r.ess):
            self.ess_sum += float(r.ess)
            self.ess_count += 1

    @property
    def mean_found_fraction(self) -> float:
        return self.found_sum / self.frames if self.frames else 0.0

    @property
    def mean_ess(self) -> float:
        return self.ess_sum / self.ess_count if self.ess_count else float("nan")


class Progress(Sink):
    """``progress(1)`` after every frame (e.g. a progress bar's ``update``); it may raise
    (KeyboardInterrupt stops the run, and the outputs are removed as for any error)."""

    def __init__(self, progress: Callable[[int], None]):
        self.progress = progress

    def frame(self, frame: Any, r: Any) -> None:
        self.progress(1)


class TrackCsv(Sink):
    """The track CSV (:class:`trackcli.io.tracks.TrackWriter`), a row per result."""

    def __init__(self, path: Path, names: Sequence[str], outline: OutlineColumns | None,
                 extra_columns: Sequence[str] | None, drawn: DrawnBox | None, frame_size: tuple[int, int]):
        self.writer = TrackWriter(path, names, outline, extra_columns, drawn, frame_size=frame_size)

    def frame(self, frame: Any, r: Any) -> None:
        self.writer.write(r)

    def write(self, r: Any) -> None:
        self.writer.write(r)

    def close(self, error: BaseException | None) -> None:
        self.writer.__exit__(*_exc_info(error))


class SmootherSink(Sink):
    """An offline smoother (:mod:`trackcli.trackers.smoothing`: ``push(result)`` and ``finish()``
    give smoothed results) into a CSV of the track's format and, as a second contour
    (``video/smoothed``) and centroid series, into the recording when there is one."""

    def __init__(self, smoother: Any, csv: TrackCsv, recording: RecordingSink | None = None):
        self.smoother = smoother
        self.csv = csv
        self.recording = recording

    def _write(self, done: list[Any]) -> None:
        for s in done:
            self.csv.write(s)
        if self.recording is not None and done:
            self.recording.smoothed(done)

    def frame(self, frame: Any, r: Any) -> None:
        self._write(self.smoother.push(r))

    def finish(self) -> None:
        self._write(self.smoother.finish())
        if self.recording is not None:
            self.recording.smoothed_series()

    def close(self, error: BaseException | None) -> None:
        self.csv.close(error)


class RecordingSink(Sink):
    """The Rerun recording of a run: every frame with its drawings (logged in a thread of its
    own, :class:`~trackcli.run.background.BackgroundRecorder`), and the per-frame values as
    plots (``series/…``), the translation histogram over time, the tracker's own values.

    Parameters
    ----------
    path : Path
        The ``.rrd`` file.
    video
        The clip (its path, codec and frame storage, :func:`trackcli.io.recording.frame_storage`).
    params : dict
        Logged as the recording's ``params``.
    frames_mode : {"auto", "jpeg", "asset"}
        How frames are stored (``output.frames``).
    keep_jpeg : bool
        The frames come with their source's JPEG bytes, stored as they are.
    extra_columns : list of str
        The tracker's own values (:attr:`FrameResult.extra`): time series ``series/extra/NAME``;
        label posteriors ``p_<label>`` go in one plot ``series/labels`` and a label strip.
    """

    def __init__(self, path: Path, video: Any, *, params: dict[str, Any], jpeg_quality: int, recording_id: str | None,
                 properties: dict[str, Any] | None, frames_mode: str, keep_jpeg: bool,
                 extra_columns: Sequence[str] | None):
        from trackcli.io.recording import Recording, frame_storage

        self._ctx = Recording(path, app_id="trackcli", recording_id=recording_id, blueprint="track",
                              properties=properties)
        self.rec = rec = self._ctx.__enter__()
        self.recorder: BackgroundRecorder | None = None
        try:
            rec.log_params("params", params)
            storage, why = frame_storage(frames_mode, codec=getattr(video, "codec", ""),
                                         embeddable=getattr(video, "is_rerun_video_asset", lambda: False)(),
                                         whole_clip=getattr(video, "whole_clip", False))
            log.info("recording frames as %s: %s", {"jpeg": "JPEG", "av1": "AV1 video"}.get(storage, "a video asset"),
                     why)
            log_frame = rec.frame_logger(getattr(video, "path", None) if storage == "asset" else None,
                                         quality=jpeg_quality, keep_jpeg=keep_jpeg, av1=storage == "av1",
                                         fps=getattr(video, "fps", 25.0))
            self.recorder = BackgroundRecorder(rec, log_frame, _record_frame)
        except BaseException as exc:
            self._ctx.__exit__(type(exc), exc, exc.__traceback__)
            raise
        # the plots: the series are sent every SERIES_CHUNK frames and forgotten; what only
        # the end can draw is kept compact (each frame's histogram as the 8-bit grey levels of
        # its row of the heat-map, one byte a bin; the tracker's own values, 8 bytes each)
        self.series: dict[str, array.array] = _new_series()
        self.extra_names = list(extra_columns or [])
        self.extras = array.array("d")
        self.extras_at = array.array("d")  # frame and time of each row of extras
        self.hist_rows = bytearray()
        self.hist_edges: np.ndarray | None = None
        self.smoothed_centroids: list[tuple[int, float, float, float]] = []

    def frame(self, frame: Any, r: Any) -> None:
        from trackcli.io.recording import histogram_grey

        series = self.series
        for key, val in (("frame", r.index), ("time", r.time), ("tx", r.X[0]), ("ty", r.X[1]),
                         ("cx", r.centroid[0]), ("cy", r.centroid[1]), ("found", r.n_found),
                         ("gate", r.gate_rms), ("ess", r.ess), ("loglik", r.loglik)):
            series[key].append(float(val))
        if len(series["frame"]) >= SERIES_CHUNK:  # sent in the recorder's thread, in order
            full, self.series = series, _new_series()
            self.recorder.call(_record_series, self.rec, full)
        if self.extra_names:
            self.extras.extend(float(r.extra.get(e, np.nan)) for e in self.extra_names)
            self.extras_at.extend((float(r.index), float(r.time)))
        if "histogram" in r.display:
            self.hist_rows += histogram_grey(np.asarray(r.display["histogram"])[None])[0].tobytes()
            self.hist_edges = r.display["hist_edges"]
        self.recorder.submit(frame, r)

    def finish(self) -> None:
        rec = self.rec
        self.recorder.finish()
        _record_series(rec, self.series)
        if self.hist_rows and self.hist_edges is not None:
            rec.log_histogram_image("histogram/tx_over_time",
                                    np.frombuffer(self.hist_rows, np.uint8).reshape(-1, len(self.hist_edges) - 1),
                                    self.hist_edges)
        if self.extras:
            names_all = self.extra_names
            at = np.asarray(self.extras_at, dtype=float).reshape(-1, 2)
            f, t = at[:, 0].astype(np.int64), at[:, 1]
            values = np.asarray(self.extras, dtype=float).reshape(-1, len(names_all))
            # a mixed-state run's label posteriors (p_<label>): one plot and a label strip
            labels = [j for j, e in enumerate(names_all) if e.startswith("p_")]
            if labels:
                names = [names_all[j][2:] for j in labels]
                rec.send_series("series/labels", f, t, values[:, labels], names=names, unit="probability")
                rec.log_label_strip("labels/posterior_over_time", values[:, labels], names, first_frame=int(f[0]))
            for j, e in enumerate(names_all):
                if j not in labels:
                    rec.send_series(f"series/extra/{e}", f, t, values[:, j], names=e)

    def smoothed(self, results: list[Any]) -> None:
        """Smoothed results (:class:`SmootherSink`): a second contour, ``video/smoothed``."""
        for s in results:
            self.smoothed_centroids.append((s.index, s.time, float(s.centroid[0]), float(s.centroid[1])))
            self.rec.set_frame(s.index, s.time)
            self.rec.log_contour("video/smoothed", s.contour, color=SMOOTHED_RGB, width=2.0,
                                 tolerance=CURVE_TOLERANCE)

    def smoothed_series(self) -> None:
        """The smoothed centroids as a plot, ``series/centroid_smoothed``."""
        if self.smoothed_centroids:
            c = np.asarray(self.smoothed_centroids)
            self.rec.send_series("series/centroid_smoothed", c[:, 0].astype(np.int64), c[:, 1], c[:, 2:],
                                 names=["cx", "cy"])

    def close(self, error: BaseException | None) -> None:
        if error is not None and self.recorder is not None:
            self.recorder.close()
        self._ctx.__exit__(*_exc_info(error))


def _exc_info(error: BaseException | None) -> tuple[Any, Any, Any]:
    return (None, None, None) if error is None else (type(error), error, error.__traceback__)


def _record_frame(rec: Any, log_frame: Any, frame: Any, r: Any) -> None:
    rec.set_frame(r.index, r.time)
    log_frame(r.index, frame.image, getattr(frame, "encoded", None))
    d = r.display
    if "particle_contours" in d:
        rec.log_contours("video/particles", d["particle_contours"], d["particle_weights"], closed=True)
    if "gate_inner" in d:
        rec.log_segments("video/gates", d["gate_inner"], d["gate_outer"], color=GATE_RGB)
    if "features" in d and len(d["features"]):
        rec.log_points("video/features", d["features"], colors=FEATURE_RGB, radii=2.0)
    rec.log_contour("video/estimate", r.contour, color=ESTIMATE_RGB, width=2.0, tolerance=CURVE_TOLERANCE)
    if getattr(r, "outline", None) is not None:
        rec.log_contour("video/outline", r.outline, color=OUTLINE_RGB, width=2.0, tolerance=OUTLINE_TOLERANCE)
    rec.log_points("video/centroid", r.centroid[None], colors=ESTIMATE_RGB, radii=3.0)
    if "histogram" in d:
        rec.log_histogram("histogram/tx", d["histogram"], d["hist_edges"])
    for path, kind, data, color in d.get("overlays", ()):
        if kind == "points":
            rec.log_points(path, data, colors=color, radii=3.0)
        elif kind == "segments":
            rec.log_segments(path, data[0], data[1], color=color)
        elif kind == "contour":
            rec.log_contour(path, data, color=color, width=2.0, tolerance=CURVE_TOLERANCE)
        else:
            raise DataError(f"display overlay {path}: unknown kind {kind!r} (points, segments or contour)")


#: the per-frame values plotted in the recording (``series/…``)
SERIES_KEYS = ("frame", "time", "tx", "ty", "cx", "cy", "found", "gate", "ess", "loglik")
#: frames whose series values are sent to the recording together, then dropped from memory
SERIES_CHUNK = 1000


def _new_series() -> dict[str, array.array]:
    return {k: array.array("d") for k in SERIES_KEYS}


def _record_series(rec: Any, s: dict[str, array.array]) -> None:
    """Send the series values held in ``s`` (:data:`SERIES_KEYS`) to the recording."""
    if not s["frame"]:
        return
    f = np.asarray(s["frame"], dtype=np.int64)
    t = np.asarray(s["time"], dtype=float)
    rec.send_series("series/translation", f, t, np.column_stack([s["tx"], s["ty"]]), names=["tx", "ty"], unit="px")
    rec.send_series("series/centroid", f, t, np.column_stack([s["cx"], s["cy"]]), names=["cx", "cy"], unit="px")
    rec.send_series("series/gate_rms", f, t, np.asarray(s["gate"], dtype=float), names="gate_rms", unit="px")
    rec.send_series("series/normals_with_feature", f, t, np.asarray(s["found"], dtype=float),
                    names="normals with a feature", unit="count")
    ess = np.asarray(s["ess"], dtype=float)
    if np.isfinite(ess).any():
        rec.send_series("series/ess", f, t, ess, names="ESS", unit="samples")
        rec.send_series("series/loglik", f, t, np.asarray(s["loglik"], dtype=float), names="loglik",
                        unit="log-likelihood")
