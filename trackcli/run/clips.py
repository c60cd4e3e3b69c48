"""Running a tracker over a clip and writing its outputs (CSV, recording, effective config).

:func:`track_clip` is what ``trackcli track`` does for one clip (and what a batch job runs):
open the clip, decide what is tracked (a learned model placed by a template drawn on this
clip, a model alone, or a template with hand-set dynamics), call :func:`run_clip`, and write
the effective configuration with the results (a run that fails writes none of them).

:func:`run_clip` drives a tracker through the frame loop of :mod:`trackcli.trackers.base` and
feeds every result to the sinks of :mod:`trackcli.run.sinks` (the track CSV, the Rerun
recording, a smoother, the progress bar, the counts of the :class:`RunSummary` that gives the
one-line summary the command prints).  All files are written atomically: an interrupted run
leaves no half-written file.

The runner has no branch on a tracker's name: what a tracker supports (a smoother, mixed
dynamics, its sample count, the sections it reads, how it starts, a structure template, what
``-v`` says of it) is declared on its class (:class:`trackcli.trackers.base.Tracker`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Collection, ContextManager, Iterable, Iterator, Mapping, Sequence

import numpy as np

from trackcli import __version__
from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.mixed import is_mixed_file
from trackcli.errors import ConfigError, DataError, TemplateError
from trackcli.io.outputs import output_dir, refuse_overwriting_inputs, write_text
from trackcli.io.tracks import DrawnBox
from trackcli.run.outline_columns import OutlineColumns
from trackcli.run.background import DecodeAhead
from trackcli.run.sinks import Progress, RecordingSink, Sink, SmootherSink, Tally, TrackCsv, feed
from trackcli.settings import Settings, dump_yaml, to_dict
from trackcli.shapes.outline import contour_summary
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.trackers import tracker_class, trackers_that

log = logging.getLogger(__name__)


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
    smoothed_csv: str | None = None

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
                f"{self.tracker_fps:.0f} frames/s (tracker alone) -> {self.csv}"
                + (f", smoothed -> {self.smoothed_csv}" if self.smoothed_csv else ""))


#: The keys every per-clip JSON object starts with, in ``track --json`` and ``batch --json``
#: alike (a failed clip has them too, with None where nothing was measured).
CLIP_JSON_KEYS = ("kind", "name", "clip", "tracker", "status", "error", "frames", "frames_lost", "tracker_fps",
                  "csv", "rrd")


def clip_json(name: str, clip: Any, tracker: str, summary: RunSummary | None = None,
              error: str | None = None) -> dict[str, Any]:
    """The JSON object of one clip of ``track --json``: :data:`CLIP_JSON_KEYS`, then the run's details."""
    d: dict[str, Any] = {"kind": "clip", "name": name, "clip": str(clip), "tracker": tracker,
                         "status": "failed" if summary is None else "ok", "error": error,
                         "frames": None, "frames_lost": None, "tracker_fps": None, "csv": None, "rrd": None}
    if summary is not None:
        extra = summary.to_dict()
        d.update({k: extra.pop(k) for k in ("frames", "frames_lost", "tracker_fps", "csv", "rrd")})
        extra.pop("clip", None)
        extra.pop("tracker", None)
        d.update(extra)
    return d


#: frames of at least this many pixels get their whole-frame images (feature image, colour map)
#: made in the thread that decodes ahead (:meth:`trackcli.trackers.base.Tracker.prepare`).
#: On a 2-core machine that made 1600 frames of 480x360 7 % faster to track and 313 of
#: 1280x720 10 %, but 1600 of 320x240 3 % slower: there the images take 1.5 ms a frame, and
#: the decoding thread then competes with the thread scoring half the samples.
PREPARE_AHEAD_PIXELS = 100_000


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
    outline_points: int = 64,
    frames_mode: str = "auto",
    smoother: Any = None,
    smooth_csv_path: Path | None = None,
    properties: dict[str, Any] | None = None,
    extra_columns: list[str] | None = None,
    prepare: Callable[[Any], Any] | None = None,
    drawn: DrawnBox | None = None,
    sinks: Sequence[Sink] = (),
) -> RunSummary:
    """Track ``video`` with ``make_tracker(frames)`` and write the outputs.

    Parameters
    ----------
    video : trackcli.io.video.Video
    make_tracker : callable
        Given an iterable of frames, returns the iterator of FrameResult.
    space : ShapeSpace
        Gives the CSV column names.
    progress : callable, optional
        Called with 1 after every frame (for a progress bar).  It may raise (e.g.
        KeyboardInterrupt to stop the run): the outputs are then removed as for any error.
    recording_id : str, optional
        Readable name of the recording (its id adds a unique suffix), see
        :class:`trackcli.io.recording.Recording`.
    properties : dict, optional
        Recording properties, e.g. the seed.
    outline_points : int
        Points of the estimated outline written to every CSV row (0: no outline columns).
    frames_mode : {"auto", "jpeg", "asset"}
        How the recording stores frames (``output.frames``, see
        :func:`trackcli.io.recording.frame_storage`).
    smoother : optional
        A consumer of the results (:mod:`trackcli.trackers.smoothing`: ``push(result)`` and
        ``finish()`` return smoothed results); they go to ``smooth_csv_path`` in the track
        format and, as a second contour (``video/smoothed``), to the recording.
    extra_columns : list of str, optional
        Names of the tracker's own values (:attr:`FrameResult.extra`): CSV columns after
        the common ones, and time series ``series/extra/NAME`` in the recording; label
        posteriors ``p_<label>`` (mixed-state dynamics) go in one plot ``series/labels`` and
        a label strip ``labels/posterior_over_time`` instead.
    prepare : callable, optional
        Applied to every decoded frame in the thread that decodes ahead (the tracker's
        :meth:`~trackcli.trackers.base.Tracker.prepare`: feature image and colour map), so
        that these whole-frame images are made while the previous frame is tracked;
        ``make_tracker`` then receives its results.
    drawn : DrawnBox, optional
        The box columns of the CSVs hold this box carried by the estimate.
    sinks : sequence of Sink
        More consumers of the results (:class:`trackcli.run.sinks.Sink`, e.g. per-frame mask
        images), fed after the CSV, the counts, the recording, the smoother and the progress.
    """
    if outline_points == 1:
        raise ConfigError("output.outline_points: expected 0 (no outline) or at least 2 points, got 1")
    outline = OutlineColumns(space, int(outline_points)) if outline_points else None
    # with a recording that keeps the source's JPEG frames, the frames come with them
    keep_jpeg = rrd_path is not None and frames_mode == "auto" and hasattr(video, "frames")
    frames = DecodeAhead(video.frames(encoded=True) if keep_jpeg else video, prepare=prepare)
    t_start = time.perf_counter()
    # the box columns hold the part of the box inside the frame, as benchmark annotations do
    size = (video.width, video.height)
    tally = Tally()
    more, sinks = list(sinks), []
    try:
        try:
            recording = None
            if rrd_path is not None:
                recording = RecordingSink(rrd_path, video, params=params, jpeg_quality=jpeg_quality,
                                          recording_id=recording_id, properties=properties, frames_mode=frames_mode,
                                          keep_jpeg=keep_jpeg, extra_columns=extra_columns)
                sinks.append(recording)
            sinks.insert(0, TrackCsv(csv_path, space.names, outline, extra_columns, drawn, size))
            sinks.insert(1, tally)
            if smoother is not None:
                smoothed = TrackCsv(smooth_csv_path, space.names, outline, extra_columns, drawn, size)
                sinks.append(SmootherSink(smoother, smoothed, recording))
            if progress is not None:
                sinks.append(Progress(progress))
        except BaseException as exc:
            for sink in reversed([*sinks, *more]):
                sink.close(exc)
            raise
        step_seconds = feed(make_tracker(frames), frames, [*sinks, *more])
    finally:
        frames.close()
    wall = time.perf_counter() - t_start
    # the tracker's own time: its steps, less the time they waited for a decoded frame, plus
    # the time `prepare` spent on their images in the decoding thread (the outline refinement,
    # in a thread of its own, counts where the steps waited for it)
    tracker_seconds = max(step_seconds - frames.wait_seconds + frames.prepare_seconds, 1e-9)
    return RunSummary(
        clip=str(getattr(video, "path", "?")), tracker=tracker, frames=tally.frames, frames_lost=tally.lost,
        mean_found_fraction=tally.mean_found_fraction, mean_ess=tally.mean_ess,
        tracker_seconds=tracker_seconds, decode_seconds=frames.decode_seconds, wall_seconds=wall,
        csv=str(csv_path), rrd=str(rrd_path) if rrd_path else None,
        smoothed_csv=str(smooth_csv_path) if smoother is not None else None,
    )


# ---------------------------------------------------------------------------------------------
# One clip, as `trackcli track` runs it


@dataclass(frozen=True)
class TrackingSetup:
    """What is tracked in one clip.

    Attributes
    ----------
    space : ShapeSpace
        The shape-space, anchored in this clip.
    dynamics : AR2
        Dynamics per frame interval of this clip.
    X0 : ndarray of shape (Nx,)
        Initial shape vector.
    source : str
        One-line description (for logs and recordings).
    drawn : DrawnBox or None
        The box the template was drawn from (:attr:`trackcli.shapes.template.Template.box`),
        which the track's box columns carry, when the tracker starts at that template and
        ``output.box`` is ``drawn``.
    """

    space: ShapeSpace
    dynamics: AR2
    X0: np.ndarray
    source: str
    drawn: DrawnBox | None = None


def clip_name(clip: str | os.PathLike[str]) -> str:
    """Default name of a clip's outputs: a file's stem, or a folder's name; for the frames folder
    of a benchmark sequence, ``NAME/img``, the sequence's name ``NAME``."""
    p = Path(clip)
    if p.name.lower() == "img" and not p.suffix:
        return p.absolute().parent.name or p.name
    return p.stem if p.suffix else p.name


def check_template_frame(template: Any, video: Any) -> None:
    """Raise TemplateError if ``template`` was drawn on a frame of another size than ``video``'s."""
    if template.frame_size and tuple(template.frame_size) != (video.width, video.height):
        raise TemplateError(f"the template was drawn on a {template.frame_size[0]}x{template.frame_size[1]} frame "
                            f"but {video.path} is {video.width}x{video.height}; draw a template on this clip")


def warn_if_drawn_elsewhere(template: Any, template_path: str | os.PathLike[str], video: Any) -> bool:
    """Log a warning if ``template`` was drawn on another clip than ``video``; True if so.

    A template places the object where it was drawn: on another clip of the same size it
    starts wherever the object happened to be there, and the tracker may never find it.
    Clips are the same when they are the same file, or (paths stored relative to where
    ``draw`` ran) when their names are equal.
    """
    drawn = getattr(template, "clip", None)
    if not drawn:
        return False
    here = Path(str(video.path))
    try:
        same = os.path.samefile(drawn, here)
    except OSError:
        same = False
    if same or Path(drawn).name == here.name:
        return False
    log.warning("%s was drawn on %s, not on %s: tracking starts where the object was in that clip "
                "(draw a template on this clip to start on the object)", template_path, drawn, here)
    return True


def template_space(template: Any, path: str | os.PathLike[str], kind: str) -> ShapeSpace:
    """The shape-space ``kind`` on a template, or a TemplateError naming the template file.

    A template whose control points (nearly) coincide or lie on a line cannot carry a
    similarity or affine shape-space: its columns would be linearly dependent.
    """
    from trackcli.shapes.outline import build_space

    try:
        return build_space(template, kind)
    except DataError:
        raise TemplateError(f"{path}: the outline is too degenerate for a {kind} shape-space (its control "
                            "points nearly coincide or lie on a line); draw a larger outline") from None


def tracking_setup(model: str | os.PathLike[str] | None, template: str | os.PathLike[str] | None,
                   settings: Settings, video: Any, *, starts_at_template: bool = True) -> TrackingSetup:
    """Decide what is tracked in ``video``.

    - ``model`` and ``template``: the model's shape-space and learned dynamics, placed where
      the template was drawn on this clip (position and size, see
      :func:`trackcli.dynamics.model.place_space`; dynamics adapted by
      :func:`trackcli.dynamics.model.place_dynamics` with ``settings.placement``);
    - ``model`` alone: the model as learned, starting where its own template was drawn
      (dynamics adapted as above, mean kept);
    - ``template`` alone: the template's shape-space (``settings.shape_space``) with hand-set
      dynamics (``settings.dynamics``).

    With ``starts_at_template`` (the tracker starts where the template was drawn), a template
    drawn on another clip is warned about (:func:`warn_if_drawn_elsewhere`).

    Raises
    ------
    ConfigError
        Neither a model nor a template is given.
    ModelError, TemplateError
        A file is missing or malformed, or the template does not fit this clip or model.
    """
    from trackcli.dynamics.model import load_model, place_dynamics, place_space
    from trackcli.shapes.template import load_template
    from trackcli.dynamics.handset import handset_dynamics

    if not model and not template:
        raise ConfigError("nothing to track: give a model, a template, or both")
    tau = 1.0 / video.fps
    if model and is_mixed_file(model):
        return mixed_setup(model, template, settings, video, starts_at_template=starts_at_template)
    if model:
        m = load_model(model)
        noise = placement_noise(settings)
        if template:
            tmpl = load_template(template)
            check_template_frame(tmpl, video)
            if starts_at_template:
                warn_if_drawn_elsewhere(tmpl, template, video)
            space, X0 = place_space(m.space, tmpl)
            return TrackingSetup(space, place_dynamics(m.dynamics, space, X0, tau, **noise), X0,
                                 f"model {model} placed by template {template}",
                                 drawn=_drawn_box(tmpl, space, X0, settings, starts_at_template, placed=True))
        return TrackingSetup(m.space, place_dynamics(m.dynamics, m.space, None, tau, **noise),
                             np.zeros(m.space.Nx), f"model {model}")
    tmpl = load_template(template)
    check_template_frame(tmpl, video)
    if starts_at_template:
        warn_if_drawn_elsewhere(tmpl, template, video)
    space = template_space(tmpl, template, settings.shape_space)
    X0 = np.zeros(space.Nx)
    return TrackingSetup(space, handset_dynamics(space, settings.dynamics, tau), X0,
                         f"template {template} (hand-set dynamics)",
                         drawn=_drawn_box(tmpl, space, X0, settings, starts_at_template))


def _drawn_box(tmpl: Any, space: ShapeSpace, X0: np.ndarray, settings: Settings, starts_at_template: bool, *,
               placed: bool = False) -> DrawnBox | None:
    """The box ``tmpl`` was drawn from, for the track's box columns to carry (``output.box``);
    ``placed``: the curve tracked is a model's placed by the template, not the template's own."""
    if tmpl.box is None or not starts_at_template or settings.output.box != "drawn":
        return None
    _, _, start = contour_summary(space, X0)
    return DrawnBox(tmpl.box, tmpl.frame, tuple(float(v) for v in start), first=placed)


def placement_noise(settings: Settings) -> dict[str, Any]:
    """The keyword arguments of :func:`trackcli.dynamics.model.place_dynamics` that the settings give."""
    p = settings.placement
    return {"translation_noise": p.translation_noise, "deformation_noise": p.deformation_noise,
            "coupling": p.coupling, "max_spectral_radius": settings.learning.max_spectral_radius}


def mixed_dynamics_on(mm: Any, template: Any, template_path: str | os.PathLike[str] | None, settings: Settings,
                      tau: float) -> tuple[ShapeSpace, Any, np.ndarray]:
    """``(space, dynamics, X0)`` of a mixed-state model (:mod:`trackcli.dynamics.mixed`).

    Hand-set labels are built on the template's shape-space as the ``dynamics`` settings are;
    learned labels (a model from ``learn --labels``, which holds its own template and
    shape-space) are placed by ``template`` as a single learned model is, or without one
    start where their own template was drawn.  A hand-written model needs a template.
    """
    from trackcli.dynamics.mixed_dynamics import build_dynamics
    from trackcli.dynamics.model import place_dynamics, place_space

    if mm.space is None:
        if template is None:
            raise ConfigError("a hand-written mixed-state model has no template of its own; give --template")
        space = template_space(template, str(template_path), settings.shape_space)
        X0 = np.zeros(space.Nx)
        return space, build_dynamics(mm, space, tau, X0=X0), X0
    if template is not None:
        space, X0 = place_space(mm.space, template)
        at = X0
    else:
        space, X0, at = mm.space, np.zeros(mm.space.Nx), None
    noise = placement_noise(settings)
    placed = [None if lab.ar2 is None else place_dynamics(lab.ar2, space, at, tau, **noise) for lab in mm.labels]
    return space, build_dynamics(mm, space, tau, X0=X0, placed=placed), X0


def mixed_setup(model: str | os.PathLike[str], template: str | os.PathLike[str] | None, settings: Settings,
                video: Any, *, starts_at_template: bool = True) -> TrackingSetup:
    """A mixed-state model on ``video`` (see :func:`mixed_dynamics_on`)."""
    from trackcli.dynamics.mixed import load_mixed
    from trackcli.shapes.template import load_template

    mm = load_mixed(model)
    tmpl = None
    if template:
        tmpl = load_template(template)
        check_template_frame(tmpl, video)
        if starts_at_template:
            warn_if_drawn_elsewhere(tmpl, template, video)
    try:
        space, dynamics, X0 = mixed_dynamics_on(mm, tmpl, template, settings, 1.0 / video.fps)
    except ConfigError as exc:
        raise ConfigError(f"{model}: {exc}") from None
    where = f" placed by template {template}" if template else ""
    return TrackingSetup(space, dynamics, X0, f"mixed-state model {model} ({', '.join(mm.names)}){where}")


def output_base(outdir: str | os.PathLike[str], name: str, tracker: str) -> Path:
    """``outdir/NAME.TRACKER``: the outputs are this plus the suffixes of :data:`OUTPUT_SUFFIXES`."""
    return Path(outdir) / f"{name}.{tracker}"


#: the outputs of one run by kind, as suffixes of :func:`output_base`
OUTPUT_SUFFIXES = {"csv": ".csv", "rrd": ".rrd", "config": ".config.yaml", "smoothed": ".smoothed.csv"}


def output_files(outdir: str | os.PathLike[str], name: str, tracker: str) -> dict[str, Path]:
    """Every output a run of ``tracker`` on clip ``name`` may write in ``outdir``, by kind."""
    base = output_base(outdir, name, tracker)
    return {kind: Path(f"{base}{suffix}") for kind, suffix in OUTPUT_SUFFIXES.items()}


class _NullBar:
    def update(self, n: int) -> None:
        pass


def no_progress() -> ContextManager[Any]:
    """A progress bar that shows nothing (``with no_progress() as bar: bar.update(1)``)."""
    return contextlib.nullcontext(_NullBar())


def track_clip(
    clip: str | os.PathLike[str],
    *,
    settings: Settings,
    outdir: str | os.PathLike[str],
    model: str | os.PathLike[str] | None = None,
    template: str | os.PathLike[str] | None = None,
    tracker: str = "condensation",
    name: str | None = None,
    rrd: bool = True,
    progress: Callable[[str, int], ContextManager[Any]] | None = None,
    explicit: Collection[str] | None = None,
    smooth: bool = False,
    inputs: dict[str, Any] | None = None,
    options: Mapping[str, str] | None = None,
    sinks: Callable[[Any], Sequence[Sink]] | None = None,
) -> RunSummary:
    """Track one clip and write its outputs: what ``trackcli track`` does per clip.

    Writes, atomically, in ``outdir`` (created if needed):

    - ``NAME.TRACKER.csv``: per-frame estimates (see :mod:`trackcli.io.tracks`);
    - ``NAME.TRACKER.rrd``: the Rerun recording, if ``rrd`` and ``settings.output.rrd``;
    - ``NAME.TRACKER.smoothed.csv``: with ``smooth``, the smoothed estimates (Kalman:
      Rauch–Tung–Striebel; CONDENSATION: forward-filtering backward-smoothing; both over
      the whole clip, see :mod:`trackcli.trackers.smoothing`);
    - ``NAME.TRACKER.config.yaml``: the effective settings (written last).

    A run that fails writes none of them (earlier outputs of the same name stay as they
    were) and removes ``outdir`` again if it created it.  An output that would replace the
    clip, the model or the template is refused.

    Parameters
    ----------
    clip : path
        Video file or image folder, read with ``settings.video`` (fps, start, end, step).
    settings : Settings
        Effective settings; ``settings.seed`` seeds CONDENSATION.
    outdir : path
        Output folder.
    model, template : path, optional
        What to track (at least one), see :func:`tracking_setup`.
    tracker : str
        A name of :data:`trackcli.trackers.TRACKERS`.
    name : str, optional
        Output file prefix; default :func:`clip_name` of ``clip``.
    rrd : bool
        Write a recording (when the settings also ask for one).
    progress : callable, optional
        ``progress(label, n_frames)`` returns a context manager whose value has
        ``update(n)``, called after every frame (e.g. a progress bar).
    explicit : collection of str, optional
        With a ``model``: the dotted setting keys the user set (configuration file and
        options).  Every other key of the sections a model carries
        (:data:`trackcli.dynamics.model.MODEL_SECTIONS`) is then taken from the model's stored
        settings (:func:`trackcli.dynamics.model.settings_with_model`).  None: ``settings`` are used
        as given.
    smooth : bool
        Also smooth the track offline (see above).
    inputs : dict, optional
        Other input files of the run by label (e.g. ``{"-c/--config": path}``), which the
        outputs must not replace either.
    options : mapping of str to str, optional
        The command-line options the user gave that set a setting, each with the dotted key
        it set (e.g. ``{"--particles": "condensation.particles"}``): one that sets a section the
        tracker does not read (:attr:`~trackcli.trackers.base.Tracker.reads`) is refused.
    sinks : callable, optional
        Given the opened clip, more consumers of the results (e.g. the per-frame masks of
        :class:`trackcli.run.export.MaskSink`), fed and closed with the run's own.

    Returns
    -------
    RunSummary

    Raises
    ------
    ConfigError
        Unknown tracker, nothing to track, something the tracker does not support (``smooth``,
        a mixed-state model, an option it ignores, a missing structure template), a frame
        selection outside the clip, or an output that names an input.
    VideoError, ModelError, TemplateError
        An input cannot be read or does not fit this clip.
    """
    from trackcli.io.video import open_video
    from trackcli.observe.region import outline_refiner
    from trackcli.shapes.template import load_template
    from trackcli.trackers.base import run_tracker

    tracker_cls = tracker_class(tracker)
    check_options(tracker_cls, options or {})
    if smooth and tracker_cls.smoother is None:
        raise ConfigError(f"--smooth: not available with --tracker {tracker} ({tracker_cls.no_smoother})")
    name = name or clip_name(clip)
    mixed = bool(model) and is_mixed_file(model)
    if mixed and not tracker_cls.mixed_dynamics:
        able = ", ".join(f"--tracker {n}" for n in trackers_that("mixed_dynamics"))
        raise ConfigError(f"--model {model} is a mixed-state model: only {able} tracks with one")
    if mixed and smooth:
        raise ConfigError("--smooth: not available with a mixed-state model (the smoother needs one AR(2) model)")
    if tracker_cls.needs_template and not template:
        raise ConfigError(f"--tracker {tracker} needs --template (a structure template)")
    if model and explicit is not None and not mixed:
        from trackcli.dynamics.model import load_model, settings_with_model

        settings, sources = settings_with_model(settings, load_model(model).settings, explicit, f"model {model}")
        for section, source in sources.items():
            log.info("%s settings: %s", section, source)
    files = output_files(outdir, name, tracker)
    csv_path, rrd_path, config_path = files["csv"], files["rrd"], files["config"]
    smooth_path = files["smoothed"] if smooth else None
    write_rrd = rrd and settings.output.rrd
    refuse_overwriting_inputs({"the track CSV": csv_path, "the recording": rrd_path if write_rrd else None,
                               "the effective configuration": config_path, "the smoothed track": smooth_path},
                              {"clip": clip, "model": model, "template": template, **(inputs or {})})
    v = settings.video
    with open_video(clip, fps=v.fps, start=v.start, end=v.end, step=v.step) as video, output_dir(outdir):
        at_template = tracker_cls.starts_at_template(settings)
        setup = tracking_setup(model, template, settings, video, starts_at_template=at_template)
        space, dynamics, X0 = setup.space, setup.dynamics, setup.X0
        rng = np.random.default_rng(settings.seed)
        extra: dict[str, Any] = {}
        if tracker_cls.needs_template:  # e.g. a structure template's parts
            extra = {"template": load_template(template), "template_path": str(template)}
        the_tracker = tracker_cls(space, dynamics, settings, rng, X0=X0, **extra)
        the_tracker.label = name

        # the drawn outline, refined from each frame's estimate after the step; the region the
        # template was fitted to starts it (its colours, its outline); the frames' optical flow is the
        # tracker's when it has one (computed once a frame, before the step)
        refiner = outline_refiner(settings, space, start=load_template(template).region if template else None,
                                  flow=getattr(the_tracker, "flow", None))

        def make(frames: Iterable[Any]) -> Iterator[Any]:
            return run_tracker(the_tracker, frames, refiner=refiner)

        smoother = tracker_cls.make_smoother(space, dynamics) if smooth else None
        _log_setup(name, tracker_cls, setup, settings, video)
        params = {"clip": str(clip), "tracker": tracker, "source": setup.source, "settings": to_dict(settings)}
        # the seed as text: exact at any size, and of one type for every run in a process
        properties = {"seed": str(settings.seed), "clip": str(clip), "tracker": tracker, "trackcli": __version__}
        bar_ctx = progress(f"{name} ({tracker})", len(video)) if progress else no_progress()
        with bar_ctx as bar:
            summary = run_clip(video, make, space, tracker=tracker, csv_path=csv_path,
                               extra_columns=the_tracker.extra_columns, drawn=setup.drawn,
                               rrd_path=rrd_path if write_rrd else None,
                               params=params, jpeg_quality=settings.output.jpeg_quality,
                               progress=bar.update, recording_id=f"{name}-{tracker}-seed{settings.seed}",
                               properties=properties, outline_points=settings.output.outline_points,
                               frames_mode=settings.output.frames, smoother=smoother, smooth_csv_path=smooth_path,
                               prepare=the_tracker.prepare if video.width * video.height >= PREPARE_AHEAD_PIXELS
                               else None, sinks=sinks(video) if sinks is not None else ())
        # written with the outputs, not before them: a run that fails leaves no configuration
        write_text(config_path, dump_yaml(settings))
        log.info("%s: %d frames decoded in %.2f s, tracked in %.2f s", name, summary.frames, summary.decode_seconds,
                 summary.tracker_seconds)
        return summary


def check_options(tracker_cls: Any, options: Mapping[str, str]) -> None:
    """Refuse a command-line option that sets a section ``tracker_cls`` does not read.

    ``options`` maps each option given to the dotted key it set (``{"--particles":
    "condensation.particles"}``).  Raises a one-line ConfigError naming the option (and the
    tracker's own sample count when the option was one).
    """
    for option, key in options.items():
        section = key.partition(".")[0]
        if section in tracker_cls.reads:
            continue
        own = tracker_cls.sample_count
        hint = (f"; its sample count is {own} (set it in a configuration file, -c)" if own and own != key
                and key.endswith("particles") else "")
        raise ConfigError(f"{option}: --tracker {tracker_cls.name} does not read {key}{hint}")


def _log_setup(name: str, tracker_cls: Any, setup: TrackingSetup, settings: Settings, video: Any) -> None:
    """What ``-v`` tells about a clip before it runs: what is tracked, where it starts, the sampling."""
    r = video.indices
    log.info("%s: %s tracker on %s, frames %d-%d step %d (%d frames), %.3g frames/s", name, tracker_cls.name,
             video.path, r.start, r.stop - 1, r.step, len(r), video.fps)
    log.info("%s: tracking %s; shape-space %s (%d components)", name, setup.source, setup.space.kind,
             setup.space.Nx)
    x0 = ", ".join(f"{n}={v:.3g}" for n, v in zip(setup.space.names, setup.X0))
    log.info("%s: initial shape X0: %s", name, x0)
    said = tracker_cls.describe(settings)
    if said:
        log.info("%s: %s", name, said)
