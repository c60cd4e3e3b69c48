"""Finding the object in a frame, as a mask, for the templates ``draw`` makes.

- :mod:`.masks` — masks read from files, their outline, their overlap.
- :mod:`.grabcut` — the object inside a box (GrabCut, leaks and colour pruning, the choice
  among candidate masks).

This layer sits above :mod:`trackcli.shapes` (outline geometry) and :mod:`trackcli.observe`
(grey frames and their texture), below :mod:`trackcli.run`, which fits the templates.
"""
