"""The discriminant observation model set up for one clip, and the confidence it gives.

:class:`Presence` learns the appearance of :mod:`trackcli.observe.discriminant` from the
template on the first frame; it scores hypothesised curves (CONDENSATION's default
likelihood) and gives every tracker its per-frame confidence and ``lost`` verdict.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from trackcli.settings import MeasurementSettings, ObservationSettings
from trackcli.observe import appearance
from trackcli.observe import discriminant as observe
from trackcli.shapes.outline import contour_summary
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.shapes.spline import CurveSampler


@dataclass(frozen=True, eq=False)
class Presence:
    """The observation model of :mod:`trackcli.observe.discriminant`, set up for one clip.

    Learned from the template on the first frame; gives the discriminant log-likelihood of
    hypothesised curves (CONDENSATION's default) and, for both trackers, the per-frame
    confidence and ``lost`` verdict.  Letterbox or pillarbox bars found on the first frame
    (``area``, :func:`~trackcli.observe.appearance.picture_area`) count in every frame's
    evidence as beyond the frame's edge.
    """

    app: observe.Appearance
    h: float
    sigma: float
    threshold: float
    miss: float
    colour_weight: float
    centre: float
    reference: float = math.nan
    area: tuple[int, int, int, int] | None = None
    visible_start: float = 1.0
    """The share of the template's outline inside the frame (its picture) on the first frame: an
    object the frame's edge cuts from the start (a bust) is not judged on what it never showed."""

    @classmethod
    def learn(cls, image: np.ndarray, fimg: np.ndarray, space: ShapeSpace, sampler: CurveSampler, X0: np.ndarray,
              measurement: MeasurementSettings, settings: ObservationSettings) -> Presence:
        pts, nrm = space.points_normals(X0, sampler)
        poly, _, _ = contour_summary(space, X0)
        area = appearance.picture_area(image)
        app = appearance.learn_appearance(image, fimg if area is None else appearance.without_bars(fimg, area), pts, nrm,
                                       poly, h=settings.search, sigma=settings.sigma, threshold=measurement.threshold)
        judge = cls(app, settings.search, settings.sigma, measurement.threshold, settings.miss_probability,
                    settings.colour_weight, measurement.presence_centre, area=area)
        ev = judge.evidence(image, fimg, space.origin + X0[:2])
        reference, _, _ = observe.presence(app, ev, pts, nrm, h=judge.h, sigma=judge.sigma, threshold=judge.threshold,
                                           miss=judge.miss, colour_weight=judge.colour_weight)
        start = observe.visible_share(pts, image.shape, area)
        return dataclasses.replace(judge, reference=reference, visible_start=start if start > 0 else 1.0)

    def evidence(self, image: np.ndarray, fimg: np.ndarray, centre: np.ndarray,
                 colour: np.ndarray | None = None) -> observe.FrameEvidence:
        """The frame's evidence; with bars, its feature image without them (``ev.fimg``), its
        colour map 0 on them, and ``ev.area`` the picture.  ``colour``: the frame's colour map
        (``app.colour_map``) if already made (it is changed in place on the bars)."""
        if self.area is None:
            return observe.evidence(self.app, image, fimg, centre, self.threshold, cmap=colour)
        ev = observe.evidence(self.app, image, appearance.without_bars(fimg, self.area), centre, self.threshold,
                              cmap=colour)
        appearance.clear_bars(ev.cmap, self.area)
        return dataclasses.replace(ev, area=self.area)

    def score(self, ev: observe.FrameEvidence, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
        return observe.score(self.app, ev, pts, nrm, h=self.h, sigma=self.sigma, threshold=self.threshold,
                             miss=self.miss, colour_weight=self.colour_weight)

    def confidence(self, ev: observe.FrameEvidence, pts: np.ndarray, nrm: np.ndarray, spread: float,
                   posterior_score: float | None = None, centre: float | None = None) -> tuple[float, float, float]:
        """``(confidence, log D, log-likelihood)`` of one curve, ``spread`` its positional spread in
        object sizes; ``log D`` is the sum over the whole curve, the log-likelihood the curve's
        :meth:`score` (the trackers' weight, in which a normal beyond the frame's edge counts as
        the mean of those in view when that is negative), and the confidence judges the normals
        in the frame (:func:`observe.presence`).

        ``posterior_score``, when given, is the presence score the sample set puts on the
        object (its weighted mean score per normal); the larger of it and the curve's own
        score is judged, so that a mean curve a few pixels off a well-supported posterior, or
        between the modes of one, is not called lost when the samples are on the object.
        ``centre``, when given, replaces :attr:`centre` (the share of the reference at which
        the confidence is 0.5).
        """
        log_d, colour = observe.per_normal(self.app, ev, pts, nrm, h=self.h, sigma=self.sigma,
                                           threshold=self.threshold, miss=self.miss)
        seen = observe.in_picture(pts, ev.fimg.shape, ev.area)
        s, _, _ = observe.presence_in_view(log_d, colour, seen, self.colour_weight)
        e = float(log_d.sum())  # the whole curve's
        total = float(self.score(ev, pts, nrm))  # as the trackers weigh it (beyond the frame's edge: see score)
        if posterior_score is not None and math.isfinite(posterior_score):
            s = max(s, posterior_score)
        visible = min(1.0, float(seen.mean()) / self.visible_start)
        conf = observe.confidence(s, spread, reference=self.reference,
                                  centre=self.centre if centre is None else centre, visible=visible)
        return conf, e, total
