"""``trackcli inspect``: what a model holds, as JSON and as text.

:func:`inspect_model` describes a model learned by ``trackcli learn``: its shape-space, its
AR(2) dynamics (A1, A2, B0), their modes (AC eqs 11.10-11.13) and steady-state spread,
optionally as placed by a template on the clip where it was drawn
(:func:`trackcli.dynamics.model.place_dynamics`).  A mixed-state model is described label
by label, with its transition matrix, the mean stay in each label and the initial
distribution.  Both return a :class:`ModelReport`: ``info`` for ``--json``, ``lines`` for
the text.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence


@dataclass(frozen=True)
class ModelReport:
    """A model described: the JSON object of ``inspect --json`` and the lines of ``inspect``."""

    info: dict[str, Any]
    lines: list[str]


def mode_dict(m: Any, H: Any = None) -> dict[str, Any]:
    """One mode of :meth:`trackcli.dynamics.ar2.AR2.modes` as JSON (its dominant components by ``H``)."""
    return {"eigenvalue_modulus": m.modulus, "damping_per_s": m.beta, "frequency_hz": m.frequency,
            "decay_time_s": m.decay_time, "period_s": m.period, "stable": m.stable,
            "dominant": [[int(i), float(w)] for i, w in m.dominant(3, H)]}


def mode_rows(modes: Sequence[Any], space: Any) -> list[str]:
    """The table of ``modes`` (AR2.modes()) that ``inspect`` prints, a line each, header first."""
    import numpy as np

    names = list(space.names)
    rows = ["    |lambda|  damping(1/s)  freq(Hz)  decay(s)  period(s)  dominant components"]
    for x in modes:
        dom = ", ".join(f"{names[i]} {w:.2f}" for i, w in x.dominant(3, space.H))
        per = f"{x.period:9.3f}" if np.isfinite(x.period) else "        -"
        dec = f"{x.decay_time:8.3f}" if np.isfinite(x.decay_time) else "     inf"
        rows.append(f"    {x.modulus:8.4f}  {x.beta:12.3f}  {x.frequency:8.3f}  {dec}  {per}  {dom}"
                    + ("" if x.stable else "  no decay" if x.modulus == 1.0 else "  UNSTABLE"))
    return rows


def inspect_model(model_path: str, template: str | None = None, config: str | None = None,
                  fps: float | None = None) -> ModelReport:
    """Describe the model at ``model_path`` (a mixed-state model too, :func:`inspect_mixed`).

    With ``template``: the model placed where (and at the size) it was drawn, with the
    placement settings of ``config`` (default: the defaults) and the frame rate ``fps``
    (default: the model's).
    """
    import numpy as np

    from trackcli.dynamics.mixed import is_mixed_file
    from trackcli.dynamics.model import load_model, place_dynamics, place_space
    from trackcli.run.options import settings_from
    from trackcli.shapes.template import load_template

    if is_mixed_file(model_path):
        return inspect_mixed(model_path, template, config, fps)
    m = load_model(model_path)
    dyn, space = m.dynamics, m.space
    placement = None
    if template:
        tmpl = load_template(template)
        settings = settings_from(config, {})
        space, X0 = place_space(m.space, tmpl)
        report: list = []
        tau = 1.0 / fps if fps else m.dynamics.tau
        p = settings.placement
        dyn = place_dynamics(m.dynamics, space, X0, tau, translation_noise=p.translation_noise,
                             deformation_noise=p.deformation_noise, coupling=p.coupling,
                             max_spectral_radius=settings.learning.max_spectral_radius, report=report)
        r = report[0]
        placement = {"template": str(template), "scale": r.scale, "coupling": r.coupling,
                     "translation_noise": p.translation_noise, "deformation_noise": p.deformation_noise,
                     "learned_spectral_radius": r.learned_radius, "spectral_radius": r.radius,
                     "restabilised": r.restabilised, "limit": r.limit,
                     "centroid": [float(v) for v in space.origin]}
    try:
        rms = dyn.rms_displacement(space.H)
        Es = space.translation_projector()
        rms_t = dyn.rms_displacement(space.H, Es)
        rms_d = dyn.rms_displacement(space.H, np.eye(space.Nx) - Es)
    except Exception:  # unstable or constant-velocity models have no steady state
        rms = rms_t = rms_d = None
    modes = dyn.modes()
    names = list(space.names)
    info = {
        "model": str(model_path),
        "shape_space": {"kind": space.kind, "components": names, "control_points": space.Nq,
                        "degree": space.basis.degree, "closed": space.basis.closed},
        "frame_interval_s": dyn.tau,
        "spectral_radius": dyn.spectral_radius(),
        "stable": dyn.is_stable(),
        "mean": dict(zip(names, map(float, dyn.mean))),
        "steady_state_rms_px": {"total": rms, "translation": rms_t, "deformation": rms_d},
        "A1": dyn.A1.tolist(), "A2": dyn.A2.tolist(), "B0": dyn.B0.tolist(),
        "modes": [mode_dict(x, space.H) for x in modes],
        "provenance": m.provenance,
    }
    if placement is not None:
        info["placement"] = placement

    def fmt(v: float | None) -> str:
        return "n/a" if v is None else f"{v:.2f}"

    lines = [f"model {model_path}" + (f", placed by template {template}" if placement else "")]
    if placement is not None:
        lines.append(f"  placement     centroid ({placement['centroid'][0]:.1f}, {placement['centroid'][1]:.1f}) px, "
                     f"size {placement['scale']:.3f} x the model's template, coupling {placement['coupling']}, "
                     f"noise factors {placement['translation_noise']:g} (translation), "
                     f"{placement['deformation_noise']:g} (rest)")
        lines.append(f"                spectral radius {placement['learned_spectral_radius']:.4f} learned -> "
                     f"{placement['spectral_radius']:.4f} placed"
                     + (f" (re-stabilised: modes pulled in to {placement['limit']:.4f})"
                        if placement["restabilised"] else ""))
    lines += [f"  shape-space   {space.kind}: {', '.join(names)} ({space.Nq} control points, degree "
              f"{space.basis.degree}, {'closed' if space.basis.closed else 'open'})",
              f"  frame interval {dyn.tau:.4g} s ({1 / dyn.tau:.3g} frames/s)",
              f"  stability     spectral radius {dyn.spectral_radius():.4f} ({dyn.stability()})",
              f"  steady-state RMS displacement: total {fmt(rms)} px, translation {fmt(rms_t)} px, "
              f"deformation {fmt(rms_d)} px",
              "  mean X         " + ", ".join(f"{n}={v:.4g}" for n, v in zip(names, dyn.mean)),
              "  modes (slowest first):", *mode_rows(modes, space)]
    prov = m.provenance
    if prov:
        src = prov.get("clips") or prov.get("tracks") or []
        lines.append(f"  learned from  {', '.join(map(str, src))} ({prov.get('cycles', 0)} cycle(s))")
    return ModelReport(info, lines)


def mixed_dynamics_for(mm: Any, template: str | None, config: str | None, fps: float | None) -> tuple[Any, Any]:
    """The mixed model's labels on a shape-space (the template's, or the model's own), or
    ``(None, None)`` for a hand-written model without a template."""
    from trackcli.run.clips import mixed_dynamics_on
    from trackcli.run.options import settings_from
    from trackcli.shapes.template import load_template

    if not template and mm.space is None:
        return None, None
    tmpl = load_template(template) if template else None
    learned = [lab.ar2.tau for lab in mm.labels if lab.ar2 is not None]
    rate = fps or (1.0 / learned[0] if learned else _clip_fps(tmpl.clip if tmpl is not None else None) or 25.0)
    space, dynamics, _ = mixed_dynamics_on(mm, tmpl, template, settings_from(config, {}), 1.0 / rate)
    return dynamics, space


def _clip_fps(clip: str | None) -> float | None:
    """The frame rate of the clip a template was drawn on, when it can be opened here."""
    from trackcli.io.video import open_video

    if not clip:
        return None
    try:
        with open_video(clip) as v:
            return float(v.fps)
    except Exception:  # the clip moved or is not readable here: the caller falls back
        return None


def inspect_mixed(model_path: str, template: str | None, config: str | None, fps: float | None) -> ModelReport:
    """A mixed-state model described: every label's model (and modes), T, the label durations."""
    import numpy as np

    from trackcli.dynamics.ar2 import AR2
    from trackcli.dynamics.mixed import load_mixed

    mm = load_mixed(model_path)
    dyn, space = mixed_dynamics_for(mm, template, config, fps)
    T = mm.T
    stay = np.diag(T)
    durations = [None if s >= 1 else float(1.0 / (1.0 - s)) for s in stay]
    labels = []
    for i, lab in enumerate(mm.labels):
        d: dict = {"name": lab.name, "kind": lab.kind, "mean_duration_frames": durations[i]}
        if lab.bounce is not None:
            d["bounce"] = lab.bounce.to_dict()
            if dyn is not None:
                d["bounce"]["contact_px"] = float(dyn.models[i].contact)
        elif lab.handset is not None:
            d["dynamics"] = lab.handset_raw
        if dyn is not None and isinstance(dyn.models[i], AR2):
            ar = dyn.models[i]
            d["spectral_radius"] = ar.spectral_radius()
            d["modes"] = [mode_dict(x, space.H) for x in ar.modes()]
        labels.append(d)
    info = {"model": str(model_path), "kind": "mixed-state", "labels": labels, "transitions": T.tolist(),
            "initial": mm.initial_distribution().tolist(),
            "initial_source": "given" if mm.initial is not None else "stationary distribution of T",
            "provenance": mm.provenance}
    if space is not None:
        info["shape_space"] = {"kind": space.kind, "components": list(space.names)}
        info["frame_interval_s"] = dyn.tau
    names = mm.names
    lines = [f"mixed-state model {model_path}: {len(names)} labels ({', '.join(names)})"
             + (f", on template {template}" if template else "")]
    if space is not None:
        lines.append(f"  shape-space   {space.kind}: {', '.join(space.names)}; frame interval {dyn.tau:.4g} s")
    width = max(len(n) for n in names)
    lines.append("  transitions T[i, j] = P(next label j | label i):")
    lines.append("    " + " " * width + "  " + "  ".join(f"{n:>{max(width, 6)}}" for n in names))
    for n, row in zip(names, T):
        lines.append(f"    {n:>{width}}  " + "  ".join(f"{v:>{max(width, 6)}.4f}" for v in row))
    init = mm.initial_distribution()
    lines.append("  initial       " + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, init))
                 + ("" if mm.initial is not None else " (stationary distribution of T)"))
    for i, lab in enumerate(mm.labels):
        dur = "stays for good" if durations[i] is None else f"mean stay {durations[i]:.3g} frame(s)"
        lines.append(f"  label {lab.name} ({lab.kind}; {dur})")
        if lab.bounce is not None:
            b = lab.bounce
            line = (f"floor y = {b.point[1]:g} px" if b.normal == (0.0, -1.0)
                    else f"line through ({b.point[0]:g}, {b.point[1]:g}) with normal ({b.normal[0]:.3g}, "
                         f"{b.normal[1]:.3g})")
            contact = f", outline reaches {dyn.models[i].contact:.1f} px from its centre towards it" if dyn else ""
            lines.append(f"    bounce on the {line}{contact}; restitution {b.restitution:g}, friction {b.friction:g}, "
                         f"rebound noise {b.noise:g} x the impact speed; other components move as {b.base}")
            continue
        if lab.handset is not None:
            lines.append(f"    hand-set: {lab.handset_raw}")
        if dyn is None:
            lines.append("    (give --template to see its modes on a template's shape-space)")
            continue
        ar = dyn.models[i]
        lines.append(f"    spectral radius {ar.spectral_radius():.4f}; modes (slowest first):")
        lines += ["  " + row for row in mode_rows(ar.modes(), space)]
    return ModelReport(info, lines)
