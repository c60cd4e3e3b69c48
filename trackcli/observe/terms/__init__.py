"""The terms of the observation model, by name, and what a term is.

The observation model (:class:`trackcli.observe.observation.Observation`) scores hypothesised
curves on one frame by the sum of its terms' log-likelihoods.  A term is a :class:`Term`
subclass in a module of this package, listed in :data:`TERMS`; every term listed is asked
(:meth:`Term.build`) whether the settings switch it on.  Terms in order:

- ``discriminant``, ``clutter``, ``truncated`` (:mod:`.edges`): the edge likelihood chosen by
  ``observation.likelihood``: the contour discriminant with the colour learned on the first
  frame, AC eq 12.2, or Isard & Blake's truncated Gaussian;
- ``still`` (:mod:`.still`): with the discriminant, a curve on the first frame's scene (a
  look-alike standing still) loses ``observation.still_weight`` times the template's score.

A new term: one module here with its :class:`Term` subclass, and one line in :data:`TERMS`
(settings of its own, if it has any, go in :class:`trackcli.settings.ObservationSettings`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from trackcli.registry import lookup

#: the terms by name: ``module:class`` of a :class:`Term`, imported when first used; their
#: log-likelihoods are added in this order
TERMS: dict[str, str] = {
    "discriminant": "trackcli.observe.terms.edges:DiscriminantTerm",
    "clutter": "trackcli.observe.terms.edges:ClutterTerm",
    "truncated": "trackcli.observe.terms.edges:TruncatedTerm",
    "still": "trackcli.observe.terms.still:StillTerm",
}


def term_class(name: str) -> type[Term]:
    """The :class:`Term` subclass called ``name`` (a key of :data:`TERMS`)."""
    return lookup(TERMS, name, "observation term")


@dataclass(frozen=True, eq=False)
class Start:
    """What a term may learn from on the tracker's first frame."""

    image: np.ndarray
    """The first frame, BGR."""
    features: np.ndarray
    """Its feature image (:func:`trackcli.observe.measure.feature_image`)."""
    space: Any
    """The shape-space (:class:`trackcli.shapes.shape_space.ShapeSpace`)."""
    sampler: Any
    """The measurement points' sampler of the curves scored."""
    X0: np.ndarray
    """The template's shape on the first frame."""
    presence: Any
    """The appearance learned from the template (:class:`trackcli.observe.presence.Presence`)."""
    scene: Any = None
    """The first frame to compare later frames with (:class:`trackcli.observe.scene.StillScene`),
    when a term asked for it (:attr:`Term.compares_frames`)."""


@dataclass(frozen=True, eq=False)
class FrameView:
    """One frame as the terms read it."""

    index: int
    image: np.ndarray
    """The frame, BGR."""
    evidence: Any
    """Its evidence (:class:`trackcli.observe.discriminant.FrameEvidence`): ``fimg`` the feature
    image without letterbox bars, ``cmap`` the colour log-ratio map, ``density`` the clutter."""
    still: np.ndarray | None
    """Where it kept the first frame's colours (:meth:`trackcli.observe.scene.StillScene.compare`),
    when frames are compared; else None."""
    first: bool
    """The frame the tracker started on."""


class Term(ABC):
    """One term of ``log p(Z | X)``: built from the settings, started on the first frame, prepared
    on each frame, then asked for the log-likelihood of blocks of curves.

    :meth:`log_likelihood` may be called from several threads at once on different blocks
    (:func:`trackcli.trackers.condensation.weigh`): it must only read what :meth:`start` and
    :meth:`prepare` set.
    """

    name: ClassVar[str] = ""
    #: scored by compiled code that releases the GIL (threads pay from a few hundred samples;
    #: for numpy code only from a few thousand)
    compiled: ClassVar[bool] = False
    #: its log-likelihood is in the units of the presence score times the normals (the
    #: discriminant's), so that the posterior's mean score per normal can be judged by the confidence
    presence_units: ClassVar[bool] = False
    #: it reads each frame's comparison with the first (:attr:`FrameView.still`)
    compares_frames: ClassVar[bool] = False

    def __init__(self, settings: Any):
        self.settings = settings

    @classmethod
    def build(cls, settings: Any) -> Term | None:
        """The term under ``settings`` (:class:`trackcli.settings.Settings`), or None when they switch it off."""
        return cls(settings)

    def start(self, first: Start) -> None:
        """Learn what the term needs on the first frame (nothing by default)."""

    def prepare(self, frame: FrameView) -> bool:
        """Take the frame the next :meth:`log_likelihood` calls score; False: the term adds
        nothing on this frame."""
        return True

    @abstractmethod
    def log_likelihood(self, X: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """The term's ``log p(Z | X)`` of ``N`` curves: shapes ``X`` (N, Nx), their measurement
        points and unit normals (N, M, 2) -> (N,)."""

    def confidence(self, points: np.ndarray, normals: np.ndarray) -> float | None:
        """A factor in [0, 1] on the confidence of the estimate (points and normals (M, 2)), or
        None: the term has no say in it."""
        return None
