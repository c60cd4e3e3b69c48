"""Checks that inputs belong together, and that a run's sample set held: one-line notes.

- :func:`check_track_on_clip`: a track drawn on (or exported from) a clip must have been made on
  a clip of that length and size.  A track CSV does not record the size of its frames, so the
  size is judged from where its estimates lie: mostly outside the frames, or all of them in a
  corner a quarter of the frame or less, which is where a track made on a smaller clip lies.
- :func:`check_sizes`: two sets of masks (or a track's frames and masks) of different sizes.
- :func:`sample_collapse`: CONDENSATION's effective sample size below 1 % of N on most frames
  (e.g. ``-c tight`` on footage it was not made for: the weights put everything on one or two
  samples, and the estimate is as good as a single guess).

Notes are plain strings for the caller to print as warnings (``Warning: ...``); a mismatch that
makes the result meaningless raises :class:`~trackcli.errors.DataError` instead.
"""

from __future__ import annotations

import os

import numpy as np

from trackcli.errors import DataError

#: ESS below this fraction of N counts as a collapsed sample set ...
COLLAPSE_FRACTION = 0.01
#: ... and a run is warned about when that is so on more than this fraction of its frames.
COLLAPSE_FRAMES = 0.5
#: A track whose estimates all lie within this fraction of the frame's width and height (from
#: the top-left corner) was probably made on a smaller clip.
CORNER_FRACTION = 0.5


def check_track_on_clip(frames: np.ndarray, points: np.ndarray, *, width: int, height: int, n_frames: int,
                        track: str, clip: str) -> list[str]:
    """Refuse a track with frames the clip does not have; note estimates that do not fit its frames.

    Parameters
    ----------
    frames : ndarray of shape (T,), int
        The track's frame indices.
    points : ndarray of shape (T, P, 2)
        Its outlines (or centroids, P = 1) in pixels; NaN where a row has none.
    width, height, n_frames : int
        The clip's frame size and length.
    track, clip : str
        Names for the messages.

    Raises
    ------
    DataError
        The track has frames beyond the clip's last.
    """
    f = np.asarray(frames, dtype=int)
    if f.size and f.max() >= n_frames:
        raise DataError(f"{track} has estimates up to frame {int(f.max())} but {clip} has {n_frames} frames "
                        f"(0-{n_frames - 1}): was the track made on another clip?")
    p = np.asarray(points, dtype=float).reshape(len(f), -1, 2) if f.size else np.zeros((0, 1, 2))
    rows = np.all(np.isfinite(p), axis=(1, 2))
    if not rows.any():
        return []
    p = p[rows]
    c = p.mean(axis=1)
    outside = (c[:, 0] < 0) | (c[:, 1] < 0) | (c[:, 0] > width) | (c[:, 1] > height)
    notes = []
    if outside.mean() > 0.5:
        notes.append(f"{track}: {int(outside.sum())} of {len(c)} estimates lie outside the {width}x{height} frames "
                     f"of {clip}: was the track made on another clip?")
    else:
        right, bottom = float(np.max(p[..., 0])), float(np.max(p[..., 1]))
        if len(p) >= 2 and right <= CORNER_FRACTION * width and bottom <= CORNER_FRACTION * height:
            notes.append(f"{track}: every estimate lies within the top-left {int(np.ceil(right))}x{int(np.ceil(bottom))} "
                         f"px of the {width}x{height} frames of {clip}: was the track made on a smaller clip?")
    return notes


def check_sizes(a: tuple[int, int], b: tuple[int, int], *, what_a: str, what_b: str) -> None:
    """Raise DataError when two frame sizes ``(width, height)`` differ (masks of two clips)."""
    if tuple(a) != tuple(b):
        raise DataError(f"{what_a} is {a[0]}x{a[1]} but {what_b} is {b[0]}x{b[1]}: "
                        "they were not made on the same clip")


def sample_collapse(ess: np.ndarray, particles: int, *, name: str = "the run") -> str | None:
    """A note when the effective sample size was below 1 % of ``particles`` on most frames, else None.

    Parameters
    ----------
    ess : ndarray of shape (T,)
        The ``ess`` column of a track (NaN for trackers without samples: no note).
    particles : int
        The sample-set size N (``condensation.particles``).
    """
    e = np.asarray(ess, dtype=float)
    e = e[np.isfinite(e)]
    if e.size == 0 or particles < 1:
        return None
    limit = COLLAPSE_FRACTION * particles
    low = e < limit
    if low.mean() <= COLLAPSE_FRAMES:
        return None
    return (f"{name}: the sample set collapsed: the effective sample size was below {limit:g} (1% of "
            f"N = {particles}) on {int(low.sum())} of {e.size} frames (median {np.median(e):.1f}), so each "
            "estimate rests on one or two samples; the observation model is too sharp for this footage "
            "(a config with wider measurements or softer weights, or more particles)")


def track_warnings(csv: str | os.PathLike[str], particles: int, *, name: str) -> list[str]:
    """The warnings about a finished run that its track CSV shows: a collapsed sample set."""
    from trackcli.errors import TrackcliError
    from trackcli.io.tracks import read_columns

    try:
        ess = read_columns(csv, ["ess"])["ess"]
    except TrackcliError:  # a track without an ESS column
        return []
    note = sample_collapse(ess, particles, name=name)
    return [note] if note else []


__all__ = ["COLLAPSE_FRACTION", "COLLAPSE_FRAMES", "check_sizes", "check_track_on_clip", "sample_collapse",
           "track_warnings"]
