"""Model files: everything needed to track an object class in new footage.

A model is YAML::

    format: 1
    kind: trackcli-model
    template: {...}          # the template it was built on (see trackcli.shapes.template)
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
from typing import Any, Collection

import numpy as np
import yaml

from trackcli.settings import Settings, replace, settings_from_dict, to_dict
from trackcli.dynamics.ar2 import AR2
from trackcli.errors import ConfigError, ModelError, TrackcliError
from trackcli.io.outputs import other_kind, read_yaml_file, write_text
from trackcli.shapes.shape_space import ShapeSpace
from trackcli.shapes.template import Template

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
    other = other_kind(d, KIND)
    if other:
        raise ModelError(f"{p}: {other}, not a model (a YAML file written by 'trackcli learn')")
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


def scale_direction(space: ShapeSpace) -> np.ndarray | None:
    """The shape vector ``e`` that scales the space's template about its origin, or None.

    ``W e = Q0 − origin`` (per coordinate): then ``X ↦ s X + (s − 1) e`` is the same curve
    scaled by ``s`` about the origin, and translation by ``s`` too, for every ``X``.  The
    similarity and affine spaces (and spaces extending them) have such a direction; a
    translation or PCA space does not (None).
    """
    n = space.Nq
    rel = space.Q0.copy()
    rel[:n] -= space.origin[0]
    rel[n:] -= space.origin[1]
    e = space.pinv @ rel
    residual = space.W @ e - rel
    size = float(np.sqrt(rel @ space.basis.U @ rel))
    if size == 0 or float(np.sqrt(residual @ space.basis.U @ residual)) > 1e-6 * size:
        return None
    return e


#: The sections of a model's stored settings that ``track --model`` uses (unless the user
#: sets a key of them): how the object's outline was measured when the model was learned.
MODEL_SECTIONS = ("measurement",)


def settings_with_model(settings: Settings, model_settings: Settings, explicit: Collection[str],
                        where: str = "the model") -> tuple[Settings, dict[str, str]]:
    """``settings`` with the :data:`MODEL_SECTIONS` taken from a model's stored settings.

    Every key of those sections that the user did not set (``explicit``: dotted keys given
    in a configuration file or by a command-line option, e.g. ``"measurement.polarity"``)
    takes the model's value; keys the user set keep the user's value.

    Returns ``(settings, sources)``, ``sources`` mapping each section to a one-line
    description of where its values came from (for logs).
    """
    explicit = set(explicit)
    stored = to_dict(model_settings)
    overrides: dict[str, Any] = {}
    sources: dict[str, str] = {}
    for section in MODEL_SECTIONS:
        keys = list(stored[section])
        mine = [k for k in keys if f"{section}.{k}" in explicit or section in explicit]
        for k in keys:
            if k not in mine:
                overrides[f"{section}.{k}"] = stored[section][k]
        if not mine:
            sources[section] = f"from {where} (the settings it was learned with)"
        elif len(mine) == len(keys):
            sources[section] = "from the configuration / options (they set every key)"
        else:
            sources[section] = (f"from {where}, except {', '.join(mine)} from the configuration / options")
    return replace(settings, overrides), sources


def place_space(space: ShapeSpace, template: Template) -> tuple[ShapeSpace, np.ndarray]:
    """Re-anchor a learned shape-space on a template drawn in another clip.

    The new space keeps the model's deformation columns and template shape, translated so
    that its centroid lands on the new template's centroid.  The initial shape ``X0`` puts
    the model's template there at the size of the new template (the square root of the
    ratio of their areas, :func:`placement_scale`) where the space has a scale direction
    (similarity, affine).

    Only position and size are taken from the new template (so a closed one may have other
    control points than the model's, as ``draw`` gives each outline as many as it needs): a template outlined
    automatically in clutter is often too ragged to say more (its rotation, for instance),
    and the tracker itself refines the shape from the first frame on.

    Returns ``(space, X0)``.
    """
    # a closed template gives only its centroid and area, whatever its control points; an open
    # one gives the mean of its control points, which must be the model's kind to compare
    if template.closed != space.basis.closed or (not template.closed and (
            template.n_ctrl != space.Nq or template.degree != space.basis.degree)):
        raise ModelError(
            f"the template has {template.n_ctrl} control points (degree {template.degree}, "
            f"{'closed' if template.closed else 'open'}) but the model's curve has {space.Nq} "
            f"(degree {space.basis.degree}, {'closed' if space.basis.closed else 'open'}); "
            "draw the template with the same --n-ctrl")
    from trackcli.shapes.spline import curve_area_centroid

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


def placement_scale(space: ShapeSpace, X0: np.ndarray | None) -> float:
    """The size of a placed object relative to the model's template: ``s`` with
    ``X0 = (s − 1) e`` for the :func:`scale_direction` ``e``; 1 when the space has no
    scale direction, when ``X0`` is None, or when ``X0`` is not a pure scaling."""
    if X0 is None:
        return 1.0
    e = scale_direction(space)
    if e is None:
        return 1.0
    X0 = np.asarray(X0, dtype=float)
    k = float(e @ space.H @ X0) / float(e @ space.H @ e)
    if not np.allclose(k * e, X0, atol=1e-9 * max(1.0, float(np.abs(X0).max()))) or 1.0 + k <= 0:
        return 1.0
    return 1.0 + k


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


#: How a placed model keeps the learned coupling between translation and the rest of
#: shape-space (see :func:`place_dynamics`).
COUPLINGS = ("keep", "velocity", "none")


@dataclass(frozen=True)
class Placement:
    """What :func:`place_dynamics` did, for logs and ``trackcli inspect``.

    Attributes
    ----------
    scale : float
        Size of the placed object relative to the model's template (1: as learned).
    coupling : str
        One of :data:`COUPLINGS`.
    learned_radius, radius : float
        Spectral radius of the learned and of the placed model.
    restabilised : bool
        The placed model's modes above ``limit`` were pulled in to it.
    limit : float
        The largest spectral radius a placed model may have: the learned one, or
        ``max_spectral_radius`` if that is larger.
    """

    scale: float
    coupling: str
    learned_radius: float
    radius: float
    restabilised: bool
    limit: float


def remove_position_coupling(A2: np.ndarray, A1: np.ndarray, Es: np.ndarray, Ed: np.ndarray) -> np.ndarray:
    """``A1`` without the position terms between translation and the rest of shape-space.

    The part of AR(2) dynamics coupling two blocks reads, per frame,
    ``A2 X_{k-2} + A1 X_{k-1} = (A1 + A2) X_{k-1} − A2 (X_{k-1} − X_{k-2})``: a *position*
    term ``P = A1 + A2`` (how far the other block stands from its mean) and a *velocity*
    term ``−A2`` (how fast it moves).  Setting the cross blocks of ``P`` to zero, by
    ``A1 ↦ A1 − (Ed P Es + Es P Ed)``, keeps the velocity coupling (e.g. an object that
    turns as it moves) and drops the static link between where the object stood in the
    training frame and its shape (or the reverse).  ``A2`` is unchanged.
    """
    P = A1 + A2
    return A1 - (Ed @ P @ Es + Es @ P @ Ed)


def place_dynamics(
    dynamics: AR2,
    space: ShapeSpace,
    X0: np.ndarray | None,
    tau: float,
    *,
    translation_noise: float = 1.0,
    deformation_noise: float = 1.0,
    coupling: str = "keep",
    max_spectral_radius: float = 0.995,
    report: list[Placement] | None = None,
) -> AR2:
    """A learned model's dynamics, adapted for tracking a clip.

    The model is kept in coordinates relative to its mean (AC eq 9.15), so that moving the
    mean needs no change to ``A1``, ``A2``.  Placing it does three things:

    1. **The mean moves with the object.**  The translation mean goes to the translation
       of ``X0`` (where the object is placed); the rest of the learned mean shape is taken
       at the object's size on the new clip, ``s`` (:func:`placement_scale`; ``X0 = (s − 1)
       e`` scales the template about its centroid).  In a space with a scale direction the
       learned mean ``d̄`` becomes ``s d̄ + (s − 1) e``, the learned mean outline scaled by
       ``s``; in others the offset ``X0`` is added to it.  With ``X0 = None`` the mean
       stays as learned.
    2. **Deviations from the mean are rescaled, not reshaped**: ``δ ↦ G δ`` with
       ``G = s (t Es + d Ed)``, the projectors ``Es``, ``Ed`` of
       :func:`translation_split`, ``t = translation_noise`` and ``d = deformation_noise``.
       That is a change of units of the process, so ``A ↦ G A G⁻¹`` has the learned
       eigenvalues — damping, frequencies and mode shapes (up to the units) are kept
       exactly — while excursions, speeds and noise (``C ↦ G C Gᵀ``) grow by ``s t`` in
       translation and ``s d`` in the rest: the object moves in proportion to its size,
       and the factors say how much more agile the new clip is than the training one.
    3. **The coupling between translation and the rest** is kept as learned by default
       (``coupling="keep"``): the modes of the placed model are then exactly those learned.
       ``coupling="velocity"`` drops the learned link between *where* the object stood in
       the training frame and its shape (:func:`remove_position_coupling`) and keeps the
       velocity coupling; ``coupling="none"`` keeps only the blocks within translation and
       within the rest (``A ↦ Es A Es + Ed A Ed``, the partitioned structure of AC eq
       9.30).  Both change the eigenvalues: on models learned from the sample clips, by up
       to 0.2 Hz in frequency, and cutting every coupling can make a stable model unstable.

    Cutting couplings can push a mode outwards.  The placed model is never allowed a
    spectral radius above ``limit = max(learned radius, max_spectral_radius)``: modes
    beyond it are pulled in to it, keeping their frequencies and mode shapes (as learning
    does, :func:`trackcli.dynamics.learning.stabilise`), and a warning gives the numbers.

    The frame interval ``tau`` (s) of the clip is compared with the model's and only
    warned about: learned dynamics are used per frame as learned.

    Parameters
    ----------
    dynamics : AR2
        As learned (``trackcli learn``).
    space : ShapeSpace
        The model's shape-space (before or after :func:`place_space`: the split is the same).
    X0 : ndarray of shape (Nx,) or None
        Initial shape on the new clip (from :func:`place_space`).
    tau : float
        Frame interval of the new clip, seconds.
    translation_noise, deformation_noise : float
        Factors on the motion (> 0; 1 keeps it as learned).
    coupling : {"velocity", "keep", "none"}
        What is kept of the coupling between translation and the rest (see 3.).
    max_spectral_radius : float
        In (0, 1): see above.
    report : list, optional
        If given, a :class:`Placement` describing what was done is appended.

    Returns
    -------
    AR2

    Raises
    ------
    ConfigError
        A factor is not a number > 0, or ``coupling`` is unknown.
    ModelError
        The dynamics and the shape-space have different dimensions.
    """
    from trackcli.dynamics.learning import stabilise

    for name, value in (("translation_noise", translation_noise), ("deformation_noise", deformation_noise)):
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(f"placement.{name}: expected a number > 0, got {value!r}")
    if coupling not in COUPLINGS:
        raise ConfigError(f"placement.coupling: expected one of {', '.join(COUPLINGS)}, got {coupling!r}")
    if dynamics.nx != space.Nx:
        raise ModelError(f"the dynamics have {dynamics.nx} components but the shape-space has {space.Nx}")
    if not math.isclose(dynamics.tau, tau, rel_tol=1e-3):
        log.warning("the model was learned at %.3g frames/s but this clip runs at %.3g frames/s; "
                    "its dynamics are used per frame as learned", 1 / dynamics.tau, 1 / tau)
    Es, Ed = translation_split(space)
    A2, A1 = dynamics.A2, dynamics.A1
    if coupling == "velocity":
        A1 = remove_position_coupling(A2, A1, Es, Ed)
    elif coupling == "none":
        A2, A1 = Es @ A2 @ Es + Ed @ A2 @ Ed, Es @ A1 @ Es + Ed @ A1 @ Ed
    learned_radius = dynamics.spectral_radius()
    limit = max(learned_radius, float(max_spectral_radius))
    cut = AR2(A2, A1, dynamics.B0, dynamics.mean, dynamics.tau).spectral_radius()
    A2, A1, how = stabilise(A2, A1, limit)
    if how != "no":
        log.warning("placing the model (coupling: %s) moved its spectral radius from %.4f to %.4f; "
                    "its modes beyond %.4f were pulled in to it (%s), keeping their frequencies",
                    coupling, learned_radius, cut, limit, "one by one" if how == "modes" else "all scaled")
    s = placement_scale(space, X0)
    G = s * (translation_noise * Es + deformation_noise * Ed)
    G_inv = (Es / translation_noise + Ed / deformation_noise) / s
    if X0 is None:
        mean = dynamics.mean
    else:
        mean = s * (Ed @ dynamics.mean) + np.asarray(X0, dtype=float)
    placed = AR2(G @ A2 @ G_inv, G @ A1 @ G_inv, G @ dynamics.B0, mean, dynamics.tau)
    if report is not None:
        report.append(Placement(scale=s, coupling=coupling, learned_radius=learned_radius,
                                radius=placed.spectral_radius(), restabilised=how != "no", limit=limit))
    return placed
