"""The frame loops: Kalman contour tracking (AC Fig 10.3) and CONDENSATION (AC Fig 12.6).

Each tracker is a generator over frames that yields one :class:`FrameResult` per frame; it
holds no output code.  The command line consumes the results to write CSV rows, recordings
and progress bars.  Filter steps themselves are the pure functions of
:mod:`trackcli.trackers.kalman` and :mod:`trackcli.trackers.condensation`; features along normals come from
:mod:`trackcli.observe.measure`.

Notation: ``X`` shape vectors in the shape-space ``Q = W X + Q0`` of the template;
``M`` measurement normals; ``tau`` the frame interval.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator

import numpy as np

from trackcli.trackers import condensation as cond
from trackcli.trackers import kalman
from trackcli.observe import measure
from trackcli.observe import discriminant as observe
from trackcli.io.config import CondensationSettings, DynamicsSettings, KalmanSettings, MeasurementSettings, SubspaceDynamics
from trackcli.dynamics.ar2 import AR2, SubspaceModel, partitioned
from trackcli.errors import ConfigError
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.shapes.spline import CurveSampler, curve_area_centroid, dense_polygon

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
        Log-likelihood of the estimated curve under the clutter model (AC eq 12.2; NaN for Kalman).
    lost : bool
        Tracker's own verdict that it has no lock: ``confidence`` below
        ``measurement.lost_below``.
    confidence : float
        Confidence in [0, 1] that the estimate is on the object (:class:`Presence`).
    log_d : float
        Log of the contour discriminant ``D`` of the estimated curve (``> 0``: more
        object-like than clutter; :mod:`trackcli.observe.discriminant`).
    display : dict
        Extra arrays for recordings (measurement points, gate ends, features, particles, histogram).
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
    display: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# Set-up shared by both trackers


def measurement_sampler(space: ShapeSpace, n_normals: int) -> CurveSampler:
    """The ``M`` measurement points equally spaced in the spline parameter."""
    basis = space.basis
    return basis.sampler(basis.measurement_params(n_normals))


def _subspace_part(space: ShapeSpace, E: np.ndarray, s: SubspaceDynamics, tau: float, what: str,
                   unit: float) -> SubspaceModel:
    rho = None if s.rho is None else s.rho * unit
    gamma0 = None if s.gamma0 is None else s.gamma0 * unit
    try:
        return SubspaceModel.oscillator(E, s.f, s.beta, rho, tau, gamma0=gamma0)
    except ConfigError as exc:
        raise ConfigError(f"dynamics.{what}: {exc}") from None


def object_size(space: ShapeSpace) -> float:
    """The size of the template of ``space``: the square root of the area it encloses, px.

    For an open curve, the RMS distance of its control points from their mean.
    """
    Q0 = space.Q0
    if space.basis.closed:
        area, _ = curve_area_centroid(Q0, space.basis)
        return float(math.sqrt(abs(area)))
    n = space.Nq
    pts = np.column_stack([Q0[:n], Q0[n:]])
    return float(np.sqrt(((pts - pts.mean(axis=0)) ** 2).sum(axis=1).mean()))


def handset_dynamics(space: ShapeSpace, settings: DynamicsSettings, tau: float) -> AR2:
    """Partitioned damped-oscillator dynamics (AC §9.6, eq 9.30) on translation and the rest.

    The translation subspace gets ``settings.translation``; its H-orthogonal complement
    (rotation, scale and other deformation) gets ``settings.deformation``.  The mean shape is
    the template (``X̄ = 0``), so a damped deformation returns to the template's shape and
    size: scale and rotation cannot drift without bound.

    With ``settings.units = "object"`` the steady-state RMS displacements ``rho`` (and
    ``gamma0``) are in units of the template's size (:func:`object_size`), so the same
    settings describe a small and a large object alike; the damping ``beta`` (1/s) and
    frequency ``f`` (Hz) are converted per frame with the clip's frame interval ``tau``.
    """
    unit = object_size(space) if settings.units == "object" else 1.0
    Es = space.translation_projector()
    parts = [_subspace_part(space, Es, settings.translation, tau, "translation", unit)]
    if space.Nx > 2:
        parts.append(_subspace_part(space, np.eye(space.Nx) - Es, settings.deformation, tau, "deformation", unit))
    return partitioned(space.H, parts, np.zeros(space.Nx), tau)


def contour_summary(space: ShapeSpace, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """Dense contour ``(P, 2)``, area centroid ``(2,)`` and box ``(x, y, w, h)`` of shape ``X``."""
    Q = space.to_control(X)
    poly = dense_polygon(Q, space.basis)
    if space.basis.closed:
        _, centroid = curve_area_centroid(Q, space.basis)
        centroid = np.asarray(centroid, dtype=float)
    else:
        centroid = poly.mean(axis=0)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    return poly, centroid, (float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1]))


def _feature_image(image: np.ndarray, m: MeasurementSettings) -> np.ndarray:
    return measure.feature_image(image, channel=m.channel, sigma=m.smoothing, edge_sigma=m.edge_sigma)


# ---------------------------------------------------------------------------------------------
# The verdict: is the estimate on the object?


@dataclass(frozen=True, eq=False)
class Presence:
    """The observation model of :mod:`trackcli.observe.discriminant`, set up for one clip.

    Learned from the template on the first frame; gives the discriminant log-likelihood of
    hypothesised curves (CONDENSATION's default) and, for both trackers, the per-frame
    confidence and ``lost`` verdict.
    """

    app: observe.Appearance
    h: float
    sigma: float
    threshold: float
    miss: float
    colour_weight: float
    centre: float
    reference: float = math.nan

    @classmethod
    def learn(cls, image: np.ndarray, fimg: np.ndarray, space: ShapeSpace, sampler: CurveSampler, X0: np.ndarray,
              measurement: MeasurementSettings, settings: CondensationSettings) -> Presence:
        pts, nrm = space.points_normals(X0, sampler)
        poly, _, _ = contour_summary(space, X0)
        app = observe.learn_appearance(image, fimg, pts, nrm, poly, h=settings.search, sigma=settings.sigma,
                                       threshold=measurement.threshold)
        judge = cls(app, settings.search, settings.sigma, measurement.threshold, settings.miss_probability,
                    settings.colour_weight, measurement.presence_centre)
        ev = judge.evidence(image, fimg, space.origin + X0[:2])
        reference, _, _ = observe.presence(app, ev, pts, nrm, h=judge.h, sigma=judge.sigma, threshold=judge.threshold,
                                           miss=judge.miss, colour_weight=judge.colour_weight)
        return dataclasses.replace(judge, reference=reference)

    def evidence(self, image: np.ndarray, fimg: np.ndarray, centre: np.ndarray) -> observe.FrameEvidence:
        return observe.evidence(self.app, image, fimg, centre, self.threshold)

    def score(self, ev: observe.FrameEvidence, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
        return observe.score(self.app, ev, pts, nrm, h=self.h, sigma=self.sigma, threshold=self.threshold,
                             miss=self.miss, colour_weight=self.colour_weight)

    def confidence(self, ev: observe.FrameEvidence, pts: np.ndarray, nrm: np.ndarray, spread: float,
                   posterior_score: float | None = None) -> tuple[float, float, float]:
        """``(confidence, log D, log-likelihood)`` of one curve, ``spread`` its positional spread in
        object sizes; the log-likelihood is :meth:`score` of the curve.

        ``posterior_score``, when given, is the presence score the sample set puts on the
        object (its weighted mean score per normal); the larger of it and the curve's own
        score is judged, so that a mean curve a few pixels off a well-supported posterior, or
        between the modes of one, is not called lost when the samples are on the object.
        """
        s, e, _ = observe.presence(self.app, ev, pts, nrm, h=self.h, sigma=self.sigma, threshold=self.threshold,
                                   miss=self.miss, colour_weight=self.colour_weight)
        total = s * pts.shape[0]
        if posterior_score is not None and math.isfinite(posterior_score):
            s = max(s, posterior_score)
        return observe.confidence(s, spread, reference=self.reference, centre=self.centre), e * pts.shape[0], total


# ---------------------------------------------------------------------------------------------
# Kalman contour tracker (AC Fig 10.3)


def kalman_sigma(rho_f: float, n_normals: int, nx: int) -> float:
    """Per-normal measurement standard deviation ``σ = ρ_f √(M / Nx)`` (AC eq 8.17)."""
    return rho_f * math.sqrt(n_normals / nx)


def track_kalman(
    frames: Iterable[Any],
    space: ShapeSpace,
    dynamics: AR2,
    measurement: MeasurementSettings,
    settings: KalmanSettings,
    *,
    X0: np.ndarray | None = None,
    observation: CondensationSettings | None = None,
) -> Iterator[FrameResult]:
    """Run the second-order Kalman contour tracker over ``frames``.

    Parameters
    ----------
    frames : iterable of objects with ``index``, ``time``, ``image`` (BGR)
        E.g. a :class:`trackcli.io.video.Video`.
    space : ShapeSpace
    dynamics : AR2
        Its ``tau`` should equal the clip's frame interval.
    measurement, settings : settings sections
    X0 : ndarray of shape (Nx,), optional
        Initial shape (default 0: the template where it was drawn).

    Initial conditions (AC §10.1): ``settings.init = "static"`` starts at ``X0`` with the
    closed-loop steady-state covariance of a full set of measurements on that curve;
    ``"unknown"`` starts from the open-loop steady state of the dynamics.

    The confidence and ``lost`` verdict of every frame come from the discriminant of
    :class:`Presence` (settings of ``observation``, default CONDENSATION settings) applied to
    the estimated curve, learned from the template on the first frame.
    """
    observation = observation or CondensationSettings()
    judge: Presence | None = None
    M = measurement.n_normals
    sampler = measurement_sampler(space, M)
    sigma = kalman_sigma(settings.rho_f, M, space.Nx)
    X0 = np.zeros(space.Nx) if X0 is None else np.asarray(X0, dtype=float)
    if settings.init == "static":
        h0 = space.measurement_vectors(X0, sampler)
        S_full = h0.T @ h0 / sigma**2
        state = kalman.init_known_static(X0, dynamics, S=S_full)
    else:
        state = kalman.init_unknown(dynamics)
    first = True
    for frame in frames:
        predicted = state if first else kalman.predict(state, dynamics)
        first = False
        Xp = predicted.X
        pts, nrm = space.points_normals(Xp, sampler)
        h = space.measurement_vectors(Xp, sampler, nrm)
        gates = np.clip(settings.kappa * kalman.gate_rho(predicted, h), settings.min_gate, settings.max_gate)
        fimg = _feature_image(frame.image, measurement)
        if judge is None:
            judge = Presence.learn(frame.image, fimg, space, sampler, X0, measurement, observation)
        feats = measure.kalman_features(fimg, pts, nrm, gates, threshold=measurement.threshold,
                                        polarity=measurement.polarity, max_half_width=settings.max_gate)
        Z, S = measure.aggregate(h, feats.nu, feats.found, sigma)
        state = kalman.assimilate(predicted, Z, S)
        X = state.X
        contour, centroid, bbox = contour_summary(space, X)
        n_found = int(feats.found.sum())
        est_pts, est_nrm = space.points_normals(X, sampler)
        ev = judge.evidence(frame.image, fimg, centroid)
        spread = float(np.hypot(state.X_std[0], state.X_std[1])) / judge.app.size
        conf, log_d, _ = judge.confidence(ev, est_pts, est_nrm, spread)
        yield FrameResult(
            index=int(frame.index), time=float(frame.time), X=X.copy(), X_std=state.X_std.copy(),
            contour=contour, centroid=centroid, bbox=bbox, n_found=n_found, n_normals=M,
            gate_rms=float(np.sqrt(np.mean(gates**2))), lost=conf < measurement.lost_below,
            confidence=conf, log_d=log_d,
            display={
                "points": pts,
                "gate_inner": pts - gates[:, None] * nrm,
                "gate_outer": pts + gates[:, None] * nrm,
                "features": pts[feats.found] + feats.nu[feats.found, None] * nrm[feats.found],
                # for offline consumers (trackcli.dynamics.em, trackcli.trackers.smoothing): the filtered belief, and
                # the frame's measurement as absolute information z = Z + S X̃ with S
                "state": state,
                "information": (Z + S @ Xp, S),
            },
        )


# ---------------------------------------------------------------------------------------------
# CONDENSATION (AC Fig 12.6)


def initial_covariance(space: ShapeSpace, settings: CondensationSettings) -> np.ndarray:
    """Diagonal covariance of the hand-placed initial sample set (``init: template``).

    ``init_translation`` (px) on the two translation components, ``init_deformation`` on
    every other component (in the units of ``X``: for similarity and affine spaces, a
    fraction of the template's size).
    """
    var = np.full(space.Nx, settings.init_deformation**2)
    var[:2] = settings.init_translation**2
    return np.diag(var)


def track_condensation(
    frames: Iterable[Any],
    space: ShapeSpace,
    dynamics: AR2,
    measurement: MeasurementSettings,
    settings: CondensationSettings,
    rng: np.random.Generator,
    *,
    X0: np.ndarray | None = None,
    hist_range: tuple[float, float] | None = None,
) -> Iterator[FrameResult]:
    """Run CONDENSATION over ``frames`` (AC Fig 12.6).

    The observation model is ``settings.likelihood``: ``"discriminant"`` (the default), the
    contour discriminant with polarity per normal and colour learned on the first frame
    (:class:`Presence`, :mod:`trackcli.observe.discriminant`); ``"clutter"``, AC eq 12.2
    (:func:`trackcli.observe.measure.log_likelihood`); or ``"truncated"``, the truncated Gaussian of
    Isard & Blake 1996 eqs 10–11 (:func:`trackcli.observe.measure.truncated_log_likelihood`).

    Every frame's confidence and ``lost`` verdict come from :class:`Presence`.  The motion
    prior is a mixture of the AR(2) prediction and jumps (:func:`translation_jumps`); once
    the tracker has been lost for ``settings.reacquire_after`` frames in a row, a share of the
    samples is drawn from the colour proposal of :func:`trackcli.observe.discriminant.reacquisition_proposal`
    with its importance weights.

    The sample set starts either as a Gaussian about ``X0`` (``settings.init = "template"``,
    AC §12.4, "positioned by hand") or from the steady state of the motion model
    (``"steady_state"``, 000 §5.1), with ``initial_particles`` samples falling to
    ``particles`` over ``schedule_frames`` frames.  A hand-placed set starts at rest unless
    ``settings.init_speed`` > 0: then each sample's previous shape is its current one less
    a velocity drawn from ``N(0, init_speed² I)`` (px/frame) in translation, for an object
    that may already be moving when the template is drawn (the second-order state carries
    velocity, AC eq 9.16).  On the first frame the initial samples are weighted without
    prediction; afterwards every frame is select → predict → weight.

    ``hist_range`` is the range of horizontal translation ``tx`` covered by the histogram
    (default: the frame width around the template).
    """
    M = measurement.n_normals
    sampler = measurement_sampler(space, M)
    X0 = np.zeros(space.Nx) if X0 is None else np.asarray(X0, dtype=float)
    schedule = cond.sample_size_schedule(settings.initial_particles, settings.particles, settings.schedule_frames)
    n0 = schedule(0)
    if settings.init == "template":
        particles = cond.init_gaussian(X0, initial_covariance(space, settings), n0, rng)
        if settings.init_speed > 0:
            v = np.zeros_like(particles.cur)
            v[:, :2] = settings.init_speed * rng.standard_normal((particles.n, 2))
            particles = cond.ParticleSet(particles.cur - v, particles.cur, particles.log_w)
    else:
        if not dynamics.is_stable():
            raise ConfigError("condensation.init: steady_state needs dynamics with a steady state, and these have "
                              f"none (spectral radius {dynamics.spectral_radius():.4g}; the default translation is a "
                              "damped velocity with a free position): use init: template, or give "
                              "dynamics.translation a rho")
        particles = cond.init_steady_state(dynamics, n0, rng)
    edges = None
    judge: Presence | None = None
    centre = space.origin + X0[:2]
    lost_prev = False
    lost_run = 0  # frames lost in a row
    k = 0
    for frame in frames:
        fimg = _feature_image(frame.image, measurement)
        if edges is None:
            if hist_range is None:
                w = frame.image.shape[1]
                ox = float(space.origin[0])
                hist_range = (-ox, w - ox)
            edges = np.linspace(hist_range[0], hist_range[1], settings.histogram_bins + 1)
        if judge is None:
            judge = Presence.learn(frame.image, fimg, space, sampler, X0, measurement, settings)
            jumps = translation_jumps(settings.jump_fraction, settings.jump_size * judge.app.size)
        ev = judge.evidence(frame.image, fimg, centre)

        def loglik(X: np.ndarray) -> np.ndarray:
            pts, nrm = space.points_normals(X, sampler)
            if settings.likelihood == "truncated":
                return measure.truncated_log_likelihood(fimg, pts, nrm, h=settings.search, sigma=settings.sigma,
                                                        threshold=measurement.threshold,
                                                        polarity=measurement.polarity)
            if settings.likelihood == "clutter":
                return measure.log_likelihood(fimg, pts, nrm, h=settings.search, sigma=settings.sigma,
                                              alpha=settings.alpha, threshold=measurement.threshold,
                                              polarity=measurement.polarity)
            return judge.score(ev, pts, nrm)

        if k == 0:
            ll = loglik(particles.cur)
            particles = cond.ParticleSet(particles.prev, particles.cur, ll)
            ess = particles.ess
            ancestry = particles
        else:
            propose = jumps
            if lost_run >= settings.reacquire_after and settings.reacquire:
                peaks, strengths = observe.colour_peaks(ev.cmap, judge.app.size)
                reacquire = observe.reacquisition_proposal(
                    peaks, strengths, space.origin, judge.app.size, (frame.image.shape[1], frame.image.shape[0]),
                    fraction=settings.reacquire_fraction)
                if reacquire is not None:
                    propose = _chain(jumps, reacquire)
            particles, info = cond.step(particles, dynamics, loglik, rng, n_out=schedule(k),
                                        scheme=settings.resampling, ess_threshold=settings.ess_threshold,
                                        propose=propose)
            ess = info.ess
            ll = info.loglik
            ancestry = cond.ParticleSet(info.parent_shapes, particles.cur, particles.log_w)
        k += 1
        w = particles.weights
        X = cond.weighted_mean(particles)
        best = cond.best_sample(particles)
        dev = particles.cur - X
        X_std = np.sqrt(np.maximum(w @ (dev * dev), 0.0))
        contour, centroid, bbox = contour_summary(space, X)
        pts, nrm = space.points_normals(X, sampler)
        spread = float(np.sqrt(X_std[0] ** 2 + X_std[1] ** 2)) / judge.app.size
        # the evidence the posterior puts on the object: the weighted mean of the samples'
        # scores per normal (the discriminant only; the others are not in its units)
        held = w > 0
        discriminant = settings.likelihood == "discriminant"
        post = float(w[held] @ ll[held]) / M if discriminant else None
        conf, log_d, score_mean = judge.confidence(ev, pts, nrm, spread, posterior_score=post)
        loglik_mean = score_mean if discriminant else float(loglik(X[None])[0])
        lost_prev = conf < measurement.lost_below
        lost_run = lost_run + 1 if lost_prev else 0
        if np.isfinite(centroid).all():
            centre = centroid
        n_found = _normals_with_features(fimg, pts, nrm, settings, measurement)
        hist = cond.weighted_histogram(particles, edges, component=0)
        display: dict[str, Any] = {"points": pts, "histogram": hist, "hist_edges": edges, "best": best}
        if settings.display_particles:
            top = np.argsort(w)[::-1][: settings.display_particles]
            display["particle_contours"] = space.points(particles.cur[top], sampler)
            display["particle_weights"] = w[top] / max(float(w.max()), 1e-300)
        display["particle_centroids"] = particles.cur[:, :2] + space.origin
        display["weights"] = w
        # for offline consumers (trackcli.trackers.smoothing): each sample's X_{k-1} as its parent had it,
        # before a jump or a re-acquisition moved it
        display["particles"] = ancestry
        yield FrameResult(
            index=int(frame.index), time=float(frame.time), X=X, X_std=X_std, contour=contour,
            centroid=centroid, bbox=bbox, n_found=n_found, n_normals=M, gate_rms=float(settings.search),
            ess=float(ess), loglik=loglik_mean, lost=bool(lost_prev), confidence=conf, log_d=log_d,
            display=display,
        )


def translation_jumps(fraction: float, rms: float):
    """The jump part of CONDENSATION's motion prior, as a ``propose`` hook of :func:`cond.step`.

    The prediction of the AR(2) model is smooth; objects in real footage also move
    abruptly (a kick, a turn of the head, a jolt of the camera).  The motion prior is taken
    as a mixture: with probability ``1 - fraction`` the AR(2) prediction, with probability
    ``fraction`` the same plus an isotropic Gaussian jump of RMS ``rms`` px per axis in
    translation (a displacement: the previous shape moves with it, so the velocity is the
    AR(2) model's).  Drawing from this prior needs no importance correction (zero log-weights).
    Returns None when there are no jumps.
    """
    if fraction <= 0 or rms <= 0:
        return None

    def propose(prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        hit = rng.random(new.shape[0]) < fraction
        jump = rms * rng.standard_normal((int(hit.sum()), 2))
        out, out_prev = new.copy(), prev.copy()
        out[hit, :2] += jump
        out_prev[hit, :2] += jump  # a displacement: the velocity is the AR(2) model's
        return out_prev, out, np.zeros(new.shape[0])

    return propose


def _chain(first, second):
    """Two ``propose`` hooks applied in turn (either may be None); corrections add up."""
    if first is None:
        return second

    def propose(prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p1, a, ca = first(prev, new, rng)
        p2, b, cb = second(p1, a, rng)
        return p2, b, ca + cb

    return propose


def _normals_with_features(fimg, pts, nrm, settings: CondensationSettings, m: MeasurementSettings) -> int:
    feats = measure.kalman_features(fimg, pts, nrm, settings.search, threshold=m.threshold, polarity=m.polarity,
                                    max_half_width=max(settings.search, 1.0))
    return int(feats.found.sum())


def build_space(template: Any, kind: str) -> ShapeSpace:
    """The constructive shape-space ``kind`` (translation, similarity, affine) on a template."""
    from trackcli.shapes import shape_space as ss

    builders = {"translation": ss.translation, "similarity": ss.similarity, "affine": ss.affine}
    if kind not in builders:
        raise ConfigError(f"shape_space: expected one of {', '.join(builders)}, got {kind!r}")
    return builders[kind](template.basis(), template.Q)
