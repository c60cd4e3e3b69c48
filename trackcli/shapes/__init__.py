"""Curves and the spaces they move in.

- :mod:`.spline` — B-spline bases, sampling of points and normals along a curve, dense
  polygons, area centroid (AC ch. 3), and the least-squares fit of a curve to points
  (:func:`.spline.fit`).
- :mod:`.shape_space` — the shape-space ``Q = W X + Q0`` (AC ch. 4, eq 4.1): Euclidean,
  similarity and affine spaces, measurement vectors ``h(s)`` along the normals (AC eq 6.4).
- :mod:`.template` — the template file (a curve drawn on one frame).
- :mod:`.draw` — headless outline extraction for templates (points, shapes, boxes, masks).
"""
