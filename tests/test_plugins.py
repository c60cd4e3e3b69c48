"""The plug-in points: a tracker, an observation term and an output sink each added by one class
(and one registry line), with no edit of the runner; options a tracker ignores are refused."""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import CLIP_ELLIPSE, ellipse_frame
from trackcli.cli import cli
from trackcli.errors import ConfigError
from trackcli.io.video import open_video
from trackcli.observe.observation import Observation
from trackcli.observe.terms import TERMS, Term
from trackcli.run import clips
from trackcli.run.sinks import Sink
from trackcli.settings import Settings, replace
from trackcli.shapes import shape_space as ss
from trackcli.shapes.outline import contour_summary, measurement_sampler
from trackcli.shapes.spline import SplineBasis
from trackcli.trackers import TRACKERS
from trackcli.trackers.base import FrameData, FrameResult, Tracker, feature_image

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / "sample_data" / "test.mp4"
TEMPLATE = ROOT / "tests" / "data" / "pinned" / "test.template.yaml"
FRAMES = 6


# ---------------------------------------------------------------------------------------------
# A new tracker: one class and one registry line


class TemplateTracker(Tracker):
    """Holds the template where it was drawn, judged every frame by the observation model."""

    name = "template"
    no_smoother = "it never moves"
    reads = ("measurement", "observation")
    extra_columns = ["frames"]

    @classmethod
    def describe(cls, settings: Settings) -> str:
        return "the template, held still"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.sampler = measurement_sampler(self.space, self.settings.measurement.n_normals)
        self.observation = Observation(self.settings, self.space, self.sampler, terms=())
        self.k = 0

    def step(self, frame: FrameData) -> FrameResult:
        obs = self.observation
        if obs.presence is None:
            obs.start(frame, self.X0)
        self.k += 1
        contour, centroid, bbox = contour_summary(self.space, self.X0)
        pts, nrm = self.space.points_normals(self.X0, self.sampler)
        ev = obs.prepare(frame, centroid)
        conf, log_d, score = obs.confidence(ev, pts, nrm, 0.0)
        return FrameResult(index=frame.index, time=frame.time, X=self.X0.copy(), X_std=np.zeros(self.space.Nx),
                           contour=contour, centroid=centroid, bbox=bbox, n_found=0, n_normals=len(pts),
                           gate_rms=0.0, loglik=score, lost=conf < 0.5, confidence=conf, log_d=log_d,
                           extra={"frames": float(self.k)})


@pytest.fixture
def template_tracker(monkeypatch):
    monkeypatch.setitem(TRACKERS, "template", f"{__name__}:TemplateTracker")


def test_a_new_tracker_runs_through_the_runner_from_one_class_and_one_registry_line(template_tracker, tmp_path,
                                                                                     caplog):
    settings = replace(Settings(), {"video.end": FRAMES, "seed": 3})
    with caplog.at_level(logging.INFO, logger="trackcli"):
        summary = clips.track_clip(CLIP, settings=settings, outdir=tmp_path, template=TEMPLATE, tracker="template",
                                   rrd=False)
    assert summary.tracker == "template" and summary.frames == FRAMES
    with open(tmp_path / "test.template.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["frames"]) for r in rows] == [float(k) for k in range(1, FRAMES + 1)]
    assert len({r["cx"] for r in rows}) == 1  # held still
    # the template on its own first frame is the object: confident
    assert float(rows[0]["confidence"]) > 0.9 and rows[0]["lost"] == "0"
    assert "test: the template, held still" in caplog.text  # what -v says: the class's own words
    assert (tmp_path / "test.template.config.yaml").is_file()


def test_what_a_new_tracker_does_not_declare_is_refused(template_tracker, tmp_path):
    settings = replace(Settings(), {"video.end": FRAMES})
    with pytest.raises(ConfigError, match=r"^--smooth: not available with --tracker template \(it never moves\)$"):
        clips.track_clip(CLIP, settings=settings, outdir=tmp_path / "a", template=TEMPLATE, tracker="template",
                         rrd=False, smooth=True)
    with pytest.raises(ConfigError, match=r"^--particles: --tracker template does not read condensation.particles$"):
        clips.track_clip(CLIP, settings=settings, outdir=tmp_path / "b", template=TEMPLATE, tracker="template",
                         rrd=False, options={"--particles": "condensation.particles"})
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


# ---------------------------------------------------------------------------------------------
# Options a tracker ignores, through the command line


@pytest.mark.parametrize("tracker, option, message", [
    ("kalman", ["--particles", "30"], "Error: --particles: --tracker kalman does not read condensation.particles\n"),
    ("coupled", ["--particles", "30"], "Error: --particles: --tracker coupled does not read condensation.particles; "
                                       "its sample count is coupled.particles (set it in a configuration file, -c)\n"),
    ("mht", ["--threads", "2"], "Error: --threads: --tracker mht does not read condensation.threads\n"),
    ("coupled", ["--smooth"], "Error: --smooth: not available with --tracker coupled (it keeps no sample set of "
                              "shapes, only of the parts)\n"),
    ("mht", ["--smooth"], "Error: --smooth: not available with --tracker mht (its estimate may jump from one mode "
                          "to another; smooth a kalman or condensation track)\n"),
])
def test_an_option_the_tracker_ignores_is_refused_in_one_line(tmp_path, tracker, option, message):
    template = ROOT / "tests" / "data" / "pinned" / ("test.structure.yaml" if tracker == "coupled"
                                                     else "test.template.yaml")
    res = CliRunner().invoke(cli, ["track", str(CLIP), "--template", str(template), "--tracker", tracker, *option,
                                   "-o", str(tmp_path / "out")])
    assert res.exit_code == 3
    assert res.output == message
    assert not (tmp_path / "out").exists()


def test_track_help_says_what_the_first_frame_samples():
    res = CliRunner().invoke(cli, ["track", "--help"])
    text = " ".join(res.output.split())
    assert "condensation.initial_particles samples (1500)" in text


# ---------------------------------------------------------------------------------------------
# A new observation term: one class and one registry line


class LeftwardTerm(Term):
    """Favours curves to the left: ``-tx / 4`` per curve, and counts the frames it saw."""

    name = "leftward"

    def start(self, first) -> None:
        self.frames = 0

    def prepare(self, frame) -> bool:
        self.frames += 1
        return True

    def log_likelihood(self, X, points, normals):
        return -0.25 * X[:, 0]


def _ellipse_setup():
    cx, cy, a, b = CLIP_ELLIPSE
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    space = ss.similarity(SplineBasis(12, degree=2, closed=True), np.concatenate([cx + a * np.cos(t),
                                                                                  cy + b * np.sin(t)]))
    image = ellipse_frame(np.random.default_rng(0))
    settings = Settings()
    frame = FrameData(0, 0.0, image, feature_image(image, settings.measurement))
    return settings, space, measurement_sampler(space, settings.measurement.n_normals), frame


def test_a_new_term_plugs_in_with_one_registry_line_and_changes_the_weights(monkeypatch):
    settings, space, sampler, frame = _ellipse_setup()
    X = np.zeros((5, space.Nx))
    X[:, 0] = [-8.0, -4.0, 0.0, 4.0, 8.0]

    def scored() -> tuple[Observation, np.ndarray]:
        obs = Observation(settings, space, sampler)
        obs.start(frame, np.zeros(space.Nx))
        obs.prepare(frame, space.origin)
        return obs, obs.log_likelihood(X)

    before_obs, before = scored()
    monkeypatch.setitem(TERMS, "leftward", f"{__name__}:LeftwardTerm")
    obs, after = scored()
    assert obs.names == before_obs.names + ["leftward"]
    np.testing.assert_array_equal(after - before, -0.25 * X[:, 0])
    # CONDENSATION's weights: the term moves the posterior to the left
    w_before = np.exp(before_obs.power * before - np.max(before_obs.power * before))
    w_after = np.exp(obs.power * after - np.max(obs.power * after))
    mean = [float(w @ X[:, 0] / w.sum()) for w in (w_before, w_after)]
    assert mean[1] < mean[0]
    # a term out of the presence score's units turns the posterior score off
    assert before_obs.posterior_score(w_before, before) is not None
    assert obs.posterior_score(w_after, after) is None


def test_a_new_term_changes_the_track_of_the_command(monkeypatch, tmp_path, ellipse_clip):
    template = tmp_path / "e.yaml"
    runner = CliRunner()
    assert runner.invoke(cli, ["-q", "draw", str(ellipse_clip), "--ellipse", "70,60,28,36", "-o",
                               str(template)]).exit_code == 0

    def track(out: str) -> list[dict[str, str]]:
        res = runner.invoke(cli, ["-q", "track", str(ellipse_clip), "--template", str(template), "--particles", "200",
                                  "--seed", "1", "-o", str(tmp_path / out), "--no-rrd"])
        assert res.exit_code == 0, res.output
        with open(tmp_path / out / "ellipse.condensation.csv", newline="") as f:
            return list(csv.DictReader(f))

    plain = track("plain")
    monkeypatch.setitem(TERMS, "leftward", f"{__name__}:LeftwardTerm")
    left = track("left")
    assert [r["X_tx"] for r in plain] != [r["X_tx"] for r in left]
    assert plain[0]["frame"] == left[0]["frame"] and len(plain) == len(left)


# ---------------------------------------------------------------------------------------------
# A new sink


class Recorder(Sink):
    def __init__(self) -> None:
        self.frames: list[int] = []
        self.images: list[tuple[int, ...]] = []
        self.calls: list[str] = []
        self.error: BaseException | None = None

    def frame(self, frame, result) -> None:
        self.frames.append(result.index)
        self.images.append(frame.image.shape)

    def finish(self) -> None:
        self.calls.append("finish")

    def close(self, error) -> None:
        self.calls.append("close")
        self.error = error


class RefinerStub:
    """Draws no outline; notes the thread, the frame and the estimate of every call."""

    def __init__(self) -> None:
        import threading

        self.threads: set[int] = set()
        self.seen: dict[int, int] = {}  # the image's id by the frame's place in the clip
        self._threading = threading

    def __call__(self, image, estimate, confidence):
        self.threads.add(self._threading.get_ident())
        self.seen[len(self.seen)] = id(image)
        return None

    def holds(self, fit) -> bool:
        return False


def _run_clip(video, tmp_path, sink, fail_at: int | None = None, refiner=None):
    from trackcli.dynamics.handset import handset_dynamics
    from trackcli.shapes.template import load_template
    from trackcli.trackers.kalman_tracker import KalmanTracker
    from trackcli.trackers.base import run_tracker

    space = clips.template_space(load_template(TEMPLATE), TEMPLATE, "similarity")
    settings = Settings()
    tracker = KalmanTracker(space, handset_dynamics(space, settings.dynamics, 1.0 / video.fps), settings)

    def make(frames):
        for r in run_tracker(tracker, frames, refiner=refiner):
            if r.index == fail_at:
                raise KeyboardInterrupt
            yield r

    return clips.run_clip(video, make, space, tracker="kalman", csv_path=tmp_path / "t.csv", rrd_path=None,
                          params={}, sinks=[sink])


def test_a_sink_given_to_the_runner_sees_every_frame_then_finish_and_close(tmp_path):
    sink = Recorder()
    with open_video(CLIP, end=FRAMES) as video:
        summary = _run_clip(video, tmp_path, sink)
    assert sink.frames == list(range(FRAMES)) and summary.frames == FRAMES
    assert set(sink.images) == {(360, 480, 3)}
    assert sink.calls == ["finish", "close"] and sink.error is None
    assert (tmp_path / "t.csv").is_file()


class FrameRecorder(Recorder):
    def frame(self, frame, result) -> None:
        super().frame(frame, result)
        self.calls.append((frame.index, id(frame.image)))


def test_the_refinement_runs_a_frame_behind_in_its_own_thread_and_each_result_meets_its_frame(tmp_path):
    import threading

    sink, refiner = FrameRecorder(), RefinerStub()
    with open_video(CLIP, end=FRAMES) as video:
        summary = _run_clip(video, tmp_path, sink, refiner=refiner)
    assert sink.frames == list(range(FRAMES)) and summary.frames == FRAMES
    assert refiner.threads and threading.get_ident() not in refiner.threads
    paired = [c for c in sink.calls if isinstance(c, tuple)]
    # each result with the frame of its index: the very image its outline was refined on
    assert [i for i, _ in paired] == list(range(FRAMES))
    assert [image for _, image in paired] == [refiner.seen[k] for k in range(FRAMES)]
    assert sink.calls[-2:] == ["finish", "close"]


def test_a_run_that_stops_while_refining_leaves_no_thread_behind(tmp_path):
    import threading

    sink = Recorder()
    refiner = RefinerStub()
    with open_video(CLIP, end=FRAMES) as video, pytest.raises(KeyboardInterrupt):
        _run_clip(video, tmp_path, sink, fail_at=3, refiner=refiner)
    assert sink.frames == [0, 1, 2] and isinstance(sink.error, KeyboardInterrupt)
    assert refiner.threads
    assert not [t for t in threading.enumerate() if t.ident in refiner.threads and t.is_alive()]
    assert not (tmp_path / "t.csv").exists()


class FailingSink(Recorder):
    def frame(self, frame, result) -> None:
        super().frame(frame, result)
        if result.index == 2:
            raise KeyboardInterrupt


def test_a_sink_that_stops_the_run_stops_the_refinement_thread_at_once(tmp_path):
    import threading

    sink, refiner = FailingSink(), RefinerStub()
    with open_video(CLIP, end=FRAMES) as video, pytest.raises(KeyboardInterrupt):
        _run_clip(video, tmp_path, sink, refiner=refiner)
    # the traceback still holds the run's frames: the thread must have stopped without them going
    assert refiner.threads
    assert not [t for t in threading.enumerate() if t.ident in refiner.threads and t.is_alive()]
    assert sink.frames == [0, 1, 2] and isinstance(sink.error, KeyboardInterrupt)


def test_a_run_that_stops_closes_every_sink_with_the_error_and_writes_nothing(tmp_path):
    sink = Recorder()
    with open_video(CLIP, end=FRAMES) as video, pytest.raises(KeyboardInterrupt):
        _run_clip(video, tmp_path, sink, fail_at=3)
    assert sink.frames == [0, 1, 2]
    assert sink.calls == ["close"] and isinstance(sink.error, KeyboardInterrupt)
    assert not (tmp_path / "t.csv").exists()
