"""Observation models: ``log p(Z | X)`` of a block of curves on one frame's features.

A model is chosen by name (``condensation.likelihood``) and used the same way by every
tracker that weights hypotheses:

>>> model = observation_model("clutter", measurement, settings)    # doctest: +SKIP
>>> model.start(image, fimg, space, sampler, X0)                    # first frame
>>> model.prepare(image, fimg, centre)                              # every frame
>>> log_lik = model.log_likelihood(points, normals)                 # (N, M, 2) each -> (N,)

- ``clutter``: AC eq 12.2, :func:`trackcli.observe.measure.log_likelihood`;
- ``truncated``: the truncated Gaussian of Isard & Blake 1996, eqs 10–11,
  :func:`trackcli.observe.measure.truncated_log_likelihood`;
- ``discriminant``: the contour discriminant with polarity and colour learned on the first
  frame (:class:`trackcli.observe.presence.Presence`).

The Kalman tracker's measurement, the nearest feature on each normal aggregated into the
information form ``Z, S`` (AC Fig 10.3), is :func:`nearest_feature_information`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from trackcli.errors import ConfigError
from trackcli.settings import CondensationSettings, MeasurementSettings
from trackcli.observe import measure
from trackcli.observe.presence import Presence

LIKELIHOODS = ("discriminant", "clutter", "truncated")


class ObservationModel:
    """``log p(Z | X)`` per curve; :meth:`start` on the first frame, :meth:`prepare` on each."""

    name = ""

    def __init__(self, measurement: MeasurementSettings, settings: CondensationSettings):
        self.measurement = measurement
        self.settings = settings
        self._fimg: np.ndarray | None = None

    def start(self, image: np.ndarray, fimg: np.ndarray, space: Any, sampler: Any, X0: np.ndarray,
              presence: Presence | None = None) -> None:
        """Learn what the model needs from the template on the first frame (nothing here)."""

    def prepare(self, image: np.ndarray, fimg: np.ndarray, evidence: Any = None) -> None:
        """Set the frame the next :meth:`log_likelihood` calls score against."""
        self._fimg = fimg

    def log_likelihood(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class ClutterModel(ObservationModel):
    """AC eq 12.2: Gaussian localisation error, Poisson clutter of density ``alpha``."""

    name = "clutter"

    def log_likelihood(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        s, m = self.settings, self.measurement
        return measure.log_likelihood(self._fimg, points, normals, h=s.search, sigma=s.sigma, alpha=s.alpha,
                                      threshold=m.threshold, polarity=m.polarity)


class TruncatedModel(ObservationModel):
    """Isard & Blake 1996 eqs 10–11: the nearest feature, its distance truncated at ``search``."""

    name = "truncated"

    def log_likelihood(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        s, m = self.settings, self.measurement
        return measure.truncated_log_likelihood(self._fimg, points, normals, h=s.search, sigma=s.sigma,
                                                threshold=m.threshold, polarity=m.polarity)


class DiscriminantModel(ObservationModel):
    """The contour discriminant with the appearance learned on the first frame."""

    name = "discriminant"

    def start(self, image, fimg, space, sampler, X0, presence=None) -> None:
        self.presence = presence if presence is not None else Presence.learn(
            image, fimg, space, sampler, X0, self.measurement, self.settings)

    def prepare(self, image, fimg, evidence=None) -> None:
        super().prepare(image, fimg)
        self._evidence = evidence

    def log_likelihood(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        return self.presence.score(self._evidence, points, normals)


_MODELS = {cls.name: cls for cls in (ClutterModel, TruncatedModel, DiscriminantModel)}


def observation_model(name: str, measurement: MeasurementSettings, settings: CondensationSettings) -> ObservationModel:
    """The observation model called ``name`` (one of :data:`LIKELIHOODS`)."""
    if name not in _MODELS:
        raise ConfigError(f"condensation.likelihood: expected one of {', '.join(LIKELIHOODS)}, got {name!r}")
    return _MODELS[name](measurement, settings)


def nearest_feature_information(fimg: np.ndarray, points: np.ndarray, normals: np.ndarray, h: np.ndarray,
                                gates: np.ndarray, sigma: float, measurement: MeasurementSettings,
                                max_half_width: float) -> tuple[np.ndarray, np.ndarray, Any]:
    """The Kalman tracker's measurement of one curve (AC Fig 8.6 sums, assimilated as in Fig 10.3).

    The nearest feature on each normal within its gate (:func:`measure.kalman_features`),
    aggregated with the measurement vectors ``h`` into the information ``Z, S`` of the
    innovation.  Returns ``(Z, S, features)``.
    """
    feats = measure.kalman_features(fimg, points, normals, gates, threshold=measurement.threshold,
                                    polarity=measurement.polarity, max_half_width=max_half_width)
    Z, S = measure.aggregate(h, feats.nu, feats.found, sigma)
    return Z, S, feats
