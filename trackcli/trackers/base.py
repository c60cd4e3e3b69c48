"""The tracker interface and the one frame loop that drives every tracker.

A tracker is built from a shape-space, dynamics, the settings and a random generator, and
starts from the template's shape ``X0`` on the first frame.  It turns one frame
(:class:`FrameData`: the image and its feature image) into one :class:`FrameResult`:
the estimate, its uncertainty, the confidence and ``lost`` verdict, diagnostics, and what
the recording shows.  :func:`run_tracker` is the loop: decode → feature image → step.
Everything that happens to the results — CSV rows, the recording, the run summary, the
shapes that learning needs — consumes the iterator it returns
(:func:`trackcli.run.clips.run_clip`, :mod:`trackcli.run.train`); nothing of it is inside
a tracker.

A new tracker subclasses :class:`Tracker`, implements :meth:`Tracker.step`, and is listed
by name in :data:`trackcli.trackers.TRACKERS`.  Values it reports beyond the common fields
go in :attr:`FrameResult.extra` under the names of :attr:`Tracker.extra_columns`; they
become CSV columns and time series of the recording.

What it supports it declares on its class (the *contract*, read by the runner,
:func:`trackcli.run.clips.track_clip`, which has no branch on a tracker's name):
:attr:`Tracker.smoother` (``--smooth``), :attr:`Tracker.mixed_dynamics`,
:attr:`Tracker.sample_count`, :attr:`Tracker.reads` (command-line options that set other
sections are refused), :attr:`Tracker.needs_template`, :meth:`Tracker.starts_at_template` and
:meth:`Tracker.describe` (what ``-v`` says of its set-up).  A tracker that weighs curves asks
its :class:`~trackcli.observe.observation.Observation` for their log-likelihoods
(:attr:`Tracker.observation_terms` says which terms may take part).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass, field
from typing import Any, ClassVar, Iterable, Iterator

import numpy as np

from trackcli.observe import measure
from trackcli.observe.appearance import LazyColourMap
from trackcli.settings import MeasurementSettings, Settings
from trackcli.shapes.shape_space import ShapeSpace


@dataclass(frozen=True, eq=False)
class FrameResult:
    """What a tracker estimated on one frame.

    Attributes
    ----------
    index, time : int, float
        Original frame index and time (s).
    X : ndarray of shape (Nx,)
        Estimated shape vector (Kalman: posterior mean; CONDENSATION: weighted mean).
    X_std : ndarray of shape (Nx,)
        Posterior standard deviation of each component.
    contour : ndarray of shape (P, 2)
        Dense polygon of the estimated curve, image ``(x, y)``.
    centroid : ndarray of shape (2,)
        Area centroid of the estimated curve.
    bbox : tuple of float
        ``(x, y, w, h)`` tight box of the contour.
    n_found : int
        Normals on which a feature was found (Kalman; for CONDENSATION, on the mean curve).
    n_normals : int
        ``M``.
    gate_rms : float
        RMS search half-width along the normals, px.
    ess : float
        Effective sample size (CONDENSATION; NaN for Kalman).
    loglik : float
        Log-likelihood of the estimated curve under the tracker's observation model (NaN
        for Kalman).
    lost : bool
        Tracker's own verdict that it has no lock: ``confidence`` below
        ``measurement.lost_below``, unless the refined outline's region vouches for the frame
        (:func:`run_tracker`).
    confidence : float
        Confidence in [0, 1] that the estimate is on the object
        (:class:`trackcli.observe.presence.Presence`).
    log_d : float
        Log of the contour discriminant ``D`` of the estimated curve (``> 0``: more
        object-like than clutter; :mod:`trackcli.observe.discriminant`).
    extra : dict of str to float
        Tracker-specific values, keyed by the names of its ``extra_columns``.
    display : dict
        Extra arrays for recordings and offline consumers (measurement points, gate ends,
        features, particles, histogram, filtered state).  A tracker's own drawings go in
        ``display["overlays"]``: a list of ``(entity path, kind, data, rgb)`` with kind
        ``"points"`` (data ``(K, 2)``), ``"segments"`` (data ``(starts (K, 2), ends (K, 2))``)
        or ``"contour"`` (data ``(P, 2)``), e.g. ``("video/parts", "points", xy, (255, 0, 0))``.
    """

    index: int
    time: float
    X: np.ndarray
    X_std: np.ndarray
    contour: np.ndarray
    centroid: np.ndarray
    bbox: tuple[float, float, float, float]
    n_found: int
    n_normals: int
    gate_rms: float
    ess: float = math.nan
    loglik: float = math.nan
    lost: bool = False
    confidence: float = math.nan
    log_d: float = math.nan
    extra: dict[str, float] = field(default_factory=dict)
    display: dict[str, Any] = field(default_factory=dict)
    outline: np.ndarray | None = None
    """The outline refined in the full image (:class:`trackcli.observe.region.OutlineRefiner`), a
    closed polygon ``(K, 2)``; None: the outline is the estimated curve ``contour``."""
    region_agreement: float = math.nan
    """IoU of the refined region with the estimate's (NaN without refinement)."""


@dataclass(frozen=True, eq=False)
class FrameData:
    """One decoded frame as a tracker sees it: the BGR ``image``, its feature image and, once
    the tracker has learned the object's colours, its colour map (:meth:`Tracker.prepare`)."""

    index: int
    time: float
    image: np.ndarray
    features: np.ndarray
    colour: np.ndarray | LazyColourMap | None = None
    """The colour log-ratio map of the appearance model (:meth:`trackcli.observe.appearance.Appearance.colour_map`);
    None: made when the frame is tracked."""
    still: np.ndarray | None = None
    """Where the frame kept the first frame's colours (:meth:`trackcli.observe.scene.StillScene.compare`);
    None: made when the frame is tracked."""
    encoded: bytes | None = None
    """The frame's JPEG as its source stores it, for the recording (:attr:`trackcli.io.video.Frame.encoded`)."""


class LossRecord:
    """The lost verdicts of the last frames, and from them when to re-acquire.

    Re-acquisition starts once the tracker was lost on at least ``after`` of the last
    ``2 after - 1`` frames: ``after`` frames in a row, or a verdict that goes back and forth
    between lost and held (an estimate on a look-alike that resembles the object on one
    frame and not on the next).  A single short dip (fewer than ``after`` lost frames) is
    left to the motion model.
    """

    def __init__(self, after: int):
        self.after = int(after)
        self.recent: deque[bool] = deque(maxlen=2 * self.after - 1)

    def push(self, lost: bool) -> None:
        """Record the verdict of the frame just tracked."""
        self.recent.append(bool(lost))

    @property
    def reacquire(self) -> bool:
        """Whether the next frame should draw samples from the re-acquisition proposal."""
        return sum(self.recent) >= self.after


def feature_image(image: np.ndarray, m: MeasurementSettings) -> np.ndarray:
    """The feature image of a frame under the measurement settings (:func:`measure.feature_image`)."""
    return measure.feature_image(image, channel=m.channel, sigma=m.smoothing, edge_sigma=m.edge_sigma)


class Tracker(ABC):
    """A tracker: ``step`` turns one frame into one result; the first call is the first frame.

    Parameters
    ----------
    space : ShapeSpace
        The template's shape-space ``Q = W X + Q0``.
    dynamics : AR2
        Its ``tau`` should equal the clip's frame interval.
    settings : Settings
        The effective settings; a tracker reads its own sections.
    rng : numpy.random.Generator
        The only source of randomness (same seed, same numbers).
    X0 : ndarray of shape (Nx,), optional
        Shape on the first frame (default 0: the template where it was drawn).
    """

    name: ClassVar[str] = ""
    #: names of the values of :attr:`FrameResult.extra`, in CSV column order
    extra_columns: list[str] = []
    #: what log messages call the clip (set by whoever runs the tracker; empty: nothing)
    label: str = ""
    #: the observation model, when the tracker has one
    #: (:class:`trackcli.observe.observation.Observation`): :meth:`prepare` makes the frame's
    #: colour map (and comparison with the first frame) with it once it has learned the object
    observation: Any = None

    # -- the contract: what the tracker supports, read by the runner ---------------------------

    #: the offline smoother of its track (``--smooth``), ``module:class`` taking ``(space,
    #: dynamics)`` (:mod:`trackcli.trackers.smoothing`), or None: ``--smooth`` is refused
    smoother: ClassVar[str | None] = None
    #: why ``--smooth`` is refused (when :attr:`smoother` is None)
    no_smoother: ClassVar[str] = "its results carry nothing a smoother can use"
    #: it tracks with a mixed-state model (a motion label per sample, 001 §8)
    mixed_dynamics: ClassVar[bool] = False
    #: the dotted setting of its number of samples (e.g. ``condensation.particles``), or None
    sample_count: ClassVar[str | None] = None
    #: the sections of the settings it reads beyond those of every run (video, shape-space,
    #: dynamics, placement, outline, output): a command-line option that sets another is refused
    reads: ClassVar[tuple[str, ...]] = ("measurement",)
    #: it needs a structure template (``draw --parts``), given to it as ``template`` and ``template_path``
    needs_template: ClassVar[bool] = False
    #: the observation terms (:data:`trackcli.observe.terms.TERMS`) that may take part in its
    #: weights; None: all of them
    observation_terms: ClassVar[tuple[str, ...] | None] = None

    @classmethod
    def starts_at_template(cls, settings: Settings) -> bool:
        """Whether it starts where the template was drawn (else, e.g., from a steady state)."""
        return True

    @classmethod
    def describe(cls, settings: Settings) -> str:
        """What ``-v`` says of its set-up before a clip runs (the seed, the sampling, the
        likelihood); empty: nothing."""
        return ""

    @classmethod
    def make_smoother(cls, space: ShapeSpace, dynamics: Any) -> Any:
        """The smoother of :attr:`smoother` for one clip, or None."""
        from trackcli.registry import load

        return None if cls.smoother is None else load(cls.smoother)(space, dynamics)

    def __init__(self, space: ShapeSpace, dynamics: Any, settings: Settings, rng: np.random.Generator | None = None,
                 *, X0: np.ndarray | None = None):
        self.space = space
        self.dynamics = dynamics
        self.settings = settings
        self.rng = rng if rng is not None else np.random.default_rng(settings.seed)
        self.X0 = np.zeros(space.Nx) if X0 is None else np.asarray(X0, dtype=float)

    @abstractmethod
    def step(self, frame: FrameData) -> FrameResult:
        """Assimilate one frame and return the estimate (the first call starts on the template)."""

    def prepare(self, frame: Any) -> FrameData:
        """The per-frame images that depend on the frame alone: its feature image and, once the
        tracker has learned the object's appearance on its first frame, the colour map (and,
        when it uses one, the comparison with the first frame; the colour map is then read on
        the frame in the first frame's exposure when the light changed over the whole scene,
        :meth:`trackcli.observe.scene.StillScene.measure`).

        Safe to call from another thread while :meth:`step` runs (``track`` calls it in the
        thread that decodes ahead, so that these whole-frame images are made while the
        previous frame is tracked): it reads only settings and the observation model's
        appearance, which do not change after the first frame
        (:meth:`trackcli.observe.observation.Observation.frame_maps`).  The result is the same
        wherever it is made.
        """
        m = self.settings.measurement
        colour, still = self.observation.frame_maps(frame.image) if self.observation is not None else (None, None)
        return FrameData(int(frame.index), float(frame.time), frame.image, feature_image(frame.image, m), colour,
                         still, getattr(frame, "encoded", None))


def run_tracker(tracker: Tracker, frames: Iterable[Any], measurement: MeasurementSettings | None = None,
                refiner: Any = None) -> Iterator[FrameResult]:
    """The frame loop: for each decoded frame, the feature image, then one tracker step.

    ``frames`` yields objects with ``index``, ``time`` and ``image`` (BGR), e.g. a
    :class:`trackcli.io.video.Video`, or :class:`FrameData` already prepared
    (:meth:`Tracker.prepare`); ``measurement``, when given, replaces the tracker's
    measurement settings for the feature image.  With ``refiner``
    (:class:`trackcli.observe.region.OutlineRefiner`), each result carries the outline refined
    in the full image from its estimate: a stage after the tracker's step, which changes nothing
    of the estimate or the weights; a frame the tracker calls lost is reported held when the
    refined region vouches for it (:meth:`~trackcli.observe.region.OutlineRefiner.holds`; the
    tracker's own course, e.g. its re-acquisition, follows its own verdict).  The refinement
    runs in a thread of its own, a frame behind the tracker: a result is yielded once the
    tracker has taken the next frame (:func:`trackcli.run.sinks.feed` pairs it with its frame
    by index).
    """
    def data_of(frame: Any) -> FrameData:
        if measurement is not None:
            return FrameData(int(frame.index), float(frame.time), frame.image, feature_image(frame.image, measurement))
        return frame if isinstance(frame, FrameData) else tracker.prepare(frame)

    if refiner is None:
        for frame in frames:
            yield tracker.step(data_of(frame))
        return
    # The refinement of a frame runs in a thread of its own while the tracker steps on the next
    # frame (it reads nothing the tracker changes, and the tracker nothing it makes; OpenCV,
    # numpy and the compiled kernels release the interpreter's lock), so each result comes out
    # one frame late, in order: who pairs results with frames does so by their ``index``.
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="trackcli-refine")
    pending = None
    try:
        for frame in frames:
            data = data_of(frame)
            r = tracker.step(data)
            # a flow the tracker shares moves on with its next step: the refinement gets this frame's
            flow = refiner.flow.frozen() if getattr(refiner, "flow", None) is not None and not refiner.owns_flow else None
            job = pool.submit(_refined, refiner, data.image, r, flow)
            if pending is not None:
                done, pending = pending, job
                yield done.result()
            else:
                pending = job
        if pending is not None:
            done, pending = pending, None
            yield done.result()
    finally:
        if pending is not None:
            pending.cancel()
        pool.shutdown(wait=True)


def _refined(refiner: Any, image: np.ndarray, r: FrameResult, flow: Any = None) -> FrameResult:
    """``r`` with the outline ``refiner`` draws from its estimate on ``image`` (see :func:`run_tracker`);
    ``flow``: the tracker's shared flow as it was at this frame, or None."""
    import dataclasses

    fit = refiner(image, r.contour, r.confidence) if flow is None else refiner(image, r.contour, r.confidence, flow=flow)
    if fit is not None and fit.outline is not None:
        r = dataclasses.replace(r, outline=fit.outline, region_agreement=fit.agreement,
                                lost=r.lost and not refiner.holds(fit))
    return r
