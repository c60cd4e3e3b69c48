"""Hand-set dynamics: the motion model a template gets before any learning (AC §9.6)."""

from __future__ import annotations

import numpy as np

from trackcli.dynamics.ar2 import AR2, SubspaceModel, partitioned
from trackcli.errors import ConfigError
from trackcli.settings import DynamicsSettings, SubspaceDynamics
from trackcli.shapes.outline import object_size
from trackcli.shapes.shape_space import ShapeSpace


def _subspace_part(E: np.ndarray, s: SubspaceDynamics, tau: float, what: str, unit: float) -> SubspaceModel:
    rho = None if s.rho is None else s.rho * unit
    gamma0 = None if s.gamma0 is None else s.gamma0 * unit
    try:
        return SubspaceModel.oscillator(E, s.f, s.beta, rho, tau, gamma0=gamma0)
    except ConfigError as exc:
        raise ConfigError(f"dynamics.{what}: {exc}") from None


def handset_dynamics(space: ShapeSpace, settings: DynamicsSettings, tau: float) -> AR2:
    """Partitioned damped-oscillator dynamics (AC §9.6, eq 9.30) on translation and the rest.

    The translation subspace gets ``settings.translation``; its H-orthogonal complement
    (rotation, scale and other deformation) gets ``settings.deformation``.  The mean shape is
    the template (``X̄ = 0``), so a damped deformation returns to the template's shape and
    size: scale and rotation cannot drift without bound.

    With ``settings.units = "object"`` the steady-state RMS displacements ``rho`` (and
    ``gamma0``) are in units of the template's size (:func:`~trackcli.shapes.outline.object_size`),
    so the same settings describe a small and a large object alike; the damping ``beta`` (1/s)
    and frequency ``f`` (Hz) are converted per frame with the clip's frame interval ``tau``.
    """
    unit = object_size(space) if settings.units == "object" else 1.0
    Es = space.translation_projector()
    parts = [_subspace_part(Es, settings.translation, tau, "translation", unit)]
    if space.Nx > 2:
        parts.append(_subspace_part(np.eye(space.Nx) - Es, settings.deformation, tau, "deformation", unit))
    return partitioned(space.H, parts, np.zeros(space.Nx), tau)
