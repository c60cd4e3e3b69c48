"""The observation model: ``log p(Z | X)`` of hypothesised curves on one frame, a sum of terms.

One :class:`Observation` per tracked clip.  It learns the object's appearance from the
template on the first frame (:class:`~trackcli.observe.presence.Presence`: the colour model,
the edge polarity, the template's own score), and, when a term asks for it, keeps that frame
to compare later ones with (:class:`~trackcli.observe.scene.StillScene`).  Its terms
(:mod:`trackcli.observe.terms`) are the ones the settings switch on, in the order of
:data:`~trackcli.observe.terms.TERMS`:

>>> obs = Observation(settings, space, sampler)            # doctest: +SKIP
>>> obs.start(frame, X0)                                   # the first frame
>>> ev = obs.prepare(frame, centre)                        # every frame, the first included
>>> ll = obs.log_likelihood(X)                             # (N, Nx) -> (N,), any block, any thread
>>> conf, log_d, score = obs.confidence(ev, pts, nrm, spread)

The weights CONDENSATION gives its samples are ``power · log p(Z | X)``: :attr:`power` is
``observation.discriminant_power`` with the discriminant (a tempered likelihood, see
:class:`~trackcli.trackers.condensation_tracker.CondensationTracker`), 1 with the papers'
models.  The confidence and ``lost`` verdict of every contour tracker come from
:meth:`confidence`.

The outline drawn for each frame is not part of this model: it is refined from the estimate
after the tracker's step (:mod:`trackcli.observe.region`), on the frame's pixels.
"""

from __future__ import annotations

import logging
from typing import Any, Iterable

import numpy as np

from trackcli.observe.appearance import GREY_BINS, TEXTURE_BINS, colour_map, polygon_mask
from trackcli.observe.discriminant import FrameEvidence
from trackcli.observe.presence import Presence
from trackcli.observe.scene import StillScene
from trackcli.observe.terms import TERMS, FrameView, Start, Term, term_class
from trackcli.shapes.outline import contour_summary

log = logging.getLogger(__name__)


class Observation:
    """The observation model of one clip (module docstring).

    Parameters
    ----------
    settings : Settings
        Its sections ``observation`` and ``measurement`` are read.
    space : ShapeSpace
        The shape-space of the curves scored.
    sampler : CurveSampler
        Their measurement points (:func:`trackcli.shapes.outline.measurement_sampler`).
    terms : iterable of str, optional
        The names of :data:`~trackcli.observe.terms.TERMS` that may take part (default: all of
        them); each of these that the settings switch on does.
    label : str
        What log messages call the clip.
    """

    def __init__(self, settings: Any, space: Any, sampler: Any, *, terms: Iterable[str] | None = None,
                 label: str = ""):
        self.settings = settings
        self.space = space
        self.sampler = sampler
        self.label = label
        names = list(TERMS) if terms is None else list(terms)
        built = (term_class(name).build(settings) for name in names)
        self.terms: list[Term] = [t for t in built if t is not None]
        self.active: list[Term] = []
        self.presence: Presence | None = None
        self.scene: StillScene | None = None
        self.frames = 0
        #: the exponent on the likelihood in CONDENSATION's weights
        self.power = (settings.observation.discriminant_power
                      if any(t.name == "discriminant" for t in self.terms) else 1.0)
        #: every term is scored by compiled code that releases the GIL
        self.compiled = all(t.compiled for t in self.terms)
        #: the log-likelihood is in the presence score's units (a mean per normal can be judged)
        self.presence_units = bool(self.terms) and all(t.presence_units for t in self.terms)

    @property
    def names(self) -> list[str]:
        """The names of the terms that take part."""
        return [t.name for t in self.terms]

    def start(self, frame: Any, X0: np.ndarray) -> None:
        """Learn the appearance from the template ``X0`` on the first ``frame`` (image and
        feature image), and start every term."""
        s, space = self.settings, self.space
        presence = Presence.learn(frame.image, frame.features, space, self.sampler, X0, s.measurement,
                                  s.observation)
        if any(t.compares_frames for t in self.terms):
            poly, _, _ = contour_summary(space, X0)
            own = polygon_mask(poly, frame.image.shape)  # the object's place: never judged
            self.scene = StillScene(frame.image, own, presence.app.size, area=presence.area)
        first = Start(frame.image, frame.features, space, self.sampler, np.asarray(X0, dtype=float), presence,
                      self.scene)
        for term in self.terms:
            term.start(first)
        self.presence = presence  # last: another thread's frame_maps reads it (and the scene) once set
        self._log_start(presence, frame.index)

    def _log_start(self, presence: Presence, index: int) -> None:
        where = f"{self.label}: " if self.label else ""
        area = presence.area
        if area is not None:
            log.info("%sletterbox or pillarbox bars: the picture is x %d-%d, y %d-%d; the bars count as "
                     "beyond the frame's edge", where, area[0], area[2] - 1, area[1], area[3] - 1)
        if presence.app.grey:
            log.info("%sframe %d has no colour: the colour model is a histogram of %d grey levels x %d levels "
                     "of local texture", where, index, GREY_BINS, TEXTURE_BINS)
        if not presence.reference > 0:
            log.warning("%sthe template scores %.2f per normal on frame %d, no more object-like than clutter: "
                        "the lost verdict and the confidence will be unreliable (a tighter outline, or the "
                        "object on another frame, may do better)", where, presence.reference, index)

    def frame_maps(self, image: np.ndarray) -> tuple[Any, np.ndarray | None]:
        """``(colour map, still map)`` of a frame, once the appearance is learned (else ``(None,
        None)``): what depends on the frame alone.  Any thread may call it (it reads only what
        :meth:`start` made); the colour map is read in the first frame's exposure when the
        comparison with the first frame finds the light changed over the whole scene."""
        presence, scene = self.presence, self.scene
        if presence is None:
            return None, None
        still, exposure = scene.measure(image) if scene is not None else (None, None)
        return colour_map(presence.app, image, exposure), still

    def prepare(self, frame: Any, centre: np.ndarray) -> FrameEvidence:
        """The frame's evidence, the clutter density measured about ``centre``; every term takes
        the frame.  ``frame`` has ``image`` and ``features``, and its colour and still maps
        when they were made ahead (``colour``, ``still``: :meth:`frame_maps`)."""
        first = self.frames == 0
        self.frames += 1
        colour, still = getattr(frame, "colour", None), getattr(frame, "still", None)
        if not first and self.scene is not None and (colour is None or still is None):
            colour, still = self.frame_maps(frame.image)  # not made ahead
        ev = self.presence.evidence(frame.image, frame.features, centre, colour)
        view = FrameView(int(frame.index), frame.image, ev, still, first)
        self.active = [t for t in self.terms if t.prepare(view)]
        return ev

    def log_likelihood(self, X: np.ndarray) -> np.ndarray:
        """``log p(Z | X)`` of shapes ``X`` (N, Nx) on the prepared frame: (N,)."""
        pts, nrm = self.space.points_normals(X, self.sampler)
        return self.score(X, pts, nrm)

    def score(self, X: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """:meth:`log_likelihood` of curves already sampled: ``points``, ``normals`` (N, M, 2)."""
        total = None
        for term in self.active:
            value = term.log_likelihood(X, points, normals)
            total = value if total is None else total + value
        return np.zeros(np.shape(X)[0]) if total is None else total

    def posterior_score(self, weights: np.ndarray, loglik: np.ndarray) -> float | None:
        """The evidence per normal a weighted sample set puts on the object (the weighted mean of
        its log-likelihoods per normal), or None when the terms are not in the presence score's units."""
        if not self.presence_units:
            return None
        held = weights > 0
        return float(weights[held] @ loglik[held]) / self.settings.measurement.n_normals

    def confidence(self, ev: FrameEvidence, points: np.ndarray, normals: np.ndarray, spread: float,
                   posterior_score: float | None = None, centre: float | None = None) -> tuple[float, float, float]:
        """``(confidence, log D, score)`` of one curve (points and normals (M, 2)) as
        :meth:`~trackcli.observe.presence.Presence.confidence` gives them, the confidence also
        multiplied by the factor of every term that has a say in it on this frame."""
        conf, log_d, score = self.presence.confidence(ev, points, normals, spread, posterior_score=posterior_score,
                                                      centre=centre)
        for term in self.active:
            factor = term.confidence(points, normals)
            if factor is not None:
                conf *= factor
        return conf, log_d, score
