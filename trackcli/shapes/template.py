"""Templates: a B-spline outline drawn around the object in one frame of one clip.

A template file is YAML::

    format: 1
    kind: trackcli-template
    clip: sample_data/train.mp4     # the clip the template was drawn on (as given)
    frame: 0                        # the frame it was drawn on
    frame_size: [480, 360]          # width, height of that frame
    degree: 2                       # spline degree (2 = quadratic)
    closed: true
    control_points:                 # (x, y) in image pixels of that frame
      - [212.5, 101.0]
      - ...
    source: "box 180,60,120,200"    # how it was made
    box: [180.0, 60.0, 120.0, 200.0] # the box it was drawn from (x, y, w, h; only draw --box)
    region:                         # the segmented region's boundaries: of each piece, largest
      - [[183, 62], [184, 62], ...] #   first, then of the holes (only draw --box and --mask)

The control points are in the image coordinates of the stated frame; the shape-space built
on a template has ``Q0`` equal to these points, so ``X = 0`` is the object where it was drawn.
The spline only approximates a segmented region (a mask, a box's segmentation); ``region``
keeps the region itself, from which the outline refinement learns the object's colours and
starts (:class:`trackcli.observe.region.OutlineRefiner`).
"""

from __future__ import annotations

import copy
import threading

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from trackcli.errors import TemplateError
from trackcli.io.outputs import other_kind, read_yaml_file, write_text

FORMAT = 1
KIND = "trackcli-template"


@dataclass(frozen=True)
class Template:
    """A drawn outline.

    Attributes
    ----------
    control_points : ndarray of shape (Nq, 2)
        Control points ``(x, y)`` in pixels of the frame the template was drawn on.
    degree : int
        B-spline degree (2 = quadratic).
    closed : bool
        Closed (periodic) or open curve.
    clip : str or None
        The clip the template refers to, as the user gave it.
    frame : int
        Frame index in that clip.
    frame_size : tuple of int or None
        ``(width, height)`` of that frame.
    source : str
        How the template was made (for provenance).
    box : tuple of float or None
        The box ``(x, y, w, h)`` the outline was segmented from (``draw --box``), as given:
        a track started at the template reports this box carried along by the estimate
        (:class:`trackcli.io.tracks.BoxCarry`).
    region : tuple of ndarray of shape (P, 2), or None
        The region the outline was fitted to (``draw --mask`` / ``--box``): the outer boundary
        of each of its pieces, largest first, then the boundaries of its holes, in pixel centres
        of the drawn frame (:func:`trackcli.observe.region.mask_polygons`; a pixel is the
        region's when inside an odd number of them).
    """

    control_points: np.ndarray
    degree: int = 2
    closed: bool = True
    clip: str | None = None
    frame: int = 0
    frame_size: tuple[int, int] | None = None
    source: str = ""
    box: tuple[float, float, float, float] | None = None
    region: tuple[np.ndarray, ...] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        cp = np.asarray(self.control_points, dtype=float)
        if cp.ndim != 2 or cp.shape[1] != 2:
            raise TemplateError(f"control points must be a list of (x, y) pairs, got an array of shape {cp.shape}")
        if not np.all(np.isfinite(cp)):
            raise TemplateError("control points must be finite numbers")
        if self.degree < 1 or self.degree > 5:
            raise TemplateError(f"degree must be between 1 and 5, got {self.degree}")
        need = self.degree + 1 if not self.closed else max(3, self.degree + 1)
        if len(cp) < need:
            raise TemplateError(f"a degree-{self.degree} {'closed' if self.closed else 'open'} curve needs at least {need} control points, got {len(cp)}")
        object.__setattr__(self, "control_points", cp)
        if self.box is not None:
            b = np.asarray(self.box, dtype=float).reshape(-1)
            if b.size != 4 or not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
                raise TemplateError(f"box must be [x, y, width, height] with a positive width and height, got {self.box!r}")
            object.__setattr__(self, "box", tuple(float(v) for v in b))
        if self.region is not None:
            pieces = []
            for k, piece in enumerate(self.region):
                a = np.asarray(piece, dtype=float)
                if a.ndim != 2 or a.shape[1] != 2 or len(a) < 3 or not np.all(np.isfinite(a)):
                    raise TemplateError(f"region: piece {k} must be a list of at least three finite [x, y] pairs")
                pieces.append(a)
            object.__setattr__(self, "region", tuple(pieces) or None)

    @property
    def n_ctrl(self) -> int:
        return len(self.control_points)

    @property
    def Q(self) -> np.ndarray:
        """Stacked control vector ``(Qx; Qy)`` of shape ``(2 Nq,)``."""
        return np.concatenate([self.control_points[:, 0], self.control_points[:, 1]])

    def basis(self):
        """The :class:`~trackcli.shapes.spline.SplineBasis` of this template."""
        from trackcli.shapes.spline import SplineBasis

        return SplineBasis(self.n_ctrl, degree=self.degree, closed=self.closed)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "format": FORMAT,
            "kind": KIND,
            "clip": self.clip,
            "frame": int(self.frame),
            "frame_size": list(self.frame_size) if self.frame_size else None,
            "degree": int(self.degree),
            "closed": bool(self.closed),
            "control_points": [[round(float(x), 4), round(float(y), 4)] for x, y in self.control_points],
            "source": self.source,
        }
        if self.box is not None:
            d["box"] = [round(v, 4) for v in self.box]
        if self.region is not None:
            d["region"] = [[[_num(x), _num(y)] for x, y in piece] for piece in self.region]
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: Any, where: str = "template") -> "Template":
        if not isinstance(d, dict):
            raise TemplateError(f"{where}: expected a mapping, got {type(d).__name__}")
        if d.get("kind") != KIND:
            raise TemplateError(f"{where}: not a trackcli template (kind: {d.get('kind')!r}, expected {KIND!r})")
        if d.get("format") != FORMAT:
            raise TemplateError(f"{where}: unsupported template format {d.get('format')!r} (this version reads {FORMAT})")
        try:
            cp = np.asarray(d["control_points"], dtype=float)
        except KeyError:
            raise TemplateError(f"{where}: missing 'control_points'") from None
        except (TypeError, ValueError):
            raise TemplateError(f"{where}: control_points must be a list of [x, y] number pairs") from None
        size = d.get("frame_size")
        if size is not None:
            if not (isinstance(size, (list, tuple)) and len(size) == 2 and all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size)):
                raise TemplateError(f"{where}: frame_size must be [width, height] in pixels, got {size!r}")
            size = (int(size[0]), int(size[1]))
        frame = d.get("frame", 0)
        if not isinstance(frame, int) or isinstance(frame, bool) or frame < 0:
            raise TemplateError(f"{where}: frame must be an integer >= 0, got {frame!r}")
        degree = d.get("degree", 2)
        if not isinstance(degree, int) or isinstance(degree, bool):
            raise TemplateError(f"{where}: degree must be an integer, got {degree!r}")
        closed = d.get("closed", True)
        if not isinstance(closed, bool):
            raise TemplateError(f"{where}: closed must be true or false, got {closed!r}")
        box = d.get("box")
        if box is not None:
            if not (isinstance(box, (list, tuple)) and len(box) == 4
                    and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in box)):
                raise TemplateError(f"{where}: box must be [x, y, width, height] in pixels, got {box!r}")
        region = d.get("region")
        if region is not None:
            try:
                if not isinstance(region, list):
                    raise TypeError
                region = tuple(np.asarray(piece, dtype=float) for piece in region)
            except (TypeError, ValueError):
                raise TemplateError(f"{where}: region must be a list of polygons, each a list of [x, y] number pairs") from None
        known = {"format", "kind", "clip", "frame", "frame_size", "degree", "closed", "control_points", "source", "box",
                 "region"}
        try:
            return cls(cp, degree=degree, closed=closed, clip=d.get("clip"), frame=frame, frame_size=size,
                       source=str(d.get("source", "")), box=None if box is None else tuple(box), region=region,
                       extra={k: v for k, v in d.items() if k not in known})
        except TemplateError as exc:
            raise TemplateError(f"{where}: {exc}") from None


def _num(v: float) -> int | float:
    """A coordinate as YAML writes it: an integer when it is one (a pixel centre), else 4 decimals."""
    f = round(float(v), 4)
    return int(f) if f.is_integer() else f


def save_template(path: str | Path, template: Template) -> Path:
    """Write ``template`` as YAML (atomically)."""
    return write_text(path, yaml.safe_dump(template.to_dict(), sort_keys=False, default_flow_style=None))


def load_template(path: str | Path) -> Template:
    """Read and validate a template file.

    A run reads its template several times (its shape-space, its region, its box); the file's
    parsed YAML is kept for as long as the file is unchanged (its path, size and modification
    time), since parsing a template with its region took 0.15 s each time (each call still
    builds a new :class:`Template` from a copy of it).
    """
    p = Path(path)
    data = copy.deepcopy(_parsed(p))
    if not isinstance(data, dict) or data.get("kind") is None:
        raise TemplateError(f"{p}: not a trackcli template (a YAML file written by 'trackcli draw')")
    other = other_kind(data, KIND)
    if other:
        raise TemplateError(f"{p}: {other}, not a template (a YAML file written by 'trackcli draw')")
    return Template.from_dict(data, where=str(p))


#: parsed template files by (absolute path, size, modification time): :func:`load_template`
_PARSED: dict[tuple[str, int, int], Any] = {}
_PARSED_MAX = 8
_PARSED_LOCK = threading.Lock()


def _parsed(p: Path) -> Any:
    try:
        st = p.stat()
        key = (str(p.absolute()), st.st_size, st.st_mtime_ns)
    except OSError:  # read_yaml_file says why, in one line
        return read_yaml_file(p, "template", TemplateError)
    with _PARSED_LOCK:
        data = _PARSED.get(key)
    if data is None:
        data = read_yaml_file(p, "template", TemplateError)
        with _PARSED_LOCK:
            while len(_PARSED) >= _PARSED_MAX:
                _PARSED.pop(next(iter(_PARSED)))
            _PARSED[key] = data
    return data
