"""Running a tracker over a clip and writing its outputs (CSV, recording, effective config).

:func:`run_clip` drives one of the frame loops of :mod:`trackcli.tracking`, writes every
result to the track CSV as it arrives, mirrors it into a Rerun recording, and returns a
:class:`RunSummary` (also the source of the one-line summary the command prints).
All files are written atomically.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from .shape_space import ShapeSpace
from .tracks import TrackWriter

#: Colours (RGB) used in recordings.
ESTIMATE_RGB = (255, 60, 40)
BEST_RGB = (60, 255, 120)
GATE_RGB = (255, 210, 0)
FEATURE_RGB = (0, 200, 255)


@dataclass(frozen=True)
class RunSummary:
    clip: str
    tracker: str
    frames: int
    frames_lost: int
    mean_found_fraction: float
    mean_ess: float
    tracker_seconds: float
    decode_seconds: float
    wall_seconds: float
    csv: str
    rrd: str | None

    @property
    def tracker_fps(self) -> float:
        return self.frames / self.tracker_seconds if self.tracker_seconds > 0 else float("inf")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["tracker_fps"] = round(self.tracker_fps, 2)
        return d

    def line(self) -> str:
        ess = f", mean ESS {self.mean_ess:.0f}" if np.isfinite(self.mean_ess) else ""
        return (f"{self.clip}: {self.tracker}, {self.frames} frames, {self.frames_lost} lost, "
                f"features on {100 * self.mean_found_fraction:.0f}% of normals{ess}, "
                f"{self.tracker_fps:.0f} frames/s (tracker alone) -> {self.csv}")


class _TimedFrames:
    """Wrap a frame iterable, recording each frame and the time spent decoding."""

    def __init__(self, frames: Iterable[Any]):
        self._it = iter(frames)
        self.decode_seconds = 0.0
        self.current: Any = None

    def __iter__(self) -> Iterator[Any]:
        return self

    def __next__(self) -> Any:
        t0 = time.perf_counter()
        try:
            self.current = next(self._it)
        finally:
            self.decode_seconds += time.perf_counter() - t0
        return self.current


def run_clip(
    video: Any,
    make_tracker: Callable[[Iterable[Any]], Iterator[Any]],
    space: ShapeSpace,
    *,
    tracker: str,
    csv_path: Path,
    rrd_path: Path | None,
    params: dict[str, Any],
    jpeg_quality: int = 80,
    progress: Callable[[int], None] | None = None,
    recording_id: str | None = None,
) -> RunSummary:
    """Track ``video`` with ``make_tracker(frames)`` and write the outputs.

    Parameters
    ----------
    video : trackcli.video.Video
    make_tracker : callable
        Given an iterable of frames, returns the iterator of FrameResult.
    space : ShapeSpace
        Gives the CSV column names.
    progress : callable, optional
        Called with 1 after every frame (for a progress bar).
    """
    frames = _TimedFrames(video)
    results = make_tracker(frames)
    t_start = time.perf_counter()
    n = lost = 0
    found_sum = 0.0
    ess_vals: list[float] = []
    series: dict[str, list] = {k: [] for k in ("frame", "time", "tx", "ty", "cx", "cy", "found", "gate", "ess", "loglik")}
    hist_rows: list[np.ndarray] = []
    hist_edges = None
    rec_ctx = None
    rec = None
    log_frame = None
    if rrd_path is not None:
        from .recording import Recording

        rec_ctx = Recording(rrd_path, app_id="trackcli", recording_id=recording_id, blueprint="track")
        rec = rec_ctx.__enter__()
    try:
        with TrackWriter(csv_path, space.names) as writer:
            if rec is not None:
                rec.log_params("params", params)
                path = getattr(video, "path", None)
                use_asset = getattr(video, "is_rerun_video_asset", lambda: False)()
                log_frame = rec.frame_logger(path if use_asset else None, quality=jpeg_quality)
            record_seconds = 0.0
            for r in results:
                writer.write(r)
                n += 1
                lost += int(r.lost)
                found_sum += r.n_found / max(r.n_normals, 1)
                if np.isfinite(r.ess):
                    ess_vals.append(r.ess)
                for key, val in (("frame", r.index), ("time", r.time), ("tx", r.X[0]), ("ty", r.X[1]),
                                 ("cx", r.centroid[0]), ("cy", r.centroid[1]), ("found", r.n_found),
                                 ("gate", r.gate_rms), ("ess", r.ess), ("loglik", r.loglik)):
                    series[key].append(val)
                if "histogram" in r.display:
                    hist_rows.append(np.asarray(r.display["histogram"], dtype=float))
                    hist_edges = r.display["hist_edges"]
                if rec is not None:
                    t0 = time.perf_counter()
                    _record_frame(rec, log_frame, frames.current, r)
                    record_seconds += time.perf_counter() - t0
                if progress is not None:
                    progress(1)
            wall = time.perf_counter() - t_start
            if rec is not None:
                _record_series(rec, series, hist_rows, hist_edges)
    except BaseException as exc:
        if rec_ctx is not None:
            rec_ctx.__exit__(type(exc), exc, exc.__traceback__)
        raise
    if rec_ctx is not None:
        rec_ctx.__exit__(None, None, None)
    tracker_seconds = max(wall - frames.decode_seconds - record_seconds, 1e-9)
    return RunSummary(
        clip=str(getattr(video, "path", "?")), tracker=tracker, frames=n, frames_lost=lost,
        mean_found_fraction=found_sum / n if n else 0.0,
        mean_ess=float(np.mean(ess_vals)) if ess_vals else float("nan"),
        tracker_seconds=tracker_seconds, decode_seconds=frames.decode_seconds, wall_seconds=wall,
        csv=str(csv_path), rrd=str(rrd_path) if rrd_path else None,
    )


def _record_frame(rec: Any, log_frame: Any, frame: Any, r: Any) -> None:
    rec.set_frame(r.index, r.time)
    log_frame(r.index, frame.image)
    d = r.display
    if "particle_contours" in d:
        rec.log_contours("video/particles", d["particle_contours"], d["particle_weights"], closed=True)
    if "gate_inner" in d:
        rec.log_segments("video/gates", d["gate_inner"], d["gate_outer"], color=GATE_RGB)
    if "features" in d and len(d["features"]):
        rec.log_points("video/features", d["features"], colors=FEATURE_RGB, radii=2.0)
    rec.log_contour("video/estimate", r.contour, color=ESTIMATE_RGB, width=2.0)
    rec.log_points("video/centroid", r.centroid[None], colors=ESTIMATE_RGB, radii=3.0)
    if "histogram" in d:
        rec.log_histogram("histogram/tx", d["histogram"], d["hist_edges"])


def _record_series(rec: Any, s: dict[str, list], hist_rows: list, hist_edges: Any) -> None:
    if not s["frame"]:
        return
    f = np.asarray(s["frame"], dtype=np.int64)
    t = np.asarray(s["time"], dtype=float)
    rec.send_series("series/translation", f, t, np.column_stack([s["tx"], s["ty"]]), names=["tx", "ty"])
    rec.send_series("series/centroid", f, t, np.column_stack([s["cx"], s["cy"]]), names=["cx", "cy"])
    rec.send_series("series/normals_with_feature", f, t, np.asarray(s["found"], dtype=float))
    rec.send_series("series/gate_rms", f, t, np.asarray(s["gate"], dtype=float))
    ess = np.asarray(s["ess"], dtype=float)
    if np.isfinite(ess).any():
        rec.send_series("series/ess", f, t, ess)
        rec.send_series("series/loglik", f, t, np.asarray(s["loglik"], dtype=float))
    if hist_rows and hist_edges is not None:
        rec.log_histogram_image("histogram/tx_over_time", np.vstack(hist_rows), hist_edges)
