"""The track format: one CSV row of estimates per frame.

Columns, in order:

``frame, time``
    original frame index (0-based) and time in seconds;
``X_<name>`` …
    the estimated shape vector, one column per shape-space component (``X_tx, X_ty, …``);
``std_<name>`` …
    its posterior standard deviation;
``cx, cy``
    area centroid of the estimated contour, px;
``bbox_x, bbox_y, bbox_w, bbox_h``
    the object's box, px: the tight box of the estimated contour; when the tracker started
    at a template drawn from a box (``draw --box``) and ``output.box`` is ``drawn`` (the
    default), that box carried along by the estimate (:class:`BoxCarry`, :class:`DrawnBox`);
    either clipped to the frame (:func:`clip_box`);
``n_found, n_normals``
    measurement normals that found a feature, and how many there are;
``gate_rms``
    RMS search half-width along the normals, px;
``ess``
    effective sample size (CONDENSATION; empty for Kalman);
``loglik``
    log-likelihood of the estimated contour under CONDENSATION's observation model (empty for Kalman);
``lost``
    1 when the tracker judges it has lost lock (its confidence is below
    ``measurement.lost_below``) and the refined outline does not vouch for the frame (its
    inside standing out in the object's colours, ``outline.lost_contrast``), else 0;
``confidence``
    the tracker's confidence in [0, 1] that the estimate is on the object, from the evidence
    per normal of the estimated curve against background (:mod:`trackcli.observe.discriminant`) and the
    spread of its position;
``log_d``
    log of the contour discriminant of the estimated curve (> 0: more object-like than
    clutter).

After these (and after any other per-frame column a tracker adds), when the run writes
outlines (``output.outline_points`` = P > 0, the default 64):

``outline_closed``
    1 for a closed curve (the outline is a polygon), 0 for an open one (a polyline);
``outline_x0, outline_y0, …, outline_x{P-1}, outline_y{P-1}``
    P points of the estimated curve, px, equally spaced in the spline parameter (for a
    closed curve ``s_i = i L / P``, for an open one from ``s = 0`` to ``s = L`` inclusive).

With them any program can draw the estimate or score its outline without trackcli: a row's
``outline_x*, outline_y*`` cells, in order, are the vertices.  Readers should find columns by
name, not by position.

Files are written atomically: a run that stops early leaves no half-written CSV.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, Sequence

import numpy as np

from trackcli.errors import InputError
from trackcli.io.outputs import atomic_path

FIXED_AFTER = ["cx", "cy", "bbox_x", "bbox_y", "bbox_w", "bbox_h", "n_found", "n_normals", "gate_rms", "ess", "loglik", "lost", "confidence", "log_d"]


def header(names: Sequence[str]) -> list[str]:
    """Column names for a shape-space with component ``names``."""
    return ["frame", "time", *[f"X_{n}" for n in names], *[f"std_{n}" for n in names], *FIXED_AFTER]


def _fmt(v: float, digits: int = 6) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return f"{v:.{digits}g}" if abs(v) < 1e-3 and v != 0 else f"{v:.{digits}f}".rstrip("0").rstrip(".")


_FORMATS: dict[tuple[int, int], str] = {}


def _fmt_all(values: np.ndarray, digits: int) -> list[str]:
    """``[_fmt(v, digits) for v in values]`` for a float array, with one ``%`` formatting of
    the whole array (an outline row has 128 cells: 60 µs per frame one call at a time, 30 µs
    so)."""
    v = np.asarray(values, dtype=float).reshape(-1)
    fmt = _FORMATS.get((v.size, digits))
    if fmt is None:
        fmt = _FORMATS[(v.size, digits)] = ",".join([f"%.{digits}f"] * v.size)
    cells = [c.rstrip("0").rstrip(".") for c in (fmt % tuple(v.tolist())).split(",")] if v.size else []
    odd = ~np.isfinite(v) | ((np.abs(v) < 1e-3) & (v != 0))
    for i in np.flatnonzero(odd):  # NaN and tiny values: the general rule
        cells[i] = _fmt(float(v[i]), digits)
    return cells


@dataclass(frozen=True)
class BoxCarry:
    """The box a template was drawn from, carried along by the estimate.

    ``draw --box`` segments the object inside the user's box, and the outline it fits is
    rarely that box: GrabCut leaves out thin parts (a leaf's stem), the spline rounds off
    corners, a box drawn loosely leaves a margin.  Scored as a box, the contour's own box
    is then off the user's by the same amount on every frame.  The carried box keeps the
    drawn box's place relative to an anchor, the contour's box where the object was drawn,
    as fractions of that box's width and height: on frame ``k`` it is
    ``(x_k + fx w_k, y_k + fy h_k, fw w_k, fh h_k)`` where ``(x_k, y_k, w_k, h_k)`` is the
    estimated contour's box.  At the anchor it is the drawn box; it moves and scales with
    the contour.
    """

    fx: float
    fy: float
    fw: float
    fh: float

    @classmethod
    def between(cls, drawn: Sequence[float], anchor: Sequence[float]) -> BoxCarry | None:
        """The carry of the ``drawn`` box ``(x, y, w, h)`` about the contour's box ``anchor``;
        None when that box has no width or height."""
        x, y, w, h = (float(v) for v in anchor)
        if not (w > 0 and h > 0 and all(math.isfinite(v) for v in (x, y, w, h))):
            return None
        bx, by, bw, bh = (float(v) for v in drawn)
        return cls((bx - x) / w, (by - y) / h, bw / w, bh / h)

    def __call__(self, bbox: Sequence[float]) -> tuple[float, float, float, float]:
        x, y, w, h = (float(v) for v in bbox)
        return (x + self.fx * w, y + self.fy * h, self.fw * w, self.fh * h)


@dataclass(frozen=True)
class DrawnBox:
    """The box a template was drawn from (``box``, on frame ``frame``) and what a track's box
    columns carry it about (:class:`BoxCarry`).

    The anchor is the box of the curve the tracker starts from (``start``): the drawn
    outline itself when the template's own shape is tracked.  A model placed by a template
    (``--model M --template T``) tracks another curve, set on the object by position and
    size only, a few pixels off it; there (``first``) the anchor is the first estimate when
    it is of the frame the box was drawn on, the tracker's fit of the model to that frame.
    """

    box: tuple[float, float, float, float]
    frame: int
    start: tuple[float, float, float, float]
    first: bool = False

    def carry(self, result) -> BoxCarry | None:
        """The carry for a track whose first result is ``result``."""
        anchor = result.bbox if self.first and int(result.index) == self.frame else self.start
        return BoxCarry.between(self.box, anchor)


def clip_box(box: Sequence[float], frame_size: tuple[int, int]) -> tuple[float, float, float, float]:
    """The part of the box ``(x, y, w, h)`` inside a frame of ``frame_size = (width, height)``.

    An object that has partly left the frame is annotated by its part in view (benchmark
    truth boxes lie inside the image), and the estimate's box is reported the same way: the
    box of an outline half beyond the frame's lower edge would otherwise be centred on the
    edge, a quarter of the object's height below the centre of what is visible.  A box
    wholly outside the frame (or not finite) is returned as it is: there is no part in view
    to give.
    """
    x, y, w, h = (float(v) for v in box)
    x0, y0 = max(x, 0.0), max(y, 0.0)
    x1, y1 = min(x + w, float(frame_size[0])), min(y + h, float(frame_size[1]))
    if not (x1 > x0 and y1 > y0):  # also False for NaN
        return (x, y, w, h)
    return (x0, y0, x1 - x0, y1 - y0)


def row(result, carry: BoxCarry | None = None, frame_size: tuple[int, int] | None = None) -> list[str]:
    """CSV cells of one :class:`~trackcli.trackers.base.FrameResult` (without its extras and
    outline); with ``carry``, the box columns hold the carried box; with ``frame_size``
    ``(width, height)``, the box is clipped to the frame (:func:`clip_box`)."""
    cells = [str(result.index), f"{result.time:.6f}"]
    cells += _fmt_all(result.X, 8)
    cells += _fmt_all(result.X_std, 6)
    cells += [_fmt(float(result.centroid[0]), 3), _fmt(float(result.centroid[1]), 3)]
    box = result.bbox if carry is None else carry(result.bbox)
    if frame_size is not None:
        box = clip_box(box, frame_size)
    cells += [_fmt(float(v), 3) for v in box]
    cells += [str(result.n_found), str(result.n_normals), _fmt(result.gate_rms, 4), _fmt(result.ess, 6),
              _fmt(result.loglik, 6), "1" if result.lost else "0",
              _fmt(float(getattr(result, "confidence", math.nan)), 4), _fmt(float(getattr(result, "log_d", math.nan)), 5)]
    return cells


OUTLINE_CLOSED = "outline_closed"


def outline_header(n_points: int) -> list[str]:
    """Names of the outline columns for ``n_points`` points (empty for 0)."""
    if n_points <= 0:
        return []
    return [OUTLINE_CLOSED, *[f"outline_{a}{i}" for i in range(n_points) for a in "xy"]]


def outline_cells(points: np.ndarray, closed: bool) -> list[str]:
    """A row's outline cells: ``outline_closed`` (1 or 0) and the points ``(P, 2)``, px."""
    return ["1" if closed else "0", *_fmt_all(points, 3)]


class OutlineSource(Protocol):
    """What gives a track its outline columns (:class:`trackcli.run.outline_columns.OutlineColumns`):
    their names, and a row's cells for the estimate ``X`` or the ``refined`` outline."""

    def header(self) -> list[str]: ...

    def cells(self, X: np.ndarray, refined: np.ndarray | None = None) -> list[str]: ...


class TrackWriter:
    """Write rows as results arrive; the file appears under its final name only on ``close``.

    With ``outline`` (an :class:`OutlineSource`), every row ends with the outline columns;
    with ``drawn`` (a :class:`DrawnBox`), the box columns hold the drawn box carried by the
    estimate; with ``frame_size`` ``(width, height)``, the box columns are clipped to the
    frame (:func:`clip_box`).
    """

    def __init__(self, path: str | Path, names: Sequence[str], outline: OutlineSource | None = None,
                 extra: Sequence[str] | None = None, drawn: DrawnBox | None = None,
                 frame_size: tuple[int, int] | None = None):
        self.path = Path(path)
        self._drawn = drawn
        self._frame_size = frame_size
        self._carry: BoxCarry | None = None
        self._outline = outline
        self._extra = list(extra or [])
        self._ctx = atomic_path(self.path)
        tmp = self._ctx.__enter__()
        self._fh = open(tmp, "w", newline="", encoding="utf-8")
        self._csv = csv.writer(self._fh)
        self._csv.writerow(header(names) + self._extra + (outline.header() if outline else []))

    def write(self, result) -> None:
        if self._drawn is not None:  # anchored on the first result
            self._carry, self._drawn = self._drawn.carry(result), None
        cells = row(result, self._carry, self._frame_size)
        if self._extra:
            cells += [_fmt(float(result.extra.get(e, math.nan)), 6) for e in self._extra]
        if self._outline is not None:
            cells += self._outline.cells(result.X, getattr(result, "outline", None))
        self._csv.writerow(cells)

    def __enter__(self) -> "TrackWriter":
        return self

    def __exit__(self, et, ev, tb) -> None:
        self._fh.close()
        self._ctx.__exit__(et, ev, tb)


def _read_table(path: str | Path) -> tuple[Path, list[list[str]]]:
    """The rows of a track CSV, header first; one-line errors for a missing, unreadable or foreign file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such track file")
    try:
        with open(p, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a text file (a track is the CSV written by 'trackcli track')") from None
    except OSError as exc:
        raise InputError(f"{p}: cannot read ({exc.strerror or exc})") from None
    if not rows or "frame" not in rows[0]:
        raise InputError(f"{p}: not a trackcli track CSV (no 'frame' column in the header)")
    return p, rows


def read_track(path: str | Path, names: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Read ``(frames (T,), X (T, Nx), names)`` from a track CSV.

    If ``names`` is given the file must have exactly those shape components.
    """
    p, rows = _read_table(path)
    head = rows[0]
    x_cols = [i for i, c in enumerate(head) if c.startswith("X_")]
    found = [head[i][2:] for i in x_cols]
    if not x_cols:
        raise InputError(f"{p}: no shape-vector columns (X_...) in the header")
    if names is not None and list(names) != found:
        raise InputError(f"{p}: shape components {found} do not match the shape-space {list(names)}")
    fi = head.index("frame")
    frames, X = [], []
    for k, r in enumerate(rows[1:], 2):
        if not r:
            continue
        try:
            frames.append(int(r[fi]))
            X.append([float(r[i]) for i in x_cols])
        except (ValueError, IndexError):
            raise InputError(f"{p} line {k}: malformed row") from None
    if not frames:
        raise InputError(f"{p}: the track has no rows")
    return np.asarray(frames), np.asarray(X, dtype=float), found


def read_columns(path: str | Path, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """The named columns of a track CSV as float arrays (empty cells NaN), by name."""
    p, rows = _read_table(path)
    head = rows[0]
    missing = [c for c in columns if c not in head]
    if missing:
        raise InputError(f"{p}: no column(s) {', '.join(missing)}")
    idx = [head.index(c) for c in columns]
    values = []
    for k, r in enumerate(rows[1:], 2):
        if not r:
            continue
        try:
            values.append([float(r[i]) if r[i] != "" else math.nan for i in idx])
        except (ValueError, IndexError):
            raise InputError(f"{p} line {k}: malformed row") from None
    table = np.asarray(values, dtype=float).reshape(-1, len(idx))
    return {c: table[:, j] for j, c in enumerate(columns)}


def read_outlines(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read the outline columns of a track CSV (see the module docstring), by name.

    Returns
    -------
    frames : ndarray of shape (T,), int
    outlines : ndarray of shape (T, P, 2)
        Outline points; NaN in rows whose outline cells are empty.
    closed : ndarray of shape (T,), bool

    Raises
    ------
    InputError
        The file is missing or unreadable, has no outline columns (written with
        ``output.outline_points: 0`` or by an older trackcli), or a cell is not a number.
    """
    p, rows = _read_table(path)
    head = rows[0]
    col = {name: i for i, name in enumerate(head)}
    n = 0
    while f"outline_x{n}" in col and f"outline_y{n}" in col:
        n += 1
    if n < 2:
        raise InputError(f"{p}: no outline columns (outline_x0, outline_y0, ...); re-run `trackcli track` "
                         "with output.outline_points > 0")
    idx = [col[f"outline_{a}{i}"] for i in range(n) for a in "xy"]
    ci = col.get(OUTLINE_CLOSED)
    frames, outlines, closed = [], [], []
    for k, r in enumerate(rows[1:], 2):
        if not r:
            continue
        try:
            frames.append(int(r[col["frame"]]))
            outlines.append([float(r[i]) if r[i].strip() else math.nan for i in idx])
            closed.append(ci is None or r[ci].strip() != "0")
        except (ValueError, IndexError):
            raise InputError(f"{p} line {k}: malformed outline cells") from None
    if not frames:
        raise InputError(f"{p}: the track has no rows")
    return np.asarray(frames), np.asarray(outlines, dtype=float).reshape(len(frames), n, 2), np.asarray(closed)


def read_track_uncertainty(path: str | Path, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Read ``(std (T, Nx), lost (T,) bool)`` from a track CSV with shape components ``names``.

    Empty or missing ``std_`` cells read as NaN; a missing ``lost`` column as never lost.
    """
    p = Path(path)
    read_track(p, names)  # the same checks of file, header and rows
    _, rows = _read_table(p)
    rows = [r for r in rows if r]
    head = rows[0]
    missing = [f"std_{n}" for n in names if f"std_{n}" not in head]
    if missing:
        raise InputError(f"{p}: no uncertainty columns {', '.join(missing)} in the header")
    cols = [head.index(f"std_{n}") for n in names]
    li = head.index("lost") if "lost" in head else None
    std = np.full((len(rows) - 1, len(cols)), np.nan)
    lost = np.zeros(len(rows) - 1, dtype=bool)
    for k, r in enumerate(rows[1:]):
        try:
            std[k] = [float(r[i]) if r[i].strip() else np.nan for i in cols]
            lost[k] = li is not None and r[li].strip() not in ("", "0")
        except (ValueError, IndexError):
            raise InputError(f"{p} line {k + 2}: malformed row") from None
    return std, lost
