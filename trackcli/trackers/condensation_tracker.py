"""CONDENSATION over curve shape (AC ch. 12, Fig 12.6): select, predict, weight.

The filter step itself is :func:`trackcli.trackers.condensation.step`; this module sets it
up for a clip: the initial sample set, the observation model that weighs the samples
(:class:`trackcli.observe.observation.Observation`), the motion prior's jumps
(:func:`translation_jumps`, settings ``jumps``), re-acquisition by importance sampling after
loss (:func:`trackcli.observe.reacquire.reacquisition_proposal`, settings ``reacquire``), and
the per-frame summary.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import deque
from typing import Any, Iterable, Iterator

import numpy as np

from trackcli.dynamics.mixed_dynamics import MixedDynamics, MixedPrediction
from trackcli.errors import ConfigError
from trackcli.observe import flow as flow_cue
from trackcli.observe import measure, reacquire
from trackcli.observe.discriminant import normals_with_features
from trackcli.observe.observation import Observation
from trackcli.observe.region import FlowPrior
from trackcli.settings import CondensationSettings, MeasurementSettings, Settings
from trackcli.shapes.outline import contour_summary, measurement_sampler
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.trackers import condensation as cond
from trackcli.trackers.base import FrameData, FrameResult, LossRecord, Tracker, run_tracker

log = logging.getLogger(__name__)


BRAKE_SPREAD = 0.3  # isotropic part of a braking jump, as a fraction of the jump size (translation_jumps)
#: half-width, in object sizes, of the square about the last held position searched at once when
#: lost; it grows by reacquire.speed object sizes per second lost, or by
#: REACQUIRE_PACE times the fastest the object was seen to move, if that is more
REACQUIRE_NEAR = 2.0
REACQUIRE_PACE = 2.0
#: held frames whose centroids give the object's recent speed
RECENT_HELD = 25
#: Points on each particle contour drawn in the recording (equally spaced in the spline parameter;
#: thin lines, many of them: a coarse polygon looks the same and takes a half of the space).
PARTICLE_POINTS = 12


class LastHeld:
    """Where and when the tracker last held the object, and how fast it was moving then:
    while lost, the object is looked for in a square about that place that grows with the
    time lost (:meth:`window`)."""

    def __init__(self) -> None:
        self.recent: deque[tuple[float, float, float]] = deque(maxlen=RECENT_HELD)

    def push(self, time: float, centroid: np.ndarray) -> None:
        """Record a frame held, its time (s) and the estimate's centroid."""
        self.recent.append((float(time), float(centroid[0]), float(centroid[1])))

    def speed(self) -> float:
        """The fastest the centroid moved between consecutive held frames of the last
        :data:`RECENT_HELD`, px/s (0 with fewer than two)."""
        if len(self.recent) < 2:
            return 0.0
        a = np.asarray(self.recent)
        dt = np.diff(a[:, 0])
        ok = dt > 0
        if not ok.any():
            return 0.0
        return float((np.hypot(np.diff(a[:, 1]), np.diff(a[:, 2]))[ok] / dt[ok]).max())

    def window(self, time: float, size: float, speed: float) -> tuple[float, float, float, float] | None:
        """The square ``(x0, y0, x1, y1)`` to search at ``time``: half-width
        :data:`REACQUIRE_NEAR` object sizes plus the time since the last held frame times the
        larger of ``speed`` object sizes per second and :data:`REACQUIRE_PACE` times
        :meth:`speed`; None before any frame was held."""
        if not self.recent:
            return None
        since, x, y = self.recent[-1]
        pace = max(speed * size, REACQUIRE_PACE * self.speed())
        half = REACQUIRE_NEAR * size + pace * max(time - since, 0.0)
        return (x - half, y - half, x + half, y + half)


def initial_covariance(space: ShapeSpace, settings: CondensationSettings) -> np.ndarray:
    """Diagonal covariance of the hand-placed initial sample set (``init: template``).

    ``init_translation`` (px) on the two translation components, ``init_deformation`` on
    every other component (in the units of ``X``: for similarity and affine spaces, a
    fraction of the template's size).
    """
    var = np.full(space.Nx, settings.init_deformation**2)
    var[:2] = settings.init_translation**2
    return np.diag(var)


def translation_jumps(fraction: float, rms: float, brake: float = 0.0):
    """The jump part of CONDENSATION's motion prior, as a ``propose`` hook of :func:`cond.step`.

    The prediction of the AR(2) model is smooth; objects in real footage also move
    abruptly (a kick, a turn of the head, a jolt of the camera, a ball bouncing).  The motion
    prior is taken as a mixture of the AR(2) prediction and two kinds of jump in translation:

    - with probability ``fraction``, an isotropic Gaussian jump of ``rms`` px per axis;
    - with probability ``brake``, a braking jump ``-u v``, with ``v`` the sample's predicted
      velocity (translation, px/frame) and ``u`` uniform in [0, 2] — slowing down (u < 1),
      stopping (u = 1), turning back (u = 2: a ball bouncing off the floor, whose
      prediction overshoots by twice its speed) — plus an isotropic Gaussian of
      ``BRAKE_SPREAD * rms`` px per axis.  A jump of a fixed size cannot cover a fast object's
      bounce; one proportional to its speed along its motion does.

    A jump is an impulse: the previous shape stays where it was, so the jump is also a
    change of velocity, which the AR(2) model then carries on (and damps) — an object that is
    kicked, or turns, moves on in its new direction.  (Jumps that moved the previous shape
    too, changing the position only, were measured on the dev table: real clips P@20 0.67,
    against 0.76 for impulses over three seeds; `crossing` 0.42 against 0.89.)

    Drawing from this prior needs no importance correction (zero log-weights).
    Returns None when there are no jumps; raises :class:`ConfigError` when the two shares
    add up to more than 1.
    """
    if fraction + brake > 1:
        raise ConfigError(f"jumps.fraction ({fraction:g}) and jumps.brake ({brake:g}) are shares of "
                          "the samples: together at most 1")
    if rms <= 0 or fraction + brake <= 0:
        return None

    def propose(prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r = rng.random(new.shape[0])
        hit = np.flatnonzero(r < fraction + brake)
        jump = rms * rng.standard_normal((hit.size, 2))
        if brake > 0:
            braking = r[hit] >= fraction
            b = hit[braking]
            u = rng.uniform(0.0, 2.0, b.size)
            jump[braking] = BRAKE_SPREAD * jump[braking] - u[:, None] * (new[b, :2] - prev[b, :2])
        out = new.copy()
        out[hit, :2] += jump  # an impulse: prev stays, so the jump is in the velocity too
        return prev, out, np.zeros(new.shape[0])

    return propose


def _chain(first, second):
    """Two ``propose`` hooks applied in turn (either may be None); corrections add up."""
    if first is None:
        return second
    if second is None:
        return first

    def propose(prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p1, a, ca = first(prev, new, rng)
        p2, b, cb = second(p1, a, rng)
        return p2, b, ca + cb

    return propose


class CondensationTracker(Tracker):
    """CONDENSATION over ``frames`` (AC Fig 12.6).

    The samples are weighed by the observation model
    (:class:`~trackcli.observe.observation.Observation`, settings ``observation``): the edge
    likelihood ``observation.likelihood``, ``"discriminant"`` (the default), ``"clutter"`` (AC
    eq 12.2) or ``"truncated"`` (Isard & Blake 1996 eqs 10–11), plus the other terms the
    settings switch on (:mod:`trackcli.observe.terms`).

    The samples' weights take the discriminant's likelihood to the power
    ``observation.discriminant_power`` (0.5 by default; the clutter and truncated models as
    they are).  The discriminant multiplies the evidence of its normals as if independent;
    neighbouring normals see the same edges and colour regions, and the template never fits
    the object exactly, so the product is overconfident: on the 48 clips of
    ``bench/other_clips.py`` seeds 0–3 the estimate's error about its clip's median offset was
    a median 4.1 times the posterior's standard deviation.  Tempered, a look-alike that scores
    a little higher no longer takes all the weight from where the motion model expects the
    object, and the importance weights of the re-acquisition keep their say.  The confidence
    and the posterior score use the likelihood itself.

    Every frame's confidence and ``lost`` verdict come from the observation model
    (:meth:`~trackcli.observe.observation.Observation.confidence`).  While the tracker recovers
    from a loss (by the :class:`~trackcli.trackers.base.LossRecord` rule below) the confidence
    is judged against the stricter centre ``measurement.reacquired_centre``: a place found
    after a loss is a priori less likely to be the object than one followed from frame to frame.

    The motion prior is a mixture of the AR(2) prediction and jumps
    (:func:`translation_jumps`, settings ``jumps``); once the tracker has been lost on
    ``reacquire.after`` of the last ``2 after - 1`` frames
    (:class:`~trackcli.trackers.base.LossRecord`), a share of the samples is drawn from the colour
    proposal of :func:`trackcli.observe.reacquire.reacquisition_proposal` with its
    importance weights, from the colour peaks in a square about the centroid of the last frame
    held (:class:`LastHeld`): :data:`REACQUIRE_NEAR` object sizes from it at once, growing by
    ``reacquire.speed`` object sizes per second lost, or by :data:`REACQUIRE_PACE` times the
    fastest the object was seen to move if that is more (0: the whole frame at once).

    With the discriminant, every frame is also compared with the first (the ``still`` term,
    :mod:`trackcli.observe.terms.still`); when the light changed over the whole scene, the
    colour model is read on the frame brought back to the first frame's exposure
    (:meth:`~trackcli.observe.scene.StillScene.measure`), whatever ``observation.still_weight``.

    The sample set starts either as a Gaussian about ``X0`` (``init = "template"``, AC §12.4,
    "positioned by hand") or from the steady state of the motion model (``"steady_state"``,
    000 §5.1), with ``initial_particles`` samples falling to ``particles`` over
    ``schedule_frames`` frames.  A hand-placed set starts at rest unless ``init_speed`` > 0:
    then each sample's previous shape is its current one less a velocity drawn from
    ``N(0, init_speed² I)`` (px/frame) in translation, for an object that may already be
    moving when the template is drawn (the second-order state carries velocity, AC eq 9.16).
    On the first frame the initial samples are weighted without prediction; afterwards every
    frame is select → predict → weight.

    With mixed-state dynamics (:class:`~trackcli.dynamics.mixed_dynamics.MixedDynamics`, 001 §8)
    every sample also carries a motion label; the prediction draws it from the transition
    matrix and moves the sample with that label's model
    (:class:`~trackcli.dynamics.mixed_dynamics.MixedPrediction`), and each frame
    reports the posterior of every label in ``extra`` (``p_<label>``).

    ``hist_range`` is the range of horizontal translation ``tx`` covered by the histogram
    (default: the frame width around the template).
    """

    name = "condensation"
    smoother = "trackcli.trackers.smoothing:ParticleSmoother"
    mixed_dynamics = True
    sample_count = "condensation.particles"
    reads = ("measurement", "observation", "condensation", "reacquire", "jumps")

    @classmethod
    def starts_at_template(cls, settings: Settings) -> bool:
        # a sample set drawn from the steady state does not start at the template
        return settings.condensation.init == "template"

    @classmethod
    def describe(cls, settings: Settings) -> str:
        c = settings.condensation
        return (f"seed {settings.seed}; samples {c.initial_particles} falling to {c.particles} over "
                f"{c.schedule_frames} frames; likelihood {settings.observation.likelihood}, init {c.init}")

    def __init__(self, space: ShapeSpace, dynamics: Any, settings: Settings, rng: np.random.Generator | None = None,
                 *, X0: np.ndarray | None = None, hist_range: tuple[float, float] | None = None):
        super().__init__(space, dynamics, settings, rng, X0=X0)
        c = settings.condensation
        self.sampler = measurement_sampler(space, settings.measurement.n_normals)
        # the particle contours of the recording are drawn thin and many: a few points each
        self.display_sampler = measurement_sampler(space, min(settings.measurement.n_normals, PARTICLE_POINTS))
        self.schedule = cond.sample_size_schedule(c.initial_particles, c.particles, c.schedule_frames)
        n0 = self.schedule(0)
        if c.init == "template":
            particles = cond.init_gaussian(self.X0, initial_covariance(space, c), n0, self.rng)
            if c.init_speed > 0:
                v = np.zeros_like(particles.cur)
                v[:, :2] = c.init_speed * self.rng.standard_normal((particles.n, 2))
                particles = cond.ParticleSet(particles.cur - v, particles.cur, particles.log_w)
        else:
            if isinstance(dynamics, MixedDynamics):
                raise ConfigError("condensation.init: steady_state is not available with a mixed-state model "
                                  "(it has no single steady state); use init: template")
            if not dynamics.is_stable():
                raise ConfigError("condensation.init: steady_state needs dynamics with a steady state, and these have "
                                  f"none (spectral radius {dynamics.spectral_radius():.4g}; the default translation is "
                                  "a damped velocity with a free position): use init: template, or give "
                                  "dynamics.translation a rho")
            particles = cond.init_steady_state(dynamics, n0, self.rng)
        self.particles = particles
        # mixed-state dynamics (001 §8): a motion label beside every sample
        self.mixed = dynamics if isinstance(dynamics, MixedDynamics) else None
        if self.mixed is not None:
            self.labels = MixedPrediction(self.mixed, particles.n, self.rng)
            self.extra_columns = [f"p_{name}" for name in self.mixed.names]
        self.observation = Observation(settings, space, self.sampler, terms=self.observation_terms)
        self.hist_range = hist_range
        self.edges: np.ndarray | None = None
        self.jumps = None
        self.scale_search: reacquire.ScaleSearch | None = None
        self.centre = space.origin + self.X0[:2]
        self.losses = LossRecord(settings.reacquire.after)
        self.last_held = LastHeld()
        self.k = 0
        self.threads = c.threads  # 0: automatic (see trackcli.trackers.condensation.weigh)
        # compiled terms release the GIL; the numpy models gain from threads only at large N
        self.parallel_min = cond.PARALLEL_MIN if self.observation.compiled else cond.PARALLEL_MIN_NUMPY
        # the confidence's centre while recovering from a loss (never below the usual one)
        m = settings.measurement
        self.recovery_centre = max(m.presence_centre, m.reacquired_centre)
        # the motion cue: the frames' optical flow (shared with the outline's refinement) and the
        # last estimate it moves; X[:2] must be the translation
        self.flow = (FlowPrior() if c.flow_fraction > 0 and space.base_kind in ("translation", "similarity", "affine")
                     else None)
        self.last_X: np.ndarray | None = None
        self.last_contour: np.ndarray | None = None
        # its share of the samples, learned from the posterior weight its samples earn, and
        # this frame's draw (None: not used)
        self.flow_share = flow_cue.AdaptiveShare(c.flow_fraction, c.flow_least)
        self.flow_draw: flow_cue.FlowProposal | None = None

    def _start(self, frame: FrameData) -> None:
        c, space = self.settings.condensation, self.space
        if self.hist_range is None:
            ox = float(space.origin[0])
            self.hist_range = (-ox, frame.image.shape[1] - ox)
        self.edges = np.linspace(self.hist_range[0], self.hist_range[1], c.histogram_bins + 1)
        self.observation.label = self.label
        self.observation.start(frame, self.X0)
        j = self.settings.jumps
        self.jumps = translation_jumps(j.fraction, j.size * self.observation.presence.app.size, j.brake)
        self.scale_search = self._scale_search()

    def _proposal(self, ev: Any, frame: FrameData):
        """The motion prior's jumps; then, once lost on ``reacquire.after`` of the last
        ``2 after - 1`` frames (:class:`LossRecord`), the colour proposal, otherwise the flow's
        (:meth:`_flow_proposal`)."""
        r = self.settings.reacquire
        if not (r.enabled and self.losses.reacquire):
            return _chain(self.jumps, self._flow_proposal())
        size = self.observation.presence.app.size
        window = self.last_held.window(frame.time, size, r.speed) if r.speed > 0 else None
        peaks, strengths = reacquire.colour_peaks(ev.cmap, size, window=window)
        proposal = reacquire.reacquisition_proposal(
            peaks, strengths, self.space.origin, size, (frame.image.shape[1], frame.image.shape[0]),
            fraction=r.fraction, scale=self.scale_search, window=window)
        return self.jumps if proposal is None else _chain(self.jumps, proposal)

    def _flow_proposal(self):
        """The flow proposal (:func:`trackcli.observe.flow.flow_proposal`, ``condensation.flow_fraction``)
        about the last estimate moved by the median optical flow over its region, or None: off,
        no flow yet, or the region out of the frame."""
        if self.flow is None or self.last_contour is None:
            return None
        got = self.flow.shift_spread(self.last_contour)
        if got is None or not np.all(np.isfinite(got[0])) or not np.all(np.isfinite(got[1])):
            return None
        d, disagree = got
        size = self.observation.presence.app.size
        j = self.settings.jumps
        spread = np.maximum(max(flow_cue.MIN_SPREAD, flow_cue.FLOW_SPREAD * size), disagree)
        if self.flow_share.error is not None:  # as far off as the flow's samples were found
            spread = np.maximum(spread, np.minimum(self.flow_share.error, j.size * size))
        self.flow_draw = flow_cue.flow_proposal(self.last_X[:2] + d, spread, self.flow_share.share,
                                                jump_share=min(j.fraction + j.brake, 1.0), jump_rms=j.size * size,
                                                reference=self.flow_share.largest,
                                                groups=(lambda: self.labels.moved) if self.mixed is not None else None)
        return self.flow_draw

    def _scale_search(self) -> reacquire.ScaleSearch | None:
        """The re-acquisition's scale search, or None: not asked for, a space without scale,
        or a template whose presence score on its first frame is below
        ``reacquire.scale_reference``."""
        r, space = self.settings.reacquire, self.space
        if (r.scale <= 1 or space.base_kind == "translation"
                or not self.observation.presence.reference >= r.scale_reference):  # NaN: no reference
            return None

        def log_scale(X: np.ndarray) -> np.ndarray:
            return np.log(np.maximum(space.pose(X)[:, 3], 1e-9))

        return reacquire.ScaleSearch(log_scale, space.scaled, r.scale)

    def step(self, frame: FrameData) -> FrameResult:
        c, m, space = self.settings.condensation, self.settings.measurement, self.space
        obs = self.observation
        if obs.presence is None:
            self._start(frame)
        if self.flow is not None:
            self.flow.push(frame.image)
        self.flow_draw = None
        ev = obs.prepare(frame, self.centre)
        fimg = ev.fimg  # without letterbox bars

        if self.k == 0:
            ll = obs.log_likelihood(self.particles.cur)
            particles = cond.ParticleSet(self.particles.prev, self.particles.cur, obs.power * ll)
            ess = particles.ess
            ancestry = particles
        else:
            particles, info = cond.step(self.particles, self.dynamics, obs.log_likelihood, self.rng,
                                        n_out=self.schedule(self.k), scheme=c.resampling,
                                        ess_threshold=c.ess_threshold, propose=self._proposal(ev, frame),
                                        threads=self.threads, parallel_min=self.parallel_min,
                                        motion=self.labels if self.mixed is not None else None, power=obs.power)
            ess = info.ess
            ll = info.loglik
            ancestry = cond.ParticleSet(info.parent_shapes, particles.cur, particles.log_w)
        self.particles = particles
        self.k += 1
        w = particles.weights
        if self.flow_draw is not None:
            self.flow_share.update_error(w, self.flow_draw.responsibility,
                                         particles.cur[:, :2] - self.flow_draw.centre)
            self.flow_share.update(w, self.flow_draw.responsibility)
        X = cond.weighted_mean(particles)
        dev = particles.cur - X
        X_std = np.sqrt(np.maximum(w @ (dev * dev), 0.0))
        contour, centroid, bbox = contour_summary(space, X)
        pts, nrm = space.points_normals(X, self.sampler)
        spread = float(np.sqrt(X_std[0] ** 2 + X_std[1] ** 2)) / obs.presence.app.size
        # the evidence the posterior puts on the object: the weighted mean of the samples'
        # scores per normal (in the presence score's units only)
        post = obs.posterior_score(w, ll)
        # recovering from a loss, the place the samples found must look more like the object
        # than one followed from frame to frame does (a stricter centre of the confidence)
        strict = self.recovery_centre if self.losses.reacquire else None
        conf, log_d, score_mean = obs.confidence(ev, pts, nrm, spread, posterior_score=post, centre=strict)
        loglik_mean = score_mean if obs.presence_units else float(obs.log_likelihood(X[None])[0])
        lost = conf < m.lost_below
        self.losses.push(lost)
        finite = bool(np.isfinite(centroid).all())
        if finite and not lost:
            self.last_held.push(frame.time, centroid)
        elif not self.last_held.recent:  # lost from the start: about the template
            self.last_held.push(frame.time, self.centre)
        if finite:
            self.centre = centroid
            self.last_X, self.last_contour = X, contour
        # normals of the estimate with a feature within the search range (reported, not used)
        search = self.settings.observation.search
        n_found = normals_with_features(fimg, pts, nrm, h=search, threshold=m.threshold,
                                        sign=measure.polarity_sign(m.polarity))
        hist = cond.weighted_histogram(particles, self.edges, component=0)
        display: dict[str, Any] = {"histogram": hist, "hist_edges": self.edges}
        if c.display_particles:
            top = np.argsort(w)[::-1][: c.display_particles]
            display["particle_contours"] = space.points(particles.cur[top], self.display_sampler)
            display["particle_weights"] = w[top] / max(float(w.max()), 1e-300)
        # for offline consumers (trackcli.trackers.smoothing): each sample's X_{k-1} as its
        # parent had it, before a jump or a re-acquisition moved it
        display["particles"] = ancestry
        extra: dict[str, float] = {}
        if self.mixed is not None:
            p = self.labels.posterior(w)
            extra = {f"p_{name}": float(v) for name, v in zip(self.mixed.names, p)}
        return FrameResult(
            index=frame.index, time=frame.time, X=X, X_std=X_std, contour=contour,
            centroid=centroid, bbox=bbox, n_found=n_found, n_normals=m.n_normals,
            gate_rms=float(search), ess=float(ess), loglik=loglik_mean, lost=bool(lost), confidence=conf,
            log_d=log_d, display=display, extra=extra,
        )


def track_condensation(frames: Iterable[Any], space: ShapeSpace, dynamics: Any, measurement: MeasurementSettings,
                       settings: CondensationSettings | Settings, rng: np.random.Generator, *,
                       X0: np.ndarray | None = None,
                       hist_range: tuple[float, float] | None = None) -> Iterator[FrameResult]:
    """:class:`CondensationTracker` over ``frames`` with these sections of the settings (the rest
    default), or with the whole ``settings`` (whose ``measurement`` is then ``measurement``)."""
    if isinstance(settings, Settings):
        full = dataclasses.replace(settings, measurement=measurement)
    else:
        full = Settings(measurement=measurement, condensation=settings)
    return run_tracker(CondensationTracker(space, dynamics, full, rng, X0=X0, hist_range=hist_range), frames)
