"""The Kalman contour tracker (AC ch. 10): predict, measure along the normals, assimilate.

Each frame: the AR(2) prediction (AC Fig 10.3, :func:`trackcli.dynamics.kalman.predict`),
validation gates from the predicted uncertainty along each normal, the nearest feature in
each gate aggregated into ``Z, S``
(:func:`trackcli.observe.measure.nearest_feature_information`), and the assimilation
(:func:`trackcli.dynamics.kalman.assimilate`).
"""

from __future__ import annotations

import math
from typing import Any, Iterable, Iterator

import numpy as np

from trackcli.observe.measure import nearest_feature_information
from trackcli.observe.observation import Observation
from trackcli.settings import KalmanSettings, MeasurementSettings, ObservationSettings, Settings
from trackcli.shapes.outline import contour_summary, measurement_sampler
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.dynamics import kalman
from trackcli.trackers.base import FrameData, FrameResult, Tracker, run_tracker


def kalman_sigma(rho_f: float, n_normals: int, nx: int) -> float:
    """Per-normal measurement standard deviation ``σ = ρ_f √(M / Nx)`` (AC eq 8.17)."""
    return rho_f * math.sqrt(n_normals / nx)


class KalmanTracker(Tracker):
    """The second-order Kalman contour tracker.

    Initial conditions (AC §10.1): ``kalman.init = "static"`` starts at ``X0`` with the
    closed-loop steady-state covariance of a full set of measurements on that curve;
    ``"unknown"`` starts from the open-loop steady state of the dynamics.

    The confidence and ``lost`` verdict of every frame come from the observation model
    (:meth:`~trackcli.observe.observation.Observation.confidence`: the discriminant and colour
    learned from the template on the first frame, settings ``observation``) applied to the
    estimated curve; no term of it weighs anything here.
    """

    name = "kalman"
    smoother = "trackcli.trackers.smoothing:KalmanTrackSmoother"
    reads = ("measurement", "observation", "kalman")
    observation_terms = ()

    def __init__(self, space: ShapeSpace, dynamics: Any, settings: Settings, rng: np.random.Generator | None = None,
                 *, X0: np.ndarray | None = None):
        super().__init__(space, dynamics, settings, rng, X0=X0)
        m, k = settings.measurement, settings.kalman
        self.sampler = measurement_sampler(space, m.n_normals)
        self.sigma = kalman_sigma(k.rho_f, m.n_normals, space.Nx)
        if k.init == "static":
            h0 = space.measurement_vectors(self.X0, self.sampler)
            self.state = kalman.init_known_static(self.X0, dynamics, S=h0.T @ h0 / self.sigma**2)
        else:
            self.state = kalman.init_unknown(dynamics)
        self.observation = Observation(settings, space, self.sampler, terms=self.observation_terms)

    def step(self, frame: FrameData) -> FrameResult:
        space, m, k = self.space, self.settings.measurement, self.settings.kalman
        obs = self.observation
        first = obs.presence is None
        predicted = self.state if first else kalman.predict(self.state, self.dynamics)
        Xp = predicted.X
        pts, nrm = space.points_normals(Xp, self.sampler)
        h = space.measurement_vectors(Xp, self.sampler, nrm)
        gates = np.clip(k.kappa * kalman.gate_rho(predicted, h), k.min_gate, k.max_gate)
        fimg = frame.features
        if first:
            obs.label = self.label
            obs.start(frame, self.X0)
        Z, S, feats = nearest_feature_information(fimg, pts, nrm, h, gates, self.sigma, m, k.max_gate)
        self.state = state = kalman.assimilate(predicted, Z, S)
        X = state.X
        contour, centroid, bbox = contour_summary(space, X)
        est_pts, est_nrm = space.points_normals(X, self.sampler)
        ev = obs.prepare(frame, centroid)
        spread = float(np.hypot(state.X_std[0], state.X_std[1])) / obs.presence.app.size
        conf, log_d, _ = obs.confidence(ev, est_pts, est_nrm, spread)
        return FrameResult(
            index=frame.index, time=frame.time, X=X.copy(), X_std=state.X_std.copy(),
            contour=contour, centroid=centroid, bbox=bbox, n_found=int(feats.found.sum()), n_normals=m.n_normals,
            gate_rms=float(np.sqrt(np.mean(gates**2))), lost=conf < m.lost_below,
            confidence=conf, log_d=log_d,
            display={
                "gate_inner": pts - gates[:, None] * nrm,
                "gate_outer": pts + gates[:, None] * nrm,
                "features": pts[feats.found] + feats.nu[feats.found, None] * nrm[feats.found],
                # for offline consumers (trackcli.dynamics.em, trackcli.trackers.smoothing): the
                # filtered belief, and the frame's measurement as absolute information z = Z + S X̃ with S
                "state": state,
                "information": (Z + S @ Xp, S),
            },
        )


def track_kalman(frames: Iterable[Any], space: ShapeSpace, dynamics: Any, measurement: MeasurementSettings,
                 settings: KalmanSettings, *, X0: np.ndarray | None = None,
                 observation: ObservationSettings | None = None) -> Iterator[FrameResult]:
    """:class:`KalmanTracker` over ``frames`` with these sections of the settings (the rest default)."""
    full = Settings(measurement=measurement, kalman=settings, observation=observation or ObservationSettings())
    return run_tracker(KalmanTracker(space, dynamics, full, X0=X0), frames)
