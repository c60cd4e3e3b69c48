"""Curves and the spaces they move in.

- :mod:`.spline` — B-spline bases (AC ch 3), sampling of points and normals along a curve,
  dense polygons, area centroid, the curve norm (AC eqs 8.5–8.6), and the least-squares fit
  of a curve to points.
- :mod:`.shape_space` — shape-spaces ``Q = W X + Q0`` (AC ch 4 and §8.4): translation,
  similarity, affine, key-frame and PCA spaces, the metric ``H`` (AC eq 8.6) and the
  measurement vectors along the normals.
- :mod:`.outline` — what a shape vector looks like as a curve: contour, centroid, box, the
  object's size, the measurement points.
- :mod:`.template` — the template file (a curve drawn on one frame).
- :mod:`.structure` — structure templates: parts with their patches (003).
- :mod:`.draw` — outlines to draw templates from: parsed points, ellipses, their checks and
  polygon geometry (masks and boxes are segmented in :mod:`trackcli.segment`).
"""
