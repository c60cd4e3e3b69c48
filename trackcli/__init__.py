"""trackcli: follow the outline of an object through video, even in clutter.

Notation used throughout the package (Blake & Isard, *Active Contours*, "AC"):

- Image coordinates are ``(x, y)`` in pixels, ``x`` to the right, ``y`` down, with
  the centre of the top-left pixel at ``(0, 0)``.  Point arrays have shape ``(..., 2)``
  in that order; conversion to ``(row, col)`` happens only where images are indexed.
- ``Q`` is a curve's stacked control vector ``(Qx; Qy)`` of length ``2 * Nq``.
- ``X`` is a shape vector of length ``Nx`` in a shape-space ``Q = W X + Q0``.
- ``A1, A2, B0`` and the mean ``X̄`` define AR(2) dynamics (AC eq 9.15); ``tau`` is
  the frame interval in seconds.
- Every stochastic function takes a ``numpy.random.Generator`` called ``rng``.

The package is layered, each part importing only those below it (``tests/test_layering.py``
holds the table): :mod:`trackcli.errors` < :mod:`trackcli.io.outputs` <
:mod:`trackcli.settings` < :mod:`trackcli.io` (file formats) < :mod:`trackcli.shapes` <
:mod:`trackcli.dynamics` (models, their Kalman filter and smoother, learning) and, beside it,
:mod:`trackcli.sample_data` < :mod:`trackcli.observe` < :mod:`trackcli.trackers` <
:mod:`trackcli.run` < :mod:`trackcli.cli`.  Each package's docstring says what lives where.
"""

__version__ = "0.1.0"
