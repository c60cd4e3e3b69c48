"""Model files: everything needed to track an object class in new footage.

A model is YAML::

    format: 1
    kind: trackcli-model
    template: {...}          # the template it was built on (see trackcli.template)
    shape_space: {...}       # W, Q0, origin, spline basis (see ShapeSpace.to_dict)
    dynamics: {...}          # AR(2): tau, mean, A2, A1, B0 (see AR2.to_dict)
    settings: {...}          # measurement / Kalman / CONDENSATION settings used to learn it
    provenance: {...}        # clips, frames, cycles, learning report

``X = 0`` in the model's shape-space is the template where it was drawn on the training
clip.  To track in another clip, the user places the model there with a template drawn on
that clip (``--model M --template T``): the shape-space keeps its learned deformation
columns, re-anchored on the new template's translation (see :func:`place_space`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .config import Settings, settings_from_dict, to_dict
from .dynamics import AR2
from .errors import ConfigError, ModelError, TrackcliError
from .outputs import write_text
from .shape_space import ShapeSpace
from .template import Template

FORMAT = 1
KIND = "trackcli-model"


@dataclass(frozen=True, eq=False)
class Model:
    template: Template
    space: ShapeSpace
    dynamics: AR2
    settings: Settings
    provenance: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "kind": KIND,
            "template": self.template.to_dict(),
            "shape_space": self.space.to_dict(),
            "dynamics": self.dynamics.to_dict(),
            "settings": to_dict(self.settings),
            "provenance": self.provenance,
        }


def save_model(path: str | Path, model: Model) -> Path:
    """Write a model file atomically."""
    return write_text(path, "# trackcli model (see `trackcli inspect`)\n"
                      + yaml.safe_dump(model.to_dict(), sort_keys=False, default_flow_style=None, width=120))


def load_model(path: str | Path) -> Model:
    """Read and validate a model file; errors name the file and the key."""
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"{p}: no such model file")
    try:
        d = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ModelError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(d, dict) or d.get("kind") != KIND:
        raise ModelError(f"{p}: not a trackcli model file (expected kind: {KIND})")
    if d.get("format") != FORMAT:
        raise ModelError(f"{p}: unsupported model format {d.get('format')!r} (this version reads {FORMAT})")
    for key in ("template", "shape_space", "dynamics"):
        if key not in d:
            raise ModelError(f"{p}: missing '{key}'")
    try:
        template = Template.from_dict(d["template"], where=f"{p}: template")
        space = ShapeSpace.from_dict(d["shape_space"], where=f"{p}: shape_space")
        dynamics = AR2.from_dict(d["dynamics"], where=f"{p}: dynamics")
        settings = settings_from_dict(d.get("settings") or {})
    except ConfigError as exc:
        raise ModelError(f"{p}: settings.{exc}") from None
    except TrackcliError as exc:
        raise ModelError(str(exc)) from None
    if dynamics.nx != space.Nx:
        raise ModelError(f"{p}: dynamics has {dynamics.nx} components but the shape-space has {space.Nx}")
    prov = d.get("provenance") or {}
    return Model(template, space, dynamics, settings, prov if isinstance(prov, dict) else {})


def place_space(space: ShapeSpace, template: Template) -> tuple[ShapeSpace, np.ndarray]:
    """Re-anchor a learned shape-space on a template drawn in another clip.

    The new space keeps the model's deformation columns and template shape, translated so
    that its centroid lands on the new template's centroid.  The initial shape ``X0`` puts
    the model's template there at the size of the new template (the square root of the
    ratio of their areas) where the space has a scale direction (similarity, affine).

    Only position and size are taken from the new template: a template outlined
    automatically in clutter is often too ragged to say more (its rotation, for instance),
    and the tracker itself refines the shape from the first frame on.

    Returns ``(space, X0)``.
    """
    if template.n_ctrl != space.Nq or template.degree != space.basis.degree or template.closed != space.basis.closed:
        raise ModelError(
            f"the template has {template.n_ctrl} control points (degree {template.degree}, "
            f"{'closed' if template.closed else 'open'}) but the model's curve has {space.Nq} "
            f"(degree {space.basis.degree}, {'closed' if space.basis.closed else 'open'}); "
            "draw the template with the same --n-ctrl")
    from .spline import curve_area_centroid

    Q = template.Q
    if template.closed:
        area_new, c_new = curve_area_centroid(Q, template.basis())
        area_old, _ = curve_area_centroid(space.Q0, space.basis)
        ratio = float(np.sqrt(abs(area_new) / abs(area_old))) if abs(area_old) > 0 else 1.0
    else:
        c_new = template.control_points.mean(axis=0)
        ratio = 1.0
    shift = np.asarray(c_new, dtype=float) - space.origin
    n = space.Nq
    Q0 = space.Q0.copy()
    Q0[:n] += shift[0]
    Q0[n:] += shift[1]
    d = space.to_dict()
    d["Q0"] = Q0.tolist()
    d["origin"] = (space.origin + shift).tolist()
    placed = ShapeSpace.from_dict(d)
    # the model's template scaled by `ratio` about the new centroid, expressed in the space
    centre = np.concatenate([np.full(n, c_new[0]), np.full(n, c_new[1])])
    X0 = placed.project(centre + ratio * (Q0 - centre))
    X0[:2] = 0.0
    return placed, X0
