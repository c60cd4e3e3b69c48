"""Curves and the spaces they move in.

The package sits above the settings and the file formats (:mod:`trackcli.io`) and below
everything else (``tests/test_layering.py``).

- :mod:`.spline` — B-spline bases (AC ch 3), sampling of points and normals along a curve,
  dense polygons, area centroid, the curve norm (AC eqs 8.5–8.6).
- :mod:`.fit` — the least-squares fit of a curve to ordered points.
- :mod:`.space` — the shape-space value ``Q = W X + Q0`` (AC ch 4 and §8.4,
  :class:`.space.ShapeSpace`): the metric ``H`` (AC eq 8.6), projection, the measurement
  vectors along the normals, pose, projectors, serialisation; the columns of the
  constructive spaces.
- :mod:`.shape_space` — making shape-spaces: translation, similarity, affine, key-frame and
  PCA spaces (AC eqs 8.26–8.27); ``ShapeSpace`` is importable from here too.
- :mod:`.outline` — what a shape vector looks like as a curve: contour, centroid, box, the
  object's size, the measurement points.
- :mod:`.template` — the template file (a curve drawn on one frame).
- :mod:`.structure` — structure templates: parts with their patches (003).
- :mod:`.draw` — outlines to draw templates from: parsed points, ellipses, their checks and
  polygon geometry (masks and boxes are segmented in :mod:`trackcli.segment`).
"""
