"""Mixed-state dynamics on one shape-space: the prediction step of 001 §8 and the bounce event.

A :class:`~trackcli.dynamics.mixed.MixedModel` placed on a clip's shape-space
(:func:`build_dynamics`) gives :class:`MixedDynamics`: a model per label, an
:class:`~trackcli.dynamics.ar2.AR2` or a :class:`Bounce`, and the transition matrix ``T``.
One prediction step first draws the new label ``y_k = j`` with probability ``T[i, j]``,
``i`` the sample's old label, and then draws the continuous state from the model of the
*old* label.  :class:`MixedPrediction` is that step as CONDENSATION's motion hook.

The bounce (``bounce:``): ``floor: Y`` is the horizontal line ``y = Y`` (image pixels,
``y`` down) with the object above it; ``line: {point: [x, y], normal: [nx, ny]}`` is any
line, ``normal`` pointing to the side the object moves on.  ``base`` names the AR(2) label
whose model moves the shape's other components, and the whole shape when the step does
not reach the line.  When a sample moving towards the line with velocity ``v`` (its last
translation step) would carry the outline's extreme point towards the line (measured on the
template's outline) past the line by ``s`` in a free step ``p + v``, the bounce happens
within the frame interval: the normal part of the velocity is reversed and multiplied by
``restitution``, the tangential part by ``friction``::

    v' = friction (v - (v·n) n) - restitution (v·n) n

and the outline lands mirrored at the line, ``p + v + (1 + restitution) s n``, moving on
with velocity ``v'``.  The new position gets the base label's noise, plus Gaussian noise
along the normal of RMS ``noise · |v·n|`` (an uncertain restitution: the faster the impact,
the less certain the rebound).  A sample that does not reach the line moves as the base
label moves it, so in free flight the two labels explain the data equally and the bounce
label keeps its prior probability; at a bounce only the bounce label can follow.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from trackcli.dynamics.ar2 import AR2, predict_samples
from trackcli.dynamics.mixed import MixedModel
from trackcli.errors import ConfigError, ModelError

__all__ = ["Bounce", "MixedDynamics", "MixedPrediction", "build_dynamics"]


@dataclass(frozen=True, eq=False)
class Bounce:
    """A :class:`~trackcli.dynamics.mixed.BounceSpec` placed on a shape-space (line in pixels)."""

    base: int
    point: np.ndarray
    normal: np.ndarray
    restitution: float
    friction: float
    noise: float
    contact: float  # distance from the reference point to the outline's extreme point towards the line

    def predict(self, prev: np.ndarray, cur: np.ndarray, base_new: np.ndarray, base_noise: np.ndarray,
                origin: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(prev', new, hit)`` of samples given the bounce label: where the step reaches the
        line (``hit``), ``new`` is ``base_new`` with the translation replaced by the bounce and
        ``prev'`` is ``new`` less the velocity after it; elsewhere ``base_new`` and ``cur``."""
        n = self.normal
        v = cur[:, :2] - prev[:, :2]
        vn = v @ n
        v_out = self.friction * (v - vn[:, None] * n) - self.restitution * vn[:, None] * n
        ref = cur[:, :2] + origin
        free = ref + v
        clearance = (free - self.point) @ n - self.contact
        hit = (vn < 0) & (clearance < 0)
        # the reflection at the contact, the base model's own noise, and the rebound's: along
        # the normal, in proportion to the speed of impact (an uncertain restitution)
        pos = free + (1.0 + self.restitution) * np.maximum(-clearance, 0.0)[:, None] * n
        pos += base_noise[:, :2] + (self.noise * np.abs(vn) * rng.standard_normal(vn.size))[:, None] * n
        new = base_new.copy()
        new[hit, :2] = pos[hit] - origin
        prev_out = cur.copy()
        prev_out[hit, :2] = new[hit, :2] - v_out[hit]
        return prev_out, new, hit


@dataclass(frozen=True, eq=False)
class MixedDynamics:
    """Mixed-state dynamics on one shape-space: a model per label and the transitions.

    ``models[i]`` is an :class:`~trackcli.dynamics.ar2.AR2` or a :class:`Bounce`.
    """

    names: tuple[str, ...]
    models: tuple[Any, ...]
    T: np.ndarray
    initial: np.ndarray
    origin: np.ndarray
    tau: float

    @property
    def n_labels(self) -> int:
        return len(self.names)

    @property
    def nx(self) -> int:
        return next(m.nx for m in self.models if isinstance(m, AR2))

    def ar2_labels(self) -> list[int]:
        return [i for i, m in enumerate(self.models) if isinstance(m, AR2)]

    def draw_initial(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` labels from the initial distribution."""
        return _draw(np.broadcast_to(self.initial, (n, self.n_labels)), rng)

    def draw_labels(self, old: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """New labels ``y_k ~ T[y_{k-1}, :]`` for every sample."""
        return _draw(self.T[np.asarray(old, dtype=np.int64)], rng)

    def predict(self, prev: np.ndarray, cur: np.ndarray, labels: np.ndarray,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(prev', new, log_w)``: each sample's ``X_k`` from the model of its label (the *old*
        one, 001 §8), the ``X_{k-1}`` its velocity is measured from afterwards (``cur``
        except after a bounce), and the log prior density factor of the event: ``-inf`` for a
        sample given an event label whose step does not reach the line (the event cannot
        happen there: the transition to it depends on the state, 001 §8), else 0.  Noise is
        drawn label by label in label order."""
        prev = np.asarray(prev, dtype=np.float64)
        cur = np.asarray(cur, dtype=np.float64)
        labels = np.asarray(labels, dtype=np.int64)
        new = np.empty_like(cur)
        prev_out = cur.copy()
        log_w = np.zeros(cur.shape[0])
        for i, model in enumerate(self.models):
            idx = np.flatnonzero(labels == i)
            if idx.size == 0:
                continue
            if isinstance(model, AR2):
                new[idx] = predict_samples(prev[idx], cur[idx], model, rng)
            else:
                ar = self.models[model.base]
                base = predict_samples(prev[idx], cur[idx], ar, rng)
                expected = ar.mean + (cur[idx] - ar.mean) @ ar.A1.T + (prev[idx] - ar.mean) @ ar.A2.T
                prev_out[idx], new[idx], hit = model.predict(prev[idx], cur[idx], base, base - expected,
                                                             self.origin, rng)
                log_w[idx[~hit]] = -np.inf
        return prev_out, new, log_w

    def simulate(self, n_frames: int, rng: np.random.Generator, *, x0: np.ndarray | None = None,
                 x1: np.ndarray | None = None, label0: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One sample path ``(n_frames, Nx)`` and the label that moved each frame in (frame 0:
        the starting label, drawn from the initial distribution unless ``label0``)."""
        nx = self.nx
        start = np.zeros(nx) if x0 is None else np.asarray(x0, dtype=float)
        second = start if x1 is None else np.asarray(x1, dtype=float)
        path = np.empty((max(n_frames, 2), nx))
        path[0], path[1] = start, second
        labels = np.zeros(max(n_frames, 2), dtype=np.int64)
        y = int(self.draw_initial(1, rng)[0]) if label0 is None else int(label0)
        # nothing has moved frames 0 and 1: an event label drawn first is shown as its base
        labels[0] = labels[1] = y if isinstance(self.models[y], AR2) else self.models[y].base
        prev, cur = start[None], second[None]
        for k in range(2, n_frames):
            y_new = int(self.draw_labels(np.array([y]), rng)[0])
            prev, new, log_w = self.predict(prev, cur, np.array([y]), rng)
            if not np.isfinite(log_w[0]):  # an event that cannot happen here: the base label moves it
                y = self.models[y].base
                prev, new, _ = self.predict(prev, cur, np.array([y]), rng)
            labels[k] = y
            path[k] = new[0]
            cur, y = new, y_new  # prev: X_{k-1} as the velocity sees it (moved by a bounce)
        return path[:n_frames], labels[:n_frames]


class MixedPrediction:
    """The prediction step of mixed-state CONDENSATION (001 §8), as a ``motion`` hook of
    :func:`trackcli.trackers.condensation.step`, with each sample's label.

    Each sample carries the label whose model moved it into the current frame (``moved``,
    the ``y_{k-1}`` of 001 §8).  A step draws every selected sample's next label from
    ``T[moved of its parent, :]`` and then its shape from that label's model.

    001 §8 draws a sample's new label when its shape is predicted and uses it for the next
    prediction; here the label is drawn one selection later, just before it is used.  The
    selection weights do not depend on it (the shape they weigh was moved by the label
    before), so the sample set has the same distribution, and the labels do not collapse
    when a selection keeps only a few parents.
    """

    def __init__(self, dynamics: MixedDynamics, n: int, rng: np.random.Generator):
        self.dynamics = dynamics
        self.moved = dynamics.draw_initial(n, rng)
        self.steps = 0

    def __call__(self, prev: np.ndarray, cur: np.ndarray, rng: np.random.Generator,
                 parents: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        labels = self.dynamics.draw_labels(self.moved[parents], rng)
        self.moved = labels
        self.steps += 1
        return self.dynamics.predict(prev, cur, labels, rng)

    def posterior(self, weights: np.ndarray) -> np.ndarray:
        """The posterior probability of each label having moved the samples into this frame
        (the sum of their weights); before any step, the initial distribution."""
        if self.steps == 0:
            return np.asarray(self.dynamics.initial, dtype=float)
        return np.bincount(self.moved, weights=weights, minlength=self.dynamics.n_labels)


def _draw(P: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One index per row of the probability rows ``P`` (inverse-CDF with one uniform each)."""
    c = np.cumsum(P, axis=1)
    u = rng.random(P.shape[0]) * c[:, -1]
    return np.minimum((u[:, None] >= c).sum(axis=1), P.shape[1] - 1)


def build_dynamics(model: MixedModel, space: Any, tau: float, *, X0: np.ndarray | None = None,
                   placed: Sequence[AR2 | None] | None = None) -> MixedDynamics:
    """The model's labels on ``space`` (frame interval ``tau``).

    Hand-set labels are built on ``space`` (:func:`~trackcli.dynamics.handset.handset_dynamics`);
    learned ones are taken from ``placed`` (the caller places them on this clip, as a single
    model) or used as they are.  A bounce measures its contact distance on the template's
    outline at ``X0``.
    """
    from trackcli.dynamics.handset import handset_dynamics
    from trackcli.shapes.outline import contour_summary

    X0 = np.zeros(space.Nx) if X0 is None else np.asarray(X0, dtype=float)
    names = model.names
    models: list[Any] = []
    for i, lab in enumerate(model.labels):
        if lab.ar2 is not None:
            ar = placed[i] if placed is not None and placed[i] is not None else lab.ar2
            if ar.nx != space.Nx:
                raise ModelError(f"label {lab.name}: {ar.nx} components, the shape-space has {space.Nx}")
            models.append(ar)
        elif lab.handset is not None:
            try:
                models.append(handset_dynamics(space, lab.handset, tau))
            except ConfigError as exc:
                raise ModelError(f"label {lab.name}: {exc}") from None
        else:
            models.append(None)
    contour, _, _ = contour_summary(space, X0)
    ref = np.asarray(space.origin, dtype=float) + X0[:2]
    for i, lab in enumerate(model.labels):
        if lab.bounce is None:
            continue
        b = lab.bounce
        n = np.asarray(b.normal, dtype=float)
        contact = float(np.max((ref - np.asarray(contour, dtype=float)) @ n))
        models[i] = Bounce(names.index(b.base), np.asarray(b.point, dtype=float), n, b.restitution, b.friction,
                           b.noise, contact)
    return MixedDynamics(tuple(names), tuple(models), model.T, model.initial_distribution(),
                         np.asarray(space.origin, dtype=float), float(tau))
