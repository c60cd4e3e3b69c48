"""Observation: features along the measurement normals and the likelihoods built on them.

- :mod:`.observation` — the observation model of a clip, :class:`.observation.Observation`:
  ``log p(Z | X)`` as the sum of its terms, the tempering, the confidence; what the trackers
  call.
- :mod:`.terms` — its terms by name (:data:`.terms.TERMS`): the edge likelihood
  (discriminant, clutter or truncated, ``observation.likelihood``) and the still scene; a
  new term is one module there and one registry line.
- :mod:`.measure` — the feature image, the search for edge features along each normal
  (AC §8.3–8.4), the Kalman tracker's feature per normal and their aggregation into the
  information form ``Z, S`` (AC Fig 8.6).
- :mod:`.likelihoods` — the clutter likelihood of CONDENSATION (AC eq 12.2) and the
  truncated Gaussian of Isard & Blake 1996 (eqs 10–11) on those features.
- :mod:`.discriminant` — the contour discriminant of MacCormick & Blake (a likelihood ratio
  per normal, object against clutter, with a colour term) and the confidence.
- :mod:`.appearance` — the appearance learned on the first frame (edge polarity per
  normal, colour model and maps), letterbox bars, the first frame's exposure.
- :mod:`.presence` — that model set up for one clip: every tracker's confidence and
  ``lost`` verdict.
- :mod:`.scene` — the first frame kept to compare later frames with (a look-alike standing
  still; a change of light over the whole scene).
- :mod:`.reacquire` — the colour proposal for re-acquisition by importance sampling.
- :mod:`.region` — the drawn outline refined in the full image after each estimate.
- :mod:`.kernels` — the compiled loops.
"""
