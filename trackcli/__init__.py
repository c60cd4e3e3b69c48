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
"""

__version__ = "0.1.0"
