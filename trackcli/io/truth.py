"""What ``trackcli eval`` compares: a track's boxes and centres, and ground truth in its formats.

The formats are described in :mod:`trackcli.run.evaluate`, which scores one against the other.
A sample clip's truth CSV has its true outlines beside it, in ``<clip>.outline.json``: a base
outline and, in each row, the pose that places it.  Placing them is the sample data's
business (:mod:`trackcli.sample_data`); :func:`load_truth` is given the function that does
it (:data:`PlaceOutlines`), as :func:`trackcli.run.truth.load_truth` does.
"""

from __future__ import annotations

import csv
import logging
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Literal, Mapping, Sequence

import numpy as np

from trackcli.errors import ConfigError, InputError

log = logging.getLogger(__name__)

TRUTH_FILE_NAMES: tuple[str, ...] = ("groundtruth_rect.txt", "groundtruth.txt")
"""Names looked for, in this order, when the ground truth is given as a folder."""

_BOX_COLUMNS = ("bbox_x", "bbox_y", "bbox_w", "bbox_h")
_TRACK_COLUMNS = ("frame", "cx", "cy", *_BOX_COLUMNS)
_TRUTH_COLUMNS = ("frame", "cx", "cy", *_BOX_COLUMNS)

PathLike = str | os.PathLike

PlaceOutlines = Callable[[Path, Sequence[Mapping[str, str]]], np.ndarray]
"""``place(outline_json, rows)``: the true outline of every row of a truth CSV, ``(N, P, 2)``,
from the outline file beside it; raises ``ValueError`` for a row it cannot place."""

# ---------------------------------------------------------------------------------------------
# Data


def _frozen_array(value, dtype, shape_tail: tuple[int, ...], name: str, owner: str) -> np.ndarray:
    arr = np.array(value, dtype=dtype, copy=True)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(N" + "".join(f", {d}" for d in shape_tail) + ")"
        raise ValueError(f"{owner}.{name}: expected an array of shape {want}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _check_frames(frame: np.ndarray, owner: str) -> None:
    if frame.size and frame.min() < 0:
        raise ValueError(f"{owner}.frame: frame indices must be >= 0, got {int(frame.min())}")


def _set_outline(obj, n: int, owner: str) -> None:
    if obj.outline is None:
        return
    arr = np.array(obj.outline, dtype=np.float64, copy=True)
    if arr.ndim != 3 or arr.shape[0] != n or arr.shape[2] != 2 or arr.shape[1] < 3:
        raise ValueError(f"{owner}.outline: expected an array of shape ({n}, P >= 3, 2), got {arr.shape}")
    arr.setflags(write=False)
    object.__setattr__(obj, "outline", arr)


@dataclass(frozen=True)
class Track:
    """Per-frame estimates to be scored.

    Attributes
    ----------
    frame : ndarray of int64, shape (N,)
        Original frame indices, strictly increasing.
    centre : ndarray of float64, shape (N, 2)
        Contour centroid ``(cx, cy)`` per frame; NaN where the tracker gave no estimate.
    box : ndarray of float64, shape (N, 4)
        Tight box ``(x, y, w, h)`` of the estimated contour; NaN where there is no estimate.
    lost : ndarray of bool, shape (N,)
        The tracker's own "lost" flag (all False when the file has no ``lost`` column).
    source : str
        Where the estimates came from (used in messages).
    outline : ndarray of float64, shape (N, P, 2), or None
        Closed outline per frame (NaN where there is none), when the file has one.
    """

    frame: np.ndarray
    centre: np.ndarray
    box: np.ndarray
    lost: np.ndarray
    source: str = "<predictions>"
    outline: np.ndarray | None = None

    def __post_init__(self) -> None:
        frame = _frozen_array(self.frame, np.int64, (), "frame", "Track")
        n = frame.shape[0]
        fields = {
            "frame": frame,
            "centre": _frozen_array(self.centre, np.float64, (2,), "centre", "Track"),
            "box": _frozen_array(self.box, np.float64, (4,), "box", "Track"),
            "lost": _frozen_array(self.lost, bool, (), "lost", "Track"),
        }
        for name, arr in fields.items():
            if arr.shape[0] != n:
                raise ValueError(f"Track.{name}: expected {n} rows (one per frame), got {arr.shape[0]}")
            object.__setattr__(self, name, arr)
        _check_frames(frame, "Track")
        if n > 1 and np.any(np.diff(frame) <= 0):
            raise ValueError("Track.frame: frame indices must be strictly increasing")
        _set_outline(self, n, "Track")


@dataclass(frozen=True)
class GroundTruth:
    """Ground truth for one object.

    Attributes
    ----------
    frame : ndarray of int64, shape (M,)
        Frame indices, strictly increasing.
    centre : ndarray of float64, shape (M, 2)
        True centre ``(x, y)`` per frame (see ``centre_kind``).
    box : ndarray of float64, shape (M, 4)
        True box ``(x, y, w, h)`` per frame.
    present : ndarray of bool, shape (M,)
        False for frames where the target is absent; those frames are not scored.
    centre_kind : {"centroid", "box"}
        ``"centroid"`` when ``centre`` is the object's centroid (trackcli truth), ``"box"``
        when it is the box centre (benchmark box files).  The prediction centre used for the
        centre error is of the same kind.
    source : str
        Where the truth came from (used in messages).
    outline : ndarray of float64, shape (M, K, 2), or None
        True closed outline per frame, when known (sample-data truth).
    """

    frame: np.ndarray
    centre: np.ndarray
    box: np.ndarray
    present: np.ndarray
    centre_kind: Literal["centroid", "box"] = "box"
    source: str = "<truth>"
    outline: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.centre_kind not in ("centroid", "box"):
            raise ValueError(f"GroundTruth.centre_kind: expected 'centroid' or 'box', got {self.centre_kind!r}")
        frame = _frozen_array(self.frame, np.int64, (), "frame", "GroundTruth")
        n = frame.shape[0]
        fields = {
            "frame": frame,
            "centre": _frozen_array(self.centre, np.float64, (2,), "centre", "GroundTruth"),
            "box": _frozen_array(self.box, np.float64, (4,), "box", "GroundTruth"),
            "present": _frozen_array(self.present, bool, (), "present", "GroundTruth"),
        }
        for name, arr in fields.items():
            if arr.shape[0] != n:
                raise ValueError(f"GroundTruth.{name}: expected {n} rows (one per frame), got {arr.shape[0]}")
            object.__setattr__(self, name, arr)
        _check_frames(frame, "GroundTruth")
        if n > 1 and np.any(np.diff(frame) <= 0):
            raise ValueError("GroundTruth.frame: frame indices must be strictly increasing")
        _set_outline(self, n, "GroundTruth")

    @classmethod
    def from_boxes(cls, boxes, *, first_frame: int = 0, source: str = "<truth>") -> GroundTruth:
        """Ground truth from one box per consecutive frame, as in a benchmark box file.

        Parameters
        ----------
        boxes : array_like, shape (M, 4)
            ``(x, y, w, h)`` per frame; a row with a NaN or with zero width or height marks a
            frame where the target is absent.
        first_frame : int
            Frame index of the first row.
        """
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        present = np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
        frame = first_frame + np.arange(boxes.shape[0], dtype=np.int64)
        return cls(frame, box_centres(boxes), boxes, present, centre_kind="box", source=source)


def box_centres(boxes) -> np.ndarray:
    """Centres ``(x + w/2, y + h/2)`` of boxes.

    Parameters
    ----------
    boxes : array_like, shape (..., 4)
        ``(x, y, w, h)``.

    Returns
    -------
    ndarray, shape (..., 2)
    """
    b = np.asarray(boxes, dtype=np.float64)
    return b[..., 0:2] + 0.5 * b[..., 2:4]


# ---------------------------------------------------------------------------------------------
# Reading files


def _read_text(path: Path, what: str) -> str:
    if path.is_dir():
        raise InputError(f"{path}: expected a {what} file, got a folder")
    try:
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError(f"{path}: {what} file not found") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file ({what} files are UTF-8 text)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what} file ({exc.strerror or exc})") from None


def _number(token: str, where: str, column: str) -> float:
    token = token.strip()
    if token == "":
        return math.nan
    try:
        value = float(token)
    except ValueError:
        raise InputError(f"{where}: {column} must be a number, got {token!r}") from None
    if math.isinf(value):
        raise InputError(f"{where}: {column} must be finite or NaN, got {token!r}")
    return value


def _frame_index(token: str, where: str) -> int:
    token = token.strip()
    try:
        value = float(token)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value != int(value) or value < 0:
        raise InputError(f"{where}: frame must be an integer >= 0, got {token!r}")
    return int(value)


def _flag(token: str, where: str, column: str) -> bool:
    t = token.strip().lower()
    if t in ("1", "1.0", "true", "yes"):
        return True
    if t in ("0", "0.0", "false", "no", ""):
        return False
    raise InputError(f"{where}: {column} must be 0 or 1, got {token!r}")


#: a first line ``key: value`` (or ``key:``): a YAML file given where a table was expected
_YAML_LINE = re.compile(r"\s*[A-Za-z_][\w.-]*\s*:(\s|$)")


def _refuse_yaml(path: Path, first_line: str, what: str) -> None:
    """A one-line error when the file's first line reads like YAML (a template, model or
    configuration given in the place of a table)."""
    if _YAML_LINE.match(first_line):
        raise InputError(f"{path}: not a {what} (its first line, {first_line.strip()!r}, reads like YAML: a "
                         "template, model or configuration?)")


def _csv_table(path: Path, text: str, required: tuple[str, ...], what: str):
    """Header and rows of a CSV file, checking that the required columns are present.

    Yields ``(line_number, {column: text})`` for each non-blank row.
    """
    reader = csv.reader(text.splitlines())
    header = None
    for row in reader:
        if any(cell.strip() for cell in row):
            header = [cell.strip() for cell in row]
            break
    if header is None:
        raise InputError(f"{path}: empty {what} file (expected a CSV header)")
    missing = [c for c in required if c not in header]
    if missing:
        _refuse_yaml(path, ",".join(header), f"{what} CSV")
        raise InputError(
            f"{path}: {what} file lacks column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(missing)} (needs {', '.join(required)}; has {', '.join(header) or 'none'})"
        )
    index = {name: i for i, name in reversed(list(enumerate(header)))}
    rows = []
    try:
        for row in reader:
            if not any(cell.strip() for cell in row):
                continue
            where = f"{path} line {reader.line_num}"
            if len(row) != len(header):
                raise InputError(f"{where}: expected {len(header)} fields as in the header, got {len(row)}")
            rows.append((where, {name: row[i] for name, i in index.items()}))
    except csv.Error as exc:
        raise InputError(f"{path} line {reader.line_num}: malformed CSV ({exc})") from None
    return header, rows


def load_track(path: PathLike) -> Track:
    """Read trackcli's per-frame estimates CSV.

    Parameters
    ----------
    path : str or os.PathLike
        CSV with a header naming at least ``frame, cx, cy, bbox_x, bbox_y, bbox_w, bbox_h``;
        an optional ``lost`` column (0/1) is read; other columns are ignored.  Empty or NaN
        estimate cells mean "no estimate" for that frame.

    Returns
    -------
    Track
        Rows sorted by frame.

    Raises
    ------
    InputError
        File missing or unreadable, required columns missing, a malformed value (the message
        names the line), a repeated frame, a negative box size, or no rows.
    """
    path = Path(path)
    text = _read_text(path, "predictions")
    header, rows = _csv_table(path, text, _TRACK_COLUMNS, "predictions")
    has_lost = "lost" in header
    if not rows:
        raise InputError(f"{path}: predictions file has a header but no rows")
    frames, centres, boxes, lost = [], [], [], []
    seen: dict[int, str] = {}
    for where, rec in rows:
        f = _frame_index(rec["frame"], where)
        if f in seen:
            raise InputError(f"{where}: frame {f} repeats ({seen[f]})")
        seen[f] = where
        box = [_number(rec[c], where, c) for c in _BOX_COLUMNS]
        if box[2] < 0 or box[3] < 0:
            raise InputError(f"{where}: bbox_w and bbox_h must be >= 0, got {box[2]:g}, {box[3]:g}")
        frames.append(f)
        centres.append([_number(rec["cx"], where, "cx"), _number(rec["cy"], where, "cy")])
        boxes.append(box)
        lost.append(_flag(rec["lost"], where, "lost") if has_lost else False)
    order = np.argsort(frames, kind="stable")
    outline = _track_outlines(path, header, rows)
    return Track(
        np.asarray(frames)[order],
        np.asarray(centres).reshape(-1, 2)[order],
        np.asarray(boxes).reshape(-1, 4)[order],
        np.asarray(lost, dtype=bool)[order],
        source=str(path),
        outline=None if outline is None else outline[order],
    )


def _track_outlines(path: Path, header: list[str], rows) -> np.ndarray | None:
    """The closed outlines of a track CSV, (N, P, 2), or None (no outline columns, or open curves)."""
    n = 0
    while f"outline_x{n}" in header and f"outline_y{n}" in header:
        n += 1
    if n < 3:
        return None
    names = [f"outline_{a}{i}" for i in range(n) for a in "xy"]
    out = np.empty((len(rows), n, 2))
    for k, (where, rec) in enumerate(rows):
        if "outline_closed" in rec and rec["outline_closed"].strip() == "0":
            log.info("%s: the outlines are open curves; no outline IoU", path)
            return None
        out[k] = np.array([_number(rec[c], where, c) for c in names]).reshape(n, 2)
    return out


_BOX_SPLIT = re.compile(r"\s*,\s*|\s+")
_POLYGON_FIELDS = tuple(f"{a}{k}" for k in range(1, 5) for a in "xy")  # x1, y1, ..., x4, y4


def _load_box_file(path: Path, text: str) -> GroundTruth:
    """One ``x,y,w,h`` box per line, or a VOT polygon ``x1,y1,...,x4,y4`` (its bounding box)."""
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise InputError(f"{path}: empty truth file (expected one x,y,w,h line per frame)")
    boxes = np.empty((len(lines), 4))
    polygons = 0
    for i, line in enumerate(lines):
        where = f"{path} line {i + 1}"
        stripped = line.strip()
        if not stripped:
            raise InputError(
                f"{where}: blank line inside the box list (write NaN,NaN,NaN,NaN for a frame without the target)"
            )
        tokens = _BOX_SPLIT.split(stripped)
        if len(tokens) not in (4, 8):
            raise InputError(f"{where}: expected 4 numbers (x,y,w,h) or 8 (a polygon x1,y1,...,x4,y4), "
                             f"got {len(tokens)}")
        names = "xywh" if len(tokens) == 4 else _POLYGON_FIELDS
        for token, name in zip(tokens, names):
            if token == "":
                raise InputError(f"{where}: empty field {name} (expected {len(tokens)} numbers)")
        values = np.array([_number(token, where, name) for token, name in zip(tokens, names)])
        if len(tokens) == 8:
            # a rotated box as in VOT: scored by the rectangle around it (NaN: no target)
            polygons += 1
            xs, ys = values[0::2], values[1::2]
            values = np.array([xs.min(), ys.min(), xs.max() - xs.min(), ys.max() - ys.min()])
        boxes[i] = values
        if boxes[i, 2] < 0 or boxes[i, 3] < 0:
            raise InputError(f"{where}: w and h must be >= 0, got {boxes[i, 2]:g}, {boxes[i, 3]:g}")
    if polygons:
        log.info("%s: %d polygon lines scored by their bounding rectangles", path, polygons)
    return GroundTruth.from_boxes(boxes, source=str(path))


def _load_truth_csv(path: Path, text: str, object_id: int, outlines: PlaceOutlines | None) -> GroundTruth:
    header, rows = _csv_table(path, text, _TRUTH_COLUMNS, "truth")
    has_object = "object" in header
    has_visible = "visible" in header
    records: dict[int, tuple[int, list[float], list[float], bool, str, dict]] = {}
    objects: set[int] = set()
    for where, rec in rows:
        obj = _frame_index(rec["object"], where) if has_object else 0
        objects.add(obj)
        if obj != object_id:
            continue
        f = _frame_index(rec["frame"], where)
        if f in records:
            raise InputError(f"{where}: frame {f} of object {obj} repeats ({records[f][4]})")
        centre = [_number(rec["cx"], where, "cx"), _number(rec["cy"], where, "cy")]
        box = [_number(rec[c], where, c) for c in _BOX_COLUMNS]
        if box[2] < 0 or box[3] < 0:
            raise InputError(f"{where}: bbox_w and bbox_h must be >= 0, got {box[2]:g}, {box[3]:g}")
        if has_visible:
            fraction = _number(rec["visible"], where, "visible")
            if not (fraction >= 0.0 and fraction <= 1.0):
                raise InputError(f"{where}: visible must be a fraction from 0 to 1, got {rec['visible'].strip()!r}")
            visible = fraction > 0.0
        else:
            visible = True
        records[f] = (f, centre, box, visible, where, rec)
    if not objects:
        raise InputError(f"{path}: truth file has a header but no rows")
    if not records:
        raise ConfigError(
            f"{path}: no truth for object {object_id}; objects in the file: {', '.join(map(str, sorted(objects)))}"
        )
    ordered = [records[f] for f in sorted(records)]
    frame = np.array([r[0] for r in ordered], dtype=np.int64)
    centre = np.array([r[1] for r in ordered], dtype=np.float64)
    box = np.array([r[2] for r in ordered], dtype=np.float64)
    visible = np.array([r[3] for r in ordered], dtype=bool)
    finite = np.all(np.isfinite(box), axis=1) & np.all(np.isfinite(centre), axis=1)
    present = visible & finite & (box[:, 2] > 0) & (box[:, 3] > 0)
    outline = _truth_outlines(path, header, [r[5] for r in ordered], outlines) if outlines else None
    return GroundTruth(frame, centre, box, present, centre_kind="centroid", source=str(path), outline=outline)


def _truth_outlines(path: Path, header: list[str], records: list[dict], place: PlaceOutlines) -> np.ndarray | None:
    """True outlines of a sample-data truth CSV from ``<clip>.outline.json`` beside it, or None."""
    name = path.name
    if not name.endswith(".truth.csv") or not all(c in header for c in ("tx", "ty", "angle", "scale")):
        return None
    json_path = path.with_name(name[: -len(".truth.csv")] + ".outline.json")
    if not json_path.is_file():
        return None
    try:
        return place(json_path, records)
    except ValueError as exc:
        raise InputError(f"{path}: cannot place the outline of {json_path.name} ({exc})") from None


def load_truth(path: PathLike, *, object_id: int = 0, outlines: PlaceOutlines | None = None) -> GroundTruth:
    """Read ground truth, recognising its format from its content.

    Parameters
    ----------
    path : str or os.PathLike
        A trackcli truth CSV (first line a header naming ``frame``), a benchmark box file
        (one ``x,y,w,h`` line per frame, frame 0 first; commas, tabs or spaces; NaN or
        ``0,0,0,0`` lines mark frames without the target; a line of 8 numbers is a VOT polygon
        ``x1,y1,...,x4,y4``, read as the rectangle around it), or a folder containing one of
        :data:`TRUTH_FILE_NAMES`.
    object_id : int
        Which object of a trackcli truth CSV to read (column ``object``); ignored for box
        files.
    outlines : callable, optional
        Places the true outlines of a sample clip's truth CSV (:data:`PlaceOutlines`); used
        when the CSV, ``<clip>.truth.csv``, has the pose columns ``tx, ty, angle, scale`` and
        ``<clip>.outline.json`` lies beside it.  Without it, ``outline`` is None.

    Returns
    -------
    GroundTruth

    Raises
    ------
    InputError
        Missing or unreadable file, a folder with no known truth file, or a malformed line
        (the message names the file and line).
    ConfigError
        ``object_id`` does not occur in the truth CSV (the message lists those that do).
    """
    if isinstance(object_id, bool) or not isinstance(object_id, (int, np.integer)) or object_id < 0:
        raise ConfigError(f"object_id: expected an integer >= 0, got {object_id!r}")
    path = Path(path)
    if path.is_dir():
        for name in TRUTH_FILE_NAMES:
            candidate = path / name
            if candidate.is_file():
                path = candidate
                break
        else:
            raise InputError(f"{path}: folder holds no ground truth (looked for {', '.join(TRUTH_FILE_NAMES)})")
    text = _read_text(path, "truth")
    first = next((line for line in text.splitlines() if line.strip()), "")
    header_cells = [cell.strip().lower() for cell in first.split(",")]
    if "frame" in header_cells:
        return _load_truth_csv(path, text, int(object_id), outlines)
    _refuse_yaml(path, first, "truth file")
    return _load_box_file(path, text)
