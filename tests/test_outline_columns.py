"""The outline columns of a track CSV: the points come from the run layer, the format from io."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from trackcli.errors import InputError
from trackcli.io.tracks import TrackWriter, outline_header, read_outlines
from trackcli.run.outline_columns import OutlineColumns
from trackcli.shapes.shape_space import similarity
from trackcli.shapes.spline import SplineBasis, dense_polygon


def _space(closed: bool = True):
    t = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    Q = np.concatenate([100 + 30 * np.cos(t), 80 + 20 * np.sin(t)])
    return similarity(SplineBasis(8, 2, closed), Q)


class _Result:
    """The fields of a frame result the track writer reads."""

    def __init__(self, X, outline=None):
        self.index, self.time = 0, 0.0
        self.X, self.X_std = np.asarray(X, dtype=float), np.zeros(len(X))
        self.centroid, self.bbox = (100.0, 80.0), (70.0, 60.0, 60.0, 40.0)
        self.n_found, self.n_normals, self.gate_rms, self.ess, self.loglik, self.lost = 1, 1, 1.0, None, None, False
        self.extra = {}
        self.outline = outline


def test_the_cells_are_the_curve_of_the_estimate_or_the_refined_outline_resampled():
    space = _space()
    columns = OutlineColumns(space, 16)
    X = np.array([5.0, -3.0, 0.1, 0.05])
    assert columns.header() == outline_header(16)
    cells = columns.cells(X)
    assert cells[0] == "1" and len(cells) == 1 + 32
    curve = dense_polygon(space.to_control(X), space.basis, 16)
    np.testing.assert_allclose(np.array(cells[1:], dtype=float).reshape(-1, 2), curve, atol=5e-4)
    # a refined outline (any number of points, either direction) gives 16 points along it,
    # equally spaced, clockwise on the screen from its top
    diamond = np.array([[20.0, 0.0], [0.0, 20.0], [20.0, 40.0], [40.0, 20.0]])  # counter-clockwise on screen
    for refined in (diamond, diamond[::-1], np.roll(diamond, 1, axis=0)):
        cells = columns.cells(X, refined=refined)
        pts = np.array(cells[1:], dtype=float).reshape(-1, 2)
        assert cells[0] == "1" and pts.shape == (16, 2)
        np.testing.assert_allclose(pts[0], [20.0, 0.0], atol=5e-4)
        np.testing.assert_allclose(pts[1], [25.0, 5.0], atol=5e-4)  # to the right: clockwise on screen
        steps = np.hypot(*np.diff(np.vstack([pts, pts[:1]]), axis=0).T)
        np.testing.assert_allclose(steps, np.hypot(5.0, 5.0), atol=1e-3)
    # an open curve has no inside to refine: its own points, flagged open
    open_columns = OutlineColumns(_space(closed=False), 16)
    assert open_columns.cells(X, refined=diamond)[0] == "0"


def test_the_track_writer_ends_each_row_with_the_columns_it_is_given(tmp_path):
    space = _space()
    path = tmp_path / "t.csv"
    with TrackWriter(path, space.names, OutlineColumns(space, 12)) as writer:
        writer.write(_Result(np.zeros(4)))
    with open(path, newline="") as f:
        head, row = list(csv.reader(f))
    assert head[-25:] == outline_header(12) and len(row) == len(head)
    frames, points, closed = read_outlines(path)
    assert frames.tolist() == [0] and closed.tolist() == [True]
    np.testing.assert_allclose(points[0], dense_polygon(space.Q0, space.basis, 12), atol=5e-4)


@pytest.mark.parametrize("bad", [1, 0, 2.5, True])
def test_fewer_than_two_points_are_refused(bad):
    with pytest.raises(InputError, match="number of points >= 2"):
        OutlineColumns(_space(), bad)
