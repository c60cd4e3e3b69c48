"""``trackcli eval``: several tracks scored against one ground truth, and their plots.

:func:`score_tracks` loads the truth once and scores each track in turn
(:mod:`trackcli.run.evaluate`), yielding its summary, the notes on the frames the track and
the truth do not share, and, for the plots, its curves; :func:`write_score_plots` writes the
precision and success plots of them all (:mod:`trackcli.run.plots`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence


@dataclass(frozen=True)
class Scored:
    """One track scored: its path, its label in tables and plots, the summary
    (:class:`trackcli.run.evaluate.EvalResult`), the coverage notes and its plot curves."""

    path: str
    label: str | None
    result: Any
    notes: list[str]
    curves: Any = None

    def json(self, truth: str) -> dict[str, Any]:
        """The track's object of ``eval --json``."""
        return {"kind": "eval", "track": str(self.path), "truth": str(truth), **self.result.to_dict(),
                "warnings": self.notes}


def score_tracks(tracks: Sequence[str], truth: str, *, threshold: float = 20.0, lost_threshold: float | None = None,
                 object_id: int = 0, plot: str | None = None) -> Iterator[Scored]:
    """Score each of ``tracks`` (track CSVs) against ``truth`` (any format of
    :func:`trackcli.run.evaluate.load_truth`; ``object_id`` picks an object of a truth CSV).

    Tracks get labels (:func:`trackcli.run.plots.track_labels`) when there are several or a
    ``plot`` is to be written (which must not replace an input); with ``plot`` each yields
    its curves too.  ``threshold`` (px) is the precision's; ``lost_threshold`` (px) also
    counts a frame lost when its centre error exceeds it.
    """
    from trackcli.run.evaluate import coverage_notes, load_track, load_truth, mismatch_notes, score_frames, summarise

    if plot:
        from trackcli.io.outputs import refuse_overwriting_inputs

        refuse_overwriting_inputs({"--plot": plot}, {"TRUTH": truth, **{f"PRED {k + 1}": t for k, t in enumerate(tracks)}})
    gt = load_truth(truth, object_id=object_id)
    labels: list[str | None] = [None] * len(tracks)
    if plot or len(tracks) > 1:
        from trackcli.run.plots import track_labels

        labels = list(track_labels(tracks))
    for label, path in zip(labels, tracks):
        pred = load_track(path)
        scores = score_frames(pred, gt, lost_threshold=lost_threshold)
        result = summarise(scores, threshold=threshold)
        notes = coverage_notes(pred, gt, scores) + mismatch_notes(pred, gt, scores, truth)
        curves = None
        if plot:
            from trackcli.run.plots import curves as make_curves

            curves = make_curves(label, scores, threshold)
        yield Scored(path, label, result, notes, curves)


def write_score_plots(path: str, scored: Sequence[Scored], threshold: float = 20.0) -> Path:
    """The precision plot (0-50 px) and success plot (IoU 0-1) of ``scored`` (made with ``plot``) in one PNG."""
    from trackcli.run.plots import write_plots

    return write_plots(path, [s.curves for s in scored], threshold=threshold)
