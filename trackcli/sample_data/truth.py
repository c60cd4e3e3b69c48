"""The truth CSV and the outline JSON of a sample clip: their formats and readers."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trackcli.errors import ConfigError, InputError
from trackcli.sample_data.common import TRUTH_COLUMNS, _DECIMALS


# =============================================================================================
# Ground truth containers and files


@dataclass(frozen=True, eq=False)
class Truth:
    """Per-frame ground truth of a clip: one entry per (frame, object), frame-major.

    Every attribute is an array of shape ``(N,)`` named as the CSV column
    (:data:`TRUTH_COLUMNS`); ``frame`` and ``object`` are integers.
    """

    frame: np.ndarray
    time: np.ndarray
    object: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    bbox_x: np.ndarray
    bbox_y: np.ndarray
    bbox_w: np.ndarray
    bbox_h: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    angle: np.ndarray
    scale: np.ndarray
    visible: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    @property
    def objects(self) -> tuple[int, ...]:
        """The object indices present, ascending."""
        return tuple(int(o) for o in np.unique(self.object))

    @property
    def n_frames(self) -> int:
        """Number of distinct frames."""
        return int(np.unique(self.frame).size)

    def select(self, object_id: int) -> Truth:
        """The rows of one object, in frame order."""
        keep = self.object == object_id
        if not keep.any():
            raise ConfigError(f"no object {object_id!r} in this truth; objects are {self.objects}")
        return Truth(**{c: getattr(self, c)[keep] for c in TRUTH_COLUMNS})

    def row(self, i: int) -> dict[str, float | int]:
        """Row ``i`` as a dict of column name to value (usable by :func:`true_outline`)."""
        return {c: getattr(self, c)[i].item() for c in TRUTH_COLUMNS}

    def pose(self) -> np.ndarray:
        """``(tx, ty, angle, scale)`` of every row, shape ``(N, 4)``."""
        return np.stack([self.tx, self.ty, self.angle, self.scale], axis=1)

    def to_csv(self) -> str:
        """The CSV text, with fixed decimals per column (see ``_DECIMALS``)."""
        lines = [",".join(TRUTH_COLUMNS)]
        cols = [getattr(self, c) for c in TRUTH_COLUMNS]
        fmts = ["{:d}" if c in ("frame", "object") else f"{{:.{_DECIMALS[c]}f}}"
                for c in TRUTH_COLUMNS]  # fmt: skip
        for i in range(len(self)):
            lines.append(",".join(f.format(_plain(col[i])) for f, col in zip(fmts, cols)))
        return "\n".join(lines) + "\n"


def _plain(v):
    """A numpy scalar as a Python int/float, with ``-0.0`` made ``0.0`` for stable text."""
    v = v.item()
    return v + 0.0 if isinstance(v, float) else v


@dataclass(frozen=True, eq=False)
class Outline:
    """A clip's base outline and description, as stored in ``<clip>.outline.json``.

    Attributes
    ----------
    points : ndarray of shape (P, 2)
        Base outline in object coordinates, centred on its area centroid, counter-clockwise
        on the screen.
    clip : str
        Clip name (``"train"``, ...).
    video : str
        File name of the video beside the outline file.
    fps : float
    width, height : int
    n_frames : int
    seed : int
    objects : tuple of str
        What object ``j`` of the truth file is, by index.
    motion : dict
        Parameters of the simulated motion (clip-specific).
    """

    points: np.ndarray
    clip: str
    video: str
    fps: float
    width: int
    height: int
    n_frames: int
    seed: int
    objects: tuple[str, ...]
    motion: dict = field(default_factory=dict)


def load_truth(csv_path) -> Truth:
    """Read a ``<clip>.truth.csv`` written by this module.

    Parameters
    ----------
    csv_path : str or os.PathLike

    Returns
    -------
    Truth

    Raises
    ------
    InputError
        The file is missing, its header is not :data:`TRUTH_COLUMNS`, or a value is not a
        number.
    """
    path = Path(csv_path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot read truth file ({exc.strerror or exc})") from None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise InputError(f"{path}: empty truth file (expected header {','.join(TRUTH_COLUMNS)})")
    header = tuple(c.strip() for c in lines[0].split(","))
    if header != TRUTH_COLUMNS:
        raise InputError(
            f"{path}: truth header is {','.join(header)!r}; expected {','.join(TRUTH_COLUMNS)!r}"
        )
    if len(lines) == 1:
        raise InputError(f"{path}: truth file has a header but no rows")
    table = np.empty((len(lines) - 1, len(TRUTH_COLUMNS)))
    for i, line in enumerate(lines[1:]):
        cells = line.split(",")
        if len(cells) != len(TRUTH_COLUMNS):
            raise InputError(
                f"{path} line {i + 2}: expected {len(TRUTH_COLUMNS)} fields, got {len(cells)}"
            )
        try:
            table[i] = [float(c) for c in cells]
        except ValueError:
            raise InputError(f"{path} line {i + 2}: non-numeric field in {line!r}") from None
    cols = {c: table[:, j] for j, c in enumerate(TRUTH_COLUMNS)}
    for c in ("frame", "object"):
        if not np.all(cols[c] == np.round(cols[c])) or np.any(cols[c] < 0):
            raise InputError(f"{path}: column {c} must hold non-negative integers")
        cols[c] = cols[c].astype(np.int64)
    return Truth(**cols)


def load_outline(json_path) -> Outline:
    """Read a ``<clip>.outline.json`` written by this module.

    Raises
    ------
    InputError
        The file is missing, not JSON, of another ``format`` than 1, or lacks a field; or its
        ``points`` are not a finite ``(P, 2)`` list with ``P >= 3``.
    """
    path = Path(json_path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"{path}: cannot read outline file ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    if not isinstance(doc, dict) or doc.get("format") != 1:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{path}: outline format must be 1, got {got!r}")
    try:
        clip = doc["clip"]
        pts = np.asarray(doc["points"], dtype=float)
        out = Outline(
            points=pts,
            clip=str(clip["name"]),
            video=str(clip["video"]),
            fps=float(clip["fps"]),
            width=int(clip["width"]),
            height=int(clip["height"]),
            n_frames=int(clip["n_frames"]),
            seed=int(clip["seed"]),
            objects=tuple(str(o) for o in clip["objects"]),
            motion=dict(doc.get("motion", {})),
        )
    except KeyError as exc:
        raise InputError(f"{path}: outline file lacks field {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"{path}: malformed outline file ({exc})") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3 or not np.all(np.isfinite(pts)):
        raise InputError(f"{path}: points must be a finite list of >= 3 [x, y] pairs, got shape {pts.shape}")
    return out
