"""Choosing among ``draw --box``'s masks by the frames that follow the one drawn on.

GrabCut learns the object's colours from the whole box, so a region beside the object whose
colours are the object's (a panel striped in the shirt's blue, the background between a
leaf's edge and a disc of its colour) can be taken into the mask, and on one frame nothing
tells it from a part of the object.  The frames that follow can: the object moves and the
region stays where it was, or moves otherwise.  :func:`confirm` tracks the template of
each distinct candidate mask of :func:`trackcli.segment.grabcut.segment_candidates` over the
drawn frame and the :data:`CONFIRM_FRAMES` - 1 after it with CONDENSATION and the default
settings, and keeps the frame's own choice unless another candidate is clearly better held:

- its mean confidence over those frames is at least :data:`CONFIDENCE_GAIN` higher,
- it keeps at least :data:`HELD_GAIN` more of its first frame's score (the outline's
  log-likelihood over the frames after the first, as a share of the first; a template whose
  first frame scores nothing positive has nothing to keep and replaces no other), and
- it scores at least :data:`SCORE_GAIN` more (as a share) over those frames.

The first two are each template's own measure (against its first frame), so a weak template
that has little to lose could pass them while explaining the frames less well than the
frame's choice: the third compares the two on the frames themselves.  When several
candidates pass, the one of highest mean confidence is kept.

Measured on the first frames of the 48 clips of ``bench/other_clips.py`` (seeds 0-3), the 44
sample clips of seeds 1-44, the DAVIS clips and the benchmark clips of the footage folder
(see ``bench/RESULTS.md``, *draw --box asks the next frames*).
"""

from __future__ import annotations

import contextlib
import logging
import math
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Sequence

import numpy as np

log = logging.getLogger(__name__)

#: frames tracked per candidate, the drawn one included
CONFIRM_FRAMES = 15
#: with fewer frames after the drawn one than this, the frame's own choice stands
CONFIRM_LEAST = 8
#: an alternative is taken when its mean confidence is this much higher ...
CONFIDENCE_GAIN = 0.03
#: ... it keeps this much more of its first frame's score ...
HELD_GAIN = 0.1
#: ... and scores this share more over the frames after the first
SCORE_GAIN = 0.1
#: masks whose IoU with one tried already is above this are not tried again
SAME_MASK = 0.98


@dataclass(frozen=True)
class Trial:
    """One candidate tracked over the frames after the drawn one.

    ``confidence`` and ``score`` are means over the frames after the first of the tracker's
    confidence and the estimate's log-likelihood; ``held`` is ``score`` as a share of the
    first frame's log-likelihood (NaN when that is not positive: nothing to keep).
    """

    index: int
    confidence: float
    score: float
    held: float

    def beats(self, other: Trial) -> bool:
        """Whether this candidate is clearly better held than ``other`` (the module's rule)."""
        if not math.isfinite(self.held):  # nothing kept: no claim to be better held
            return False
        other_held = other.held if math.isfinite(other.held) else -math.inf
        return (self.confidence >= other.confidence + CONFIDENCE_GAIN
                and self.held >= other_held + HELD_GAIN
                and self.score >= other.score + SCORE_GAIN * abs(other.score))


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """The trial runs' own messages (a template that scores poorly, bars found) are not the
    user's: they are held back while the candidates are tried."""
    logger = logging.getLogger("trackcli.trackers")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def trial(template: Any, frames: Sequence[Any], fps: float, index: int = 0) -> Trial:
    """Track ``template`` over ``frames`` (the drawn frame first) with CONDENSATION and the
    default settings (their seed too, so the choice is the same on every run), the template's
    shape-space and hand-set dynamics, as ``trackcli track --template`` does; ``index`` names
    the candidate in the result.  ``frames`` holds at least two frames."""
    from trackcli.dynamics.handset import handset_dynamics
    from trackcli.settings import Settings
    from trackcli.run.clips import template_space
    from trackcli.trackers.condensation_tracker import track_condensation

    if len(frames) < 2:
        raise ValueError("a trial needs the drawn frame and at least one after it")
    settings = Settings()
    space = template_space(template, "the candidate template", settings.shape_space)
    dynamics = handset_dynamics(space, settings.dynamics, 1.0 / fps)
    with _quiet():
        results = list(track_condensation(frames, space, dynamics, settings.measurement, settings.condensation,
                                          np.random.default_rng(settings.seed)))
    conf = np.array([r.confidence for r in results], dtype=float)
    ll = np.array([r.loglik for r in results], dtype=float)
    score = float(np.mean(ll[1:]))
    held = score / float(ll[0]) if ll[0] > 0 else math.nan
    return Trial(index, float(np.mean(conf[1:])), score, held)


def to_try(masks: Sequence[np.ndarray], chosen: int) -> list[int]:
    """The masks :func:`confirm` tracks: ``chosen`` first, then every other one whose IoU with
    each listed before it is at most :data:`SAME_MASK`."""
    from trackcli.segment.masks import mask_iou

    kept: list[int] = []
    for i in [chosen] + [j for j in range(len(masks)) if j != chosen]:
        if all(mask_iou(masks[i], masks[j]) <= SAME_MASK for j in kept):
            kept.append(i)
    return kept


def confirm(masks: Sequence[np.ndarray], order: Sequence[int], fit: Callable[[np.ndarray], Any],
            frames: Sequence[Any], fps: float, *,
            progress: Callable[[int], None] | None = None) -> tuple[int, list[Trial]]:
    """The mask to keep of ``masks``: ``order[0]`` (the frame's own choice) unless another of
    ``order`` (:func:`to_try`) is clearly better held over ``frames`` (the drawn frame first;
    see the module).

    ``fit(mask)`` makes a candidate's template as ``draw`` would.  A mask whose template
    cannot be fitted or tracked (``DataError``, ``TemplateError``: a degenerate outline) is
    not tried.  Returns ``(index, trials)``, the trials in the order made (the chosen mask's
    first, when it could be tried).  ``progress(1)`` is called after each mask of ``order``.
    """
    from trackcli.errors import DataError, TemplateError

    chosen = order[0]
    trials: list[Trial] = []
    for i in order:
        try:
            trials.append(trial(fit(masks[i]), frames, fps, i))
        except (DataError, TemplateError):
            pass
        if progress is not None:
            progress(1)
    if not trials or trials[0].index != chosen:
        return chosen, trials
    better = [t for t in trials[1:] if t.beats(trials[0])]
    if not better:
        return chosen, trials
    return max(better, key=lambda t: t.confidence).index, trials
