"""Observation: features along the measurement normals and the likelihoods built on them.

- :mod:`.measure` — the feature image, the search for edge features along each normal
  (AC §8.3–8.4), the Kalman tracker's feature per normal and their aggregation into the
  information form ``Z, S`` (AC Fig 8.6), the clutter likelihood of CONDENSATION (AC eq
  12.2, :func:`.measure.log_likelihood`) and the truncated Gaussian of Isard & Blake 1996
  (eqs 10–11, :func:`.measure.truncated_log_likelihood`).
- :mod:`.discriminant` — the contour discriminant of MacCormick & Blake (a likelihood
  ratio per normal, object against clutter), the appearance learned on the first frame
  (edge polarity per normal, colour), the confidence, and the colour proposal for
  re-acquisition by importance sampling.
- :mod:`.presence` — that model set up for one clip: every tracker's confidence and
  ``lost`` verdict.
- :mod:`.models` — the observation models chosen by name (``condensation.likelihood``).
"""
