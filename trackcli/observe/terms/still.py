"""The still scene: a curve on pixels that kept the first frame's colours is not on the object.

With a still camera, a look-alike standing in the scene on the first frame is background
(:class:`trackcli.observe.scene.StillScene`).  From the second frame on, a curve loses
``observation.still_weight`` times the template's score on its first frame (at least 0.5 per
normal, times the normals), in proportion to its stillness, and the estimate's confidence is
multiplied by one less its stillness.  With the discriminant only (the penalty is in its units).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from trackcli.observe.terms import FrameView, Start, Term


class StillTerm(Term):
    """``-still_weight · M · max(reference, 0.5) · stillness(X)`` (module docstring)."""

    name = "still"
    compiled = True
    presence_units = True
    compares_frames = True

    @classmethod
    def build(cls, settings: Any) -> Term | None:
        # the frames are compared with the first whatever still_weight: the exposure the
        # comparison finds also brings the colour model back to the first frame's light
        return cls(settings) if settings.observation.likelihood == "discriminant" else None

    def start(self, first: Start) -> None:
        self.scene = first.scene
        self.penalty = (self.settings.observation.still_weight * self.settings.measurement.n_normals
                        * max(first.presence.reference, 0.5))

    def prepare(self, frame: FrameView) -> bool:
        self.still = frame.still
        return not frame.first and self.settings.observation.still_weight > 0

    def log_likelihood(self, X: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        return -(self.penalty * self.scene.stillness(self.still, points, normals))

    def confidence(self, points: np.ndarray, normals: np.ndarray) -> float | None:
        return 1.0 - float(self.scene.stillness(self.still, points, normals))
