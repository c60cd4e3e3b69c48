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
columns, re-anchored on the new template's translation (see :func:`place_space`), and the
dynamics are adapted to the new clip (see :func:`place_dynamics`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .config import Settings, settings_from_dict, to_dict
from .dynamics import AR2, symmetric_sqrt
from .errors import ConfigError, ModelError, TrackcliError
from .outputs import read_yaml_file, write_text
from .shape_space import ShapeSpace
from .template import Template

log = logging.getLogger(__name__)

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
    d = read_yaml_file(p, "model", ModelError)
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


def translation_split(space: ShapeSpace) -> tuple[np.ndarray, np.ndarray]:
    """Projectors ``(Es, Ed)``, each (Nx, Nx), with ``Es + Ed = I``, splitting shape vectors
    into translation and the rest of shape-space.

    Where two axes of the space are the rigid translations of the curve (``tx, ty`` of the
    translation, similarity, affine, key-frame and residual-PCA spaces), the split follows the
    axes: ``Es`` keeps those two components and ``Ed`` the others (shape change about the
    space's origin, the template's centroid), so that a model's blocks are the ones it was
    learned in.  Otherwise ``Es`` is the L2-orthogonal projection onto the translation
    subspace (:meth:`ShapeSpace.translation_projector`) and ``Ed = I − Es``.
    """
    n = space.Nq
    shifts = np.zeros((2 * n, 2))
    shifts[:n, 0] = 1.0
    shifts[n:, 1] = 1.0
    axes = [next((j for j in range(space.Nx) if np.allclose(space.W[:, j], shifts[:, i], atol=1e-9)), None)
            for i in range(2)]
    if None in axes:
        Es = space.translation_projector()
    else:
        Es = np.zeros((space.Nx, space.Nx))
        Es[axes, axes] = 1.0
    return Es, np.eye(space.Nx) - Es


def place_dynamics(
    dynamics: AR2,
    space: ShapeSpace,
    X0: np.ndarray | None,
    tau: float,
    *,
    translation_noise: float = 1.0,
    deformation_noise: float = 1.0,
) -> AR2:
    """A learned model's dynamics, adapted for tracking a clip.

    Three changes turn the dynamics learned on the training clips into the dynamics used
    on another clip; none alters how the shape moves *within* translation or *within* the
    rest of shape-space, apart from the size of the motion.

    1. **Translation decoupled from the rest** (the structure of the partitioned model,
       AC eq 9.30).  ``A1``, ``A2`` and the noise covariance ``C = B0 B0ᵀ`` are reduced to
       their blocks on translation and on the rest of shape-space (projectors ``Es`` and
       ``Ed = I − Es`` of :func:`translation_split`): ``A ↦ Es A Es + Ed A Ed``.  The
       coupling learned between the two ties the object's shape to where it happened to
       stand in the training frame (a few hundred frames fit it poorly, and a position term
       turns pixels of translation into scale or rotation); on a new clip, where the object
       roams elsewhere, it distorts the predicted shape.
    2. **Process noise scaled**, by ``translation_noise`` in translation and by
       ``deformation_noise`` in the rest: ``C ↦ t² Es C Esᵀ + d² Ed C Edᵀ``.  The papers
       learn from training motion of the same kind as the test motion (the dancer, AC
       §12.4); where the training clip moves more gently, these factors say how much more
       agile the new clip is.  AR(2) dynamics being linear, the model's motions (excursions,
       speeds, accelerations) in each part are scaled by its factor, while their time course
       (damping, frequencies) is kept.
    3. **Translation mean moved** to the translation of ``X0`` (where the object is placed),
       the rest of the mean kept: ``X̄ ↦ Ed X̄ + Es X0``.  With ``X0 = None`` the mean stays
       as learned.

    The frame interval ``tau`` (s) of the clip is compared with the model's and only
    warned about: learned dynamics are used per frame as learned.

    Parameters
    ----------
    dynamics : AR2
        As learned (``trackcli learn``).
    space : ShapeSpace
        The model's shape-space (before or after :func:`place_space`: the split is the same).
    X0 : ndarray of shape (Nx,) or None
        Initial shape on the new clip.
    tau : float
        Frame interval of the new clip, seconds.
    translation_noise, deformation_noise : float
        Factors on the process noise (> 0; 1 keeps it as learned).

    Returns
    -------
    AR2

    Raises
    ------
    ConfigError
        A factor is not a number > 0.
    ModelError
        The dynamics and the shape-space have different dimensions.
    """
    for name, value in (("translation_noise", translation_noise), ("deformation_noise", deformation_noise)):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"placement.{name}: expected a number > 0, got {value!r}")
    if dynamics.nx != space.Nx:
        raise ModelError(f"the dynamics have {dynamics.nx} components but the shape-space has {space.Nx}")
    if not math.isclose(dynamics.tau, tau, rel_tol=1e-3):
        log.warning("the model was learned at %.3g frames/s but this clip runs at %.3g frames/s; "
                    "its dynamics are used per frame as learned", 1 / dynamics.tau, 1 / tau)
    Es, Ed = translation_split(space)

    def blocks(A: np.ndarray) -> np.ndarray:
        return Es @ A @ Es + Ed @ A @ Ed

    C = dynamics.B0 @ dynamics.B0.T
    C = translation_noise**2 * (Es @ C @ Es.T) + deformation_noise**2 * (Ed @ C @ Ed.T)
    mean = dynamics.mean if X0 is None else Ed @ dynamics.mean + Es @ np.asarray(X0, dtype=float)
    return AR2(blocks(dynamics.A2), blocks(dynamics.A1), symmetric_sqrt(C), mean, dynamics.tau)
