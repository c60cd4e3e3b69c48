"""Ground truth as ``trackcli eval`` reads it: every format of :mod:`trackcli.io.truth`, and
for a sample clip's truth CSV its true outlines, placed by :mod:`trackcli.sample_data`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from trackcli.io import truth as formats
from trackcli.io.truth import GroundTruth, PathLike


def place_sample_outlines(json_path: Path, rows: Sequence[Mapping[str, str]]) -> np.ndarray:
    """:func:`trackcli.sample_data.place_outlines`, imported when a truth CSV has an outline
    file beside it (the sample data's geometry loads scipy, a second at start-up)."""
    from trackcli.sample_data import place_outlines

    return place_outlines(json_path, rows)


def load_truth(path: PathLike, *, object_id: int = 0) -> GroundTruth:
    """:func:`trackcli.io.truth.load_truth`, with the true outlines of a sample clip's truth
    CSV (:func:`place_sample_outlines`)."""
    return formats.load_truth(path, object_id=object_id, outlines=place_sample_outlines)
