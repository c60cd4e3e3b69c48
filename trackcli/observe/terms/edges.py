"""The edge likelihood, one of three by ``observation.likelihood``.

- ``discriminant``: the contour discriminant with edge polarity and colour learned on the first
  frame (:mod:`trackcli.observe.discriminant`), in the presence score's units;
- ``clutter``: AC eq 12.2 (:func:`trackcli.observe.likelihoods.log_likelihood`);
- ``truncated``: Isard & Blake 1996 eqs 10–11 (:func:`trackcli.observe.likelihoods.truncated_log_likelihood`).

The discriminant reads the colour term along the same normals as the edges, in one pass of
its compiled kernel (``observation.colour_weight`` is its ``w_c``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from trackcli.observe import likelihoods
from trackcli.observe.terms import FrameView, Start, Term


class EdgeTerm(Term):
    """A term that is on when ``observation.likelihood`` names it."""

    @classmethod
    def build(cls, settings: Any) -> Term | None:
        return cls(settings) if settings.observation.likelihood == cls.name else None


class DiscriminantTerm(EdgeTerm):
    """The contour discriminant (:meth:`trackcli.observe.presence.Presence.score`)."""

    name = "discriminant"
    compiled = True
    presence_units = True

    def start(self, first: Start) -> None:
        self.presence = first.presence

    def prepare(self, frame: FrameView) -> bool:
        self.evidence = frame.evidence
        return True

    def log_likelihood(self, X: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        return self.presence.score(self.evidence, points, normals)


class ClutterTerm(EdgeTerm):
    """AC eq 12.2: Gaussian localisation error, Poisson clutter of density ``alpha``."""

    name = "clutter"

    def prepare(self, frame: FrameView) -> bool:
        self.fimg = frame.evidence.fimg
        return True

    def log_likelihood(self, X: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        o, m = self.settings.observation, self.settings.measurement
        return likelihoods.log_likelihood(self.fimg, points, normals, h=o.search, sigma=o.sigma, alpha=o.alpha,
                                          threshold=m.threshold, polarity=m.polarity)


class TruncatedTerm(ClutterTerm):
    """Isard & Blake 1996 eqs 10–11: the nearest feature, its distance truncated at ``search``."""

    name = "truncated"

    def log_likelihood(self, X: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        o, m = self.settings.observation, self.settings.measurement
        return likelihoods.truncated_log_likelihood(self.fimg, points, normals, h=o.search, sigma=o.sigma,
                                                    threshold=m.threshold, polarity=m.polarity)
