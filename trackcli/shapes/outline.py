"""What a shape vector looks like as a curve: sampling, summaries, size.

Functions of a :class:`~trackcli.shapes.shape_space.ShapeSpace` and a shape vector ``X``
that every tracker, the simulator and the smoothers use to turn ``X`` into image
quantities.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from trackcli.errors import ConfigError
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.shapes.spline import CurveSampler, curve_area_centroid, dense_polygon


def measurement_sampler(space: ShapeSpace, n_normals: int) -> CurveSampler:
    """The ``M`` measurement points equally spaced in the spline parameter."""
    basis = space.basis
    return basis.sampler(basis.measurement_params(n_normals))


def object_size(space: ShapeSpace) -> float:
    """The size of the template of ``space``: the square root of the area it encloses, px.

    For an open curve, the RMS distance of its control points from their mean.
    """
    Q0 = space.Q0
    if space.basis.closed:
        area, _ = curve_area_centroid(Q0, space.basis)
        return float(math.sqrt(abs(area)))
    n = space.Nq
    pts = np.column_stack([Q0[:n], Q0[n:]])
    return float(np.sqrt(((pts - pts.mean(axis=0)) ** 2).sum(axis=1).mean()))


def contour_summary(space: ShapeSpace, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """Dense contour ``(P, 2)``, area centroid ``(2,)`` and box ``(x, y, w, h)`` of shape ``X``."""
    Q = space.to_control(X)
    poly = dense_polygon(Q, space.basis)
    if space.basis.closed:
        _, centroid = curve_area_centroid(Q, space.basis)
        centroid = np.asarray(centroid, dtype=float)
    else:
        centroid = poly.mean(axis=0)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    return poly, centroid, (float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1]))


def build_space(template: Any, kind: str) -> ShapeSpace:
    """The constructive shape-space ``kind`` (translation, similarity, affine) on a template."""
    from trackcli.shapes import shape_space as ss

    builders = {"translation": ss.translation, "similarity": ss.similarity, "affine": ss.affine}
    if kind not in builders:
        raise ConfigError(f"shape_space: expected one of {', '.join(builders)}, got {kind!r}")
    return builders[kind](template.basis(), template.Q)
