"""Coupled structures (003, Zobel, Denzler & Niemann): a centre and rays to parts, by CONDENSATION.

The object is a centre ``c`` and, for each part ``j``, a ray of length ``l_j`` and angle
``θ_j``, the part sitting at ``c + l_j (cos θ_j, sin θ_j)``.  The state of a sample is
``(c, l_1, θ_1, ..., l_J, θ_J)`` and its previous centre (for the velocity).  Its
log-weight is minus the sum of two energies (003 §2):

- internal: each ray's deviation from the drawn structure, Gaussian with spreads
  ``coupled.length_spread`` (fraction of the drawn length) and ``coupled.angle_spread``;
- external: each part's patch matched at the part's position by normalised
  cross-correlation, ``-NCC_j / coupled.temperature``.

Each frame: select by weight, predict (the centre with its velocity plus noise, and jumps
as in CONDENSATION's motion prior, ``jumps.fraction`` and ``jumps.size``; each ray with a small random walk), weigh (NCC maps of
every part over a window around its predicted position, read at every sample's part
position).  The estimate is the weighted mean; its confidence is the mean NCC of the
parts at the estimate, mapped to [0, 1] (:data:`NCC_LOST`, :data:`NCC_SURE`).  Once lost on
``reacquire.after`` of the last ``2 after - 1`` frames
(:class:`~trackcli.trackers.base.LossRecord`) a share of the samples is drawn about the
peaks of the whole frame's part votes, with importance weights (:meth:`CoupledTracker._reacquire`).  The template's outline follows the centre (translation)
and the mean change of the rays (scale and rotation), so the track CSV, ``eval`` and
``render`` work as for the other trackers; the parts' positions and scores are extra
columns.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from trackcli.errors import ConfigError
from trackcli.shapes.outline import contour_summary, object_size
from trackcli.shapes.structure import Part, parts_from_template
from trackcli.trackers import condensation as cond
from trackcli.trackers.base import FrameData, FrameResult, LossRecord, Tracker

PART_RGB = (255, 200, 0)
RAY_RGB = (255, 255, 255)
#: the mean NCC of the parts at the estimate at which the confidence is 0 and 1 (0.5 at 0.65:
#: small patches match background texture at 0.5-0.6 on their own)
NCC_LOST, NCC_SURE = 0.45, 0.85


class CoupledTracker(Tracker):
    """Coupled-structure tracking (``--tracker coupled``); needs a structure template."""

    name = "coupled"
    needs_template = True
    no_smoother = "it keeps no sample set of shapes, only of the parts"
    sample_count = "coupled.particles"
    reads = ("measurement", "coupled", "jumps", "reacquire")

    @classmethod
    def describe(cls, settings: Any) -> str:
        s = settings.coupled
        return f"seed {settings.seed}; {s.particles} samples of the structure's centre and rays"

    def __init__(self, space: Any, dynamics: Any, settings: Any, rng: np.random.Generator | None = None, *,
                 X0: np.ndarray | None = None, template: Any = None, template_path: str = "template"):
        super().__init__(space, dynamics, settings, rng, X0=X0)
        if template is None:
            raise ConfigError("--tracker coupled needs a structure template (trackcli draw CLIP --parts ...)")
        if space.kind not in ("translation", "similarity"):
            raise ConfigError(f"--tracker coupled reports a translation or similarity of the outline, not {space.kind}: "
                              "set shape_space: similarity")
        self.parts: list[Part] = parts_from_template(template, template_path)
        centres = np.array([p.centre for p in self.parts])
        self.c0 = centres.mean(axis=0)
        d = centres - self.c0
        self.l0 = np.hypot(d[:, 0], d[:, 1])
        if np.any(self.l0 < 1.0):
            raise ConfigError(f"{template_path}: a part lies on the structure's centre; draw parts around it")
        self.a0 = np.arctan2(d[:, 1], d[:, 0])
        self.size = object_size(space)
        self.patches = [p.patch.astype(np.float32) for p in self.parts]
        n = settings.coupled.particles
        J = len(self.parts)
        self.state = np.empty((n, 2 + 2 * J))
        self.state[:, :2] = self.c0
        self.state[:, 2::2] = self.l0
        self.state[:, 3::2] = self.a0
        self.prev_centre = self.state[:, :2].copy()
        self.log_w = np.full(n, -np.log(n))
        self.first = True
        self.losses = LossRecord(settings.reacquire.after)
        self.extra_columns = [f"{p.name}_{k}" for p in self.parts for k in ("x", "y", "ncc")]

    # -- the model ---------------------------------------------------------------------------

    def part_positions(self, state: np.ndarray) -> np.ndarray:
        """``(N, J, 2)`` part positions of the samples."""
        c = state[:, None, :2]
        l, a = state[:, 2::2], state[:, 3::2]
        return c + np.stack([l * np.cos(a), l * np.sin(a)], axis=-1)

    def internal_energy(self, state: np.ndarray) -> np.ndarray:
        s = self.settings.coupled
        dl = (state[:, 2::2] - self.l0) / (s.length_spread * self.l0)
        da = np.angle(np.exp(1j * (state[:, 3::2] - self.a0))) / s.angle_spread
        return 0.5 * (dl**2 + da**2).sum(axis=1)

    def _predict(self, state: np.ndarray, prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s, j = self.settings.coupled, self.settings.jumps
        rng = self.rng
        n = state.shape[0]
        new = state.copy()
        velocity = state[:, :2] - prev
        new[:, :2] += velocity + s.centre_noise * self.size * rng.standard_normal((n, 2))
        jump = rng.random(n) < j.fraction
        new[jump, :2] += j.size * self.size * rng.standard_normal((int(jump.sum()), 2))
        J = len(self.parts)
        new[:, 2::2] *= 1.0 + s.ray_noise * rng.standard_normal((n, J))
        new[:, 3::2] += s.ray_noise * rng.standard_normal((n, J))
        return new, state[:, :2].copy()

    def _ncc_maps(self, grey: np.ndarray, predicted: np.ndarray,
                  spread: np.ndarray | None = None) -> list[tuple[np.ndarray, int, int]]:
        """Per part: its NCC map over a window about its predicted position (or, with
        ``spread`` (N, J, 2), about the box of every sample's part), and the map's origin."""
        import cv2

        h_img, w_img = grey.shape
        R = int(round(self.settings.coupled.search * self.size))
        maps = []
        for j, patch in enumerate(self.patches):
            ph, pw = patch.shape
            lo, hi = (predicted[j], predicted[j]) if spread is None else (spread[:, j].min(axis=0),
                                                                          spread[:, j].max(axis=0))
            x0 = int(max(0, np.floor(lo[0] - pw / 2 - R)))
            y0 = int(max(0, np.floor(lo[1] - ph / 2 - R)))
            x1 = int(min(w_img, np.ceil(hi[0] + pw / 2 + R)))
            y1 = int(min(h_img, np.ceil(hi[1] + ph / 2 + R)))
            if x1 - x0 < pw or y1 - y0 < ph:
                maps.append((np.full((1, 1), -1.0, np.float32), x0, y0))
                continue
            m = cv2.matchTemplate(grey[y0:y1, x0:x1], patch, cv2.TM_CCOEFF_NORMED)
            # a map value at (u, v) scores the patch centred at (x0 + u + pw/2, y0 + v + ph/2)
            maps.append((np.nan_to_num(m, nan=-1.0), x0 + (pw - 1) / 2.0, y0 + (ph - 1) / 2.0))
        return maps

    def _votes(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Where the structure's centre may be in the whole frame: the parts' NCC maps shifted
        by their drawn rays and averaged (every part votes for the centre).

        Returns ``(centres (K, 2), votes (K,))`` of up to five peaks, or None.
        """
        import cv2

        h_img, w_img = grey.shape
        total = np.zeros((h_img, w_img), np.float32)
        for part, patch in zip(self.parts, self.patches):
            ph, pw = patch.shape
            if ph > h_img or pw > w_img:
                return None
            m = np.nan_to_num(cv2.matchTemplate(grey, patch, cv2.TM_CCOEFF_NORMED), nan=-1.0)
            # the map's (u, v) scores the part centred at (u + (pw-1)/2, v + (ph-1)/2); it votes for
            # the centre at that point less the part's drawn ray
            off = part.centre - self.c0
            shift = np.float32([[1, 0, (pw - 1) / 2.0 - off[0]], [0, 1, (ph - 1) / 2.0 - off[1]]])
            total += cv2.warpAffine(m, shift, (w_img, h_img), flags=cv2.INTER_NEAREST,
                                    borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
        total /= len(self.parts)
        r = max(3, int(0.25 * self.size))
        peaks, votes = [], []
        for _ in range(5):
            _, v, _, (x, y) = cv2.minMaxLoc(total)
            if v < NCC_LOST:
                break
            peaks.append((x, y))
            votes.append(v)
            cv2.circle(total, (x, y), r, -2.0, -1)
        if not peaks:
            return None
        return np.asarray(peaks, float), np.asarray(votes, float)

    def _reacquire(self, grey: np.ndarray, state: np.ndarray, prev: np.ndarray) -> np.ndarray:
        """Move a share of the samples to the whole frame's vote peaks (importance sampling).

        While lost, the motion prior is a mixture: the object may also reappear anywhere
        (uniform over the frame).  That share (``reacquire.fraction``) is drawn
        from a Gaussian mixture about the vote peaks instead, and each such sample carries
        the log of the uniform density over the proposal density; the others carry 0.
        Returns the log-corrections.
        """
        r = self.settings.reacquire
        corr = np.zeros(state.shape[0])
        found = self._votes(grey)
        if found is None:
            return corr
        peaks, votes = found
        pi = votes / votes.sum()
        take = self.rng.random(state.shape[0]) < r.fraction
        k = int(take.sum())
        if k == 0:
            return corr
        sd = 0.05 * self.size
        which = self.rng.choice(len(peaks), size=k, p=pi)
        centres = peaks[which] + sd * self.rng.standard_normal((k, 2))
        state[take, :2] = centres
        state[take, 2::2] = self.l0
        state[take, 3::2] = self.a0
        prev[take] = centres  # at rest
        d2 = ((centres[:, None, :] - peaks[None]) ** 2).sum(axis=-1)
        q = (pi[None] * np.exp(-0.5 * d2 / sd**2) / (2 * np.pi * sd**2)).sum(axis=1)
        h_img, w_img = grey.shape
        corr[take] = -np.log(float(w_img * h_img)) - np.log(np.maximum(q, 1e-300))
        return corr

    @staticmethod
    def _read(ncc: tuple[np.ndarray, float, float], pts: np.ndarray) -> np.ndarray:
        m, ox, oy = ncc
        u = np.rint(pts[..., 0] - ox).astype(np.int64)
        v = np.rint(pts[..., 1] - oy).astype(np.int64)
        inside = (u >= 0) & (v >= 0) & (u < m.shape[1]) & (v < m.shape[0])
        out = np.full(pts.shape[:-1], -1.0)
        out[inside] = m[v[inside], u[inside]]
        return out

    # -- one frame ---------------------------------------------------------------------------

    def step(self, frame: FrameData) -> FrameResult:
        import cv2

        s = self.settings.coupled
        grey = cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY).astype(np.float32)
        correction = np.zeros(self.state.shape[0])
        if self.first:
            state, prev = self.state, self.prev_centre
            self.first = False
        else:
            parents = cond.resample(np.exp(self.log_w), self.state.shape[0], self.rng, "systematic")
            state, prev = self._predict(self.state[parents], self.prev_centre[parents])
            if self.settings.reacquire.enabled and self.losses.reacquire:
                correction = self._reacquire(grey, state, prev)
        pos = self.part_positions(state)
        # samples in several places after re-acquisition: one window over all of them
        maps = self._ncc_maps(grey, pos.mean(axis=0), spread=pos if correction.any() else None)
        ncc = np.stack([self._read(maps[j], pos[:, j]) for j in range(len(self.parts))], axis=1)
        log_w = correction + ncc.sum(axis=1) / s.temperature - self.internal_energy(state)
        log_w -= log_w.max()
        w = np.exp(log_w)
        w /= w.sum()
        self.state, self.prev_centre, self.log_w = state, prev, np.log(np.maximum(w, 1e-300))
        # the estimate
        est_parts = np.einsum("n,njk->jk", w, pos)
        centre = w @ state[:, :2]
        est_ncc = np.array([self._read(maps[j], est_parts[j][None])[0] for j in range(len(self.parts))])
        d = est_parts - centre
        scale = float(np.mean(np.hypot(d[:, 0], d[:, 1]) / self.l0))
        turn = float(np.angle(np.mean(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - self.a0)))))
        X = np.zeros(self.space.Nx)
        X[:2] = self.X0[:2] + (centre - self.c0)
        if self.space.Nx >= 4:
            X[2], X[3] = scale * np.cos(turn) - 1.0, scale * np.sin(turn)
        contour, centroid, bbox = contour_summary(self.space, X)
        spread = np.sqrt(np.maximum(w @ (state[:, :2] - centre) ** 2, 0.0))
        X_std = np.zeros(self.space.Nx)
        X_std[:2] = spread
        conf = float(np.clip((np.mean(est_ncc) - NCC_LOST) / (NCC_SURE - NCC_LOST), 0.0, 1.0))
        lost = conf < self.settings.measurement.lost_below
        self.losses.push(lost)
        extra = {}
        for p, xy, q in zip(self.parts, est_parts, est_ncc):
            extra.update({f"{p.name}_x": float(xy[0]), f"{p.name}_y": float(xy[1]), f"{p.name}_ncc": float(q)})
        overlays = [("video/parts", "points", est_parts, PART_RGB),
                    ("video/rays", "segments", (np.repeat(centre[None], len(self.parts), axis=0), est_parts),
                     RAY_RGB)]
        return FrameResult(
            index=frame.index, time=frame.time, X=X, X_std=X_std, contour=contour, centroid=centroid, bbox=bbox,
            n_found=int((est_ncc > NCC_LOST).sum()), n_normals=len(self.parts), gate_rms=float(s.search * self.size),
            ess=float(1.0 / np.sum(w**2)), loglik=float(w @ ncc.sum(axis=1)), lost=lost,
            confidence=conf, extra=extra, display={"overlays": overlays},
        )
