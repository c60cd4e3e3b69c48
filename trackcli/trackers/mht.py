"""Mode-based multiple-hypothesis tracking of a contour (Cham & Rehg 1999, paper 004).

The density over the second-order shape state is kept as at most ``K = mht.modes`` Gaussian
modes (a piecewise-Gaussian density); each frame (the steps are :mod:`trackcli.trackers.modes`):

1. every mode is predicted by the AR(2) dynamics (AC Fig 10.3);
2. ``K·S`` seeds (``S = mht.samples``) are drawn from that prior: each mode's prediction and
   draws around the modes in proportion to their weights; the drawn seeds also jump as
   CONDENSATION's samples do (``jumps.fraction`` of them, by ``jumps.size`` object sizes RMS
   in translation, and ``jumps.brake`` of them braking: the motion prior is one);
3. each seed climbs to a local maximum by ``mht.iterations`` Gauss–Newton steps: the
   Kalman tracker's measurement (the best feature inside the validation gate of every
   normal, :func:`trackcli.observe.measure.kalman_features`, summed into ``Z, S`` by
   :func:`trackcli.observe.measure.aggregate`) made at the seed's current curve with the
   gates of its mode's prediction, then
   assimilated against the seed's prior mode (:func:`trackcli.dynamics.kalman.assimilate`);
4. each refined curve is weighted by its prior mode's weight and by the edge likelihood of
   the observation model (``observation.likelihood``: the discriminant by default; the
   likelihood itself, neither tempered nor with CONDENSATION's still-scene term);
5. curves within ``mht.merge_distance`` px (RMS displacement) of a heavier one are merged
   into it and the ``K`` heaviest modes are kept.

The estimate is the heaviest mode (the maximum a posteriori curve, which 004 reports as the
"dominant mode"); its covariance gives ``X_std``.  Gates, measurement noise (``kalman.rho_f``,
``kappa``, ``min_gate``, ``max_gate``) and the initial condition (``kalman.init``) are the Kalman
tracker's, so with one mode, one seed and one step the tracker *is* the Kalman tracker.  The
confidence and ``lost`` verdict come from the observation model
(:meth:`~trackcli.observe.observation.Observation.confidence`), as for the other trackers.

Per frame it reports, beside the common fields, the number of modes (``modes``), their
normalised weights heaviest first (``w_mode1 .. w_modeK``, NaN where there are fewer modes)
and their centroids (``cx_mode1, cy_mode1, ...``); the recording draws every mode's curve,
shaded by weight, where CONDENSATION draws its samples.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from trackcli.observe import measure
from trackcli.observe.observation import Observation
from trackcli.settings import Settings
from trackcli.shapes.outline import contour_summary, measurement_sampler
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.dynamics import kalman
from trackcli.trackers import modes
from trackcli.trackers.base import FrameData, FrameResult, Tracker
from trackcli.trackers.condensation_tracker import translation_jumps
from trackcli.trackers.kalman_tracker import kalman_sigma


def mode_columns(k: int) -> list[str]:
    """The extra CSV columns of a tracker keeping at most ``k`` modes."""
    return (["modes"] + [f"w_mode{j}" for j in range(1, k + 1)]
            + [f"{c}_mode{j}" for j in range(1, k + 1) for c in ("cx", "cy")])


class MHTTracker(Tracker):
    """Mode-based multiple hypotheses over contour shape (see the module's description)."""

    name = "mht"
    no_smoother = "its estimate may jump from one mode to another; smooth a kalman or condensation track"
    reads = ("measurement", "observation", "kalman", "mht", "jumps")
    #: its hypotheses are weighed by the edge likelihood alone
    observation_terms = ("discriminant", "clutter", "truncated")

    @classmethod
    def describe(cls, settings: Settings) -> str:
        s = settings.mht
        return (f"seed {settings.seed}; at most {s.modes} modes, {s.samples} seeds per mode, {s.iterations} "
                f"Gauss-Newton steps, merged within {s.merge_distance:g} px; likelihood "
                f"{settings.observation.likelihood}")

    def __init__(self, space: ShapeSpace, dynamics: Any, settings: Settings, rng: np.random.Generator | None = None,
                 *, X0: np.ndarray | None = None):
        super().__init__(space, dynamics, settings, rng, X0=X0)
        m, k = settings.measurement, settings.kalman
        self.extra_columns = mode_columns(settings.mht.modes)
        self.sampler = measurement_sampler(space, m.n_normals)
        self.sigma = kalman_sigma(k.rho_f, m.n_normals, space.Nx)
        if k.init == "static":
            h0 = space.measurement_vectors(self.X0, self.sampler)
            start = kalman.init_known_static(self.X0, dynamics, S=h0.T @ h0 / self.sigma**2)
        else:
            start = kalman.init_unknown(dynamics)
        self.modes: list[kalman.KalmanState] = [start]
        self.log_w = np.zeros(1)
        self.observation = Observation(settings, space, self.sampler, terms=self.observation_terms)
        self.jumps = None
        self.centre = space.origin + self.X0[:2]

    # ------------------------------------------------------------------------------------------

    def _measure(self, fimg: np.ndarray):
        """The Kalman tracker's measurement of many curves, as :data:`modes.Measure`.

        Keeps the gates and features of its last call (for the recording).
        """
        space, m, k = self.space, self.settings.measurement, self.settings.kalman
        last: dict[str, Any] = {}

        def run(X: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            n = X.shape[0]
            pts, nrm = space.points_normals(X, self.sampler)
            h = space.measurement_vectors(X, self.sampler, nrm)
            rho = np.sqrt(np.clip(np.einsum("nmi,nij,nmj->nm", h, P, h), 0.0, None))
            gates = np.clip(k.kappa * rho, k.min_gate, k.max_gate)
            feats = measure.kalman_features(fimg, pts.reshape(-1, 2), nrm.reshape(-1, 2), gates.reshape(-1),
                                            threshold=m.threshold, polarity=m.polarity, max_half_width=k.max_gate)
            nu, found = feats.nu.reshape(n, -1), feats.found.reshape(n, -1)
            Z = np.empty((n, space.Nx))
            S = np.empty((n, space.Nx, space.Nx))
            for i in range(n):
                Z[i], S[i] = measure.aggregate(h[i], nu[i], found[i], self.sigma)
            last.update(pts=pts, nrm=nrm, gates=gates, nu=nu, found=found)
            return Z, S

        return run, last

    def _jump(self, prior: list[kalman.KalmanState], parent: np.ndarray, seeds: np.ndarray
              ) -> tuple[np.ndarray, list[kalman.KalmanState]]:
        """The jumps of the motion prior on the drawn seeds (not the modes' predictions).

        A jump is a displacement in translation (:func:`translation_jumps`, CONDENSATION's);
        a seed that jumps carries its prior mode with it, previous shape included, so the
        jump does not read as velocity.  Returns the seeds and the prior of each.
        """
        k = len(prior)
        seed_prior = [prior[j] for j in parent]
        if self.jumps is None or seeds.shape[0] <= k:
            return seeds, seed_prior
        prev = np.stack([prior[j].X_prev for j in parent[k:]])
        _, moved, _ = self.jumps(prev, seeds[k:], self.rng)
        shift = moved - seeds[k:]
        for i in np.flatnonzero(np.any(shift != 0, axis=1)):
            p = seed_prior[k + i]
            seed_prior[k + i] = kalman.KalmanState(p.mean + np.concatenate([shift[i], shift[i]]), p.cov)
        return np.concatenate([seeds[:k], moved]), seed_prior

    def step(self, frame: FrameData) -> FrameResult:
        space, s, m = self.space, self.settings.mht, self.settings.measurement
        obs = self.observation
        first = obs.presence is None
        fimg = frame.features
        if first:
            obs.label = self.label
            obs.start(frame, self.X0)
            j = self.settings.jumps
            self.jumps = translation_jumps(j.fraction, j.size * obs.presence.app.size, j.brake)
        ev = obs.prepare(frame, self.centre)

        prior = self.modes if first else [kalman.predict(mode, self.dynamics) for mode in self.modes]
        means = np.stack([p.X for p in prior])
        covs = np.stack([p.P for p in prior])
        seeds, parent = modes.draw_seeds(means, covs, self.log_w, s.modes * s.samples, self.rng, spread=s.spread,
                                         truncate=s.truncate)
        seeds, seed_prior = self._jump(prior, parent, seeds)
        run, last = self._measure(fimg)
        refined = modes.refine(seed_prior, seeds, run, s.iterations)
        X = np.stack([r.X for r in refined])
        pts, nrm = space.points_normals(X, self.sampler)
        ll = np.asarray(obs.score(X, pts, nrm), dtype=float)
        log_w = modes.hypothesis_log_weights(parent, self.log_w, ll)
        keep = modes.merge_modes(X, log_w, space.H, s.merge_distance, s.modes)
        self.modes = [refined[i] for i in keep]
        self.log_w = modes.normalise_log(log_w[keep])

        b = int(keep[0])
        state = self.modes[0]
        Xb = state.X
        contour, centroid, bbox = contour_summary(space, Xb)
        if np.isfinite(centroid).all():
            self.centre = centroid
        spread = float(np.hypot(state.X_std[0], state.X_std[1])) / obs.presence.app.size
        conf, log_d, _ = obs.confidence(ev, pts[b], nrm[b], spread)
        weights = np.exp(self.log_w)
        extra: dict[str, float] = {"modes": float(len(keep))}
        for j in range(s.modes):
            if j < len(keep):
                _, c, _ = contour_summary(space, self.modes[j].X)
            else:
                c = (math.nan, math.nan)
            extra[f"w_mode{j + 1}"] = float(weights[j]) if j < len(keep) else math.nan
            extra[f"cx_mode{j + 1}"], extra[f"cy_mode{j + 1}"] = float(c[0]), float(c[1])
        gp, gn, gates = last["pts"][b], last["nrm"][b], last["gates"][b]
        found, nu = last["found"][b], last["nu"][b]
        return FrameResult(
            index=frame.index, time=frame.time, X=Xb.copy(), X_std=state.X_std.copy(),
            contour=contour, centroid=centroid, bbox=bbox, n_found=int(found.sum()), n_normals=m.n_normals,
            gate_rms=float(np.sqrt(np.mean(gates**2))), loglik=float(ll[b]), lost=conf < m.lost_below,
            confidence=conf, log_d=log_d, extra=extra,
            display={
                "gate_inner": gp - gates[:, None] * gn,
                "gate_outer": gp + gates[:, None] * gn,
                "features": gp[found] + nu[found, None] * gn[found],
                "particle_contours": pts[keep],
                "particle_weights": weights / weights.max(),
                "state": state,
            },
        )
