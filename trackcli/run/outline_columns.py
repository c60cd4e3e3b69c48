"""The outline columns of a track CSV: P points of each frame's outline.

The format is :mod:`trackcli.io.tracks`' (``outline_closed, outline_x0, outline_y0, …``); the
points come from here: those of the estimated curve, equally spaced in the spline parameter,
or, when the outline was refined in the image (:class:`trackcli.observe.region.OutlineRefiner`),
those of the refined polygon, equally spaced along it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackcli.errors import InputError
from trackcli.io.tracks import outline_cells, outline_header
from trackcli.observe.region import simplify_closed
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.shapes.spline import dense_polygon


@dataclass(frozen=True)
class OutlineColumns:
    """Evaluates the ``n_points`` outline points of shape vectors of ``space`` for the CSV.

    Attributes
    ----------
    space : ShapeSpace
        The shape-space of the track (``Q = W X + Q0``).
    n_points : int
        P >= 2.
    """

    space: ShapeSpace
    n_points: int

    def __post_init__(self) -> None:
        if isinstance(self.n_points, bool) or not isinstance(self.n_points, int) or self.n_points < 2:
            raise InputError(f"outline needs an integer number of points >= 2, got {self.n_points!r}")

    def points(self, X: np.ndarray) -> np.ndarray:
        """Outline points ``(P, 2)`` of the shape vector ``X`` ``(Nx,)``."""
        return dense_polygon(self.space.to_control(np.asarray(X, dtype=float)), self.space.basis, self.n_points)

    def header(self) -> list[str]:
        return outline_header(self.n_points)

    def cells(self, X: np.ndarray, refined: np.ndarray | None = None) -> list[str]:
        """The row's outline cells: of ``X``'s curve, or of the ``refined`` outline when given
        (``n_points`` of its vertices that keep its shape, :func:`trackcli.observe.region.simplify_closed`)."""
        if refined is not None and self.space.basis.closed:
            return outline_cells(simplify_closed(refined, self.n_points), True)
        return outline_cells(self.points(X), self.space.basis.closed)
