"""The tracker interface: any :class:`Tracker` runs through the one loop into the outputs."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from rrd_utils import entity_paths, read_column
from trackcli.settings import Settings
from trackcli.io.video import open_video
from trackcli.run.clips import run_clip
from trackcli.shapes import shape_space as ss
from trackcli.shapes.spline import SplineBasis
from trackcli.trackers import TRACKERS, tracker_class
from trackcli.trackers.base import FrameData, FrameResult, Tracker, run_tracker
from trackcli.trackers.kalman_tracker import KalmanTracker
from trackcli.errors import ConfigError
from conftest import CLIP_ELLIPSE
from trackcli.dynamics.handset import handset_dynamics


class CountingTracker(Tracker):
    """The Kalman tracker, plus a frame counter and the estimate's centroid as an overlay."""

    name = "counting"
    extra_columns = ["count", "half"]

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.inner = KalmanTracker(*args, **kwargs)
        self.seen: list[FrameData] = []

    def step(self, frame: FrameData) -> FrameResult:
        self.seen.append(frame)
        r = self.inner.step(frame)
        n = len(self.seen)
        overlays = [("video/counting", "points", r.centroid[None], (0, 255, 0))]
        return FrameResult(**{**r.__dict__, "extra": {"count": float(n), "half": n / 2},
                              "display": {**r.display, "overlays": overlays}})


def _space():
    cx, cy, a, b = CLIP_ELLIPSE
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    Q = np.concatenate([cx + a * np.cos(t), cy + b * np.sin(t)])
    return ss.similarity(SplineBasis(12, degree=2, closed=True), Q)


def test_every_registered_tracker_is_a_tracker():
    for name in TRACKERS:
        cls = tracker_class(name)
        assert issubclass(cls, Tracker) and cls.name == name
    with pytest.raises(ConfigError, match="tracker: expected one of"):
        tracker_class("nonsense")


def test_a_new_tracker_runs_through_the_loop_into_the_csv_and_the_recording(ellipse_clip, tmp_path):
    settings = Settings()
    space = _space()
    with open_video(ellipse_clip) as video:
        dyn = handset_dynamics(space, settings.dynamics, 1.0 / video.fps)
        tracker = CountingTracker(space, dyn, settings, X0=None)
        summary = run_clip(video, lambda frames: run_tracker(tracker, frames), space, tracker="counting",
                           csv_path=tmp_path / "t.csv", rrd_path=tmp_path / "t.rrd", params={},
                           extra_columns=tracker.extra_columns, outline_points=4)
        n = len(video)
    assert summary.frames == n == len(tracker.seen)
    # the loop gave the tracker each frame's feature image, as the measurement settings make it
    assert all(f.features.shape == f.image.shape[:2] for f in tracker.seen)
    with open(tmp_path / "t.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    header = list(rows[0])
    # the tracker's own columns come after the common ones and before the outline
    assert header.index("count") == header.index("log_d") + 1
    assert header.index("half") + 1 == header.index("outline_closed")
    assert [float(r["count"]) for r in rows] == [float(k) for k in range(1, n + 1)]
    assert math.isclose(float(rows[-1]["half"]), n / 2)
    paths = entity_paths(tmp_path / "t.rrd")
    assert "series/extra/count" in paths and "video/counting" in paths
    assert len(read_column(tmp_path / "t.rrd", "video/counting", "Points2D:positions")) == n


@pytest.mark.parametrize("name", ["condensation", "kalman"])
def test_images_prepared_while_decoding_give_the_same_track(tmp_path, name):
    """`track` makes each frame's feature image, colour map and (CONDENSATION) comparison with
    the first frame in the thread that decodes ahead (Tracker.prepare); the track must be the
    one of images made in the tracking thread."""
    import threading

    from conftest import write_ellipse_clip

    clip = write_ellipse_clip(tmp_path / "ellipse.avi", n_frames=24, seed=5)
    settings = Settings()
    space = _space()
    prepared: list[tuple[str, bool, bool]] = []

    def run(out, prepare_ahead: bool):
        with open_video(clip) as video:
            dyn = handset_dynamics(space, settings.dynamics, 1.0 / video.fps)
            tracker = tracker_class(name)(space, dyn, settings, np.random.default_rng(3), X0=None)

            def prepare(frame):
                data = tracker.prepare(frame)
                prepared.append((threading.current_thread().name, data.colour is not None, data.still is not None))
                return data

            # with the measurement given, the loop makes the feature image itself and no colour
            # map, which each step then makes from the frame
            make = (lambda frames: run_tracker(tracker, frames)) if prepare_ahead else \
                (lambda frames: run_tracker(tracker, frames, settings.measurement))
            run_clip(video, make, space, tracker=name, csv_path=out, rrd_path=None, params={},
                     prepare=prepare if prepare_ahead else None)

    run(tmp_path / "ahead.csv", True)
    run(tmp_path / "in_step.csv", False)
    # after the first frame, whose step learns the colours, the frames came with their colour map
    # made in the decoding thread (at most the queue's few frames decoded before that did not)
    assert {t for t, _, _ in prepared} == {"trackcli-decode"}
    assert sum(c for _, c, _ in prepared) >= 24 - 6
    stills = sum(s for _, _, s in prepared)
    assert stills >= 24 - 6 if name == "condensation" else stills == 0  # the Kalman tracker has none
    assert (tmp_path / "ahead.csv").read_bytes() == (tmp_path / "in_step.csv").read_bytes()
