"""``trackcli simulate``: random sample paths of a model (AC Fig 11.7), as a PNG and a recording.

:func:`simulate_model` draws the paths of a learned model
(:func:`trackcli.dynamics.simulate.simulate_paths`) or of a mixed-state model, whose paths
switch label as its transition matrix says, and writes the PNG of the trajectories and
the recording that animates them, both or neither.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Simulated:
    """What :func:`simulate_model` wrote, and a line about the paths."""

    output: Path
    png: Path
    summary: str


def default_output(model_path: str) -> Path:
    """``MODEL_sim.rrd`` beside the model."""
    return Path(model_path).with_name(Path(model_path).stem + "_sim.rrd")


def canvas_size(size: str | None) -> tuple[int, int] | None:
    """``--size 'W,H'`` of simulate's PNG, checked (None: the template's frame size)."""
    if not size:
        return None
    from trackcli.errors import ConfigError
    from trackcli.shapes.draw import parse_numbers

    w, h = parse_numbers(size, 2, "--size")
    if not all(float(v).is_integer() and 16 <= v <= 16384 for v in (w, h)):
        raise ConfigError(f"--size: expected a width and height in whole pixels from 16 to 16384, got {size!r}")
    return int(w), int(h)


def simulate_model(model_path: str, *, n_frames: int = 250, n_paths: int = 3, seed: int = 0,
                   output: str | None = None, size: str | None = None, template: str | None = None,
                   fps: float | None = None) -> Simulated:
    """Draw ``n_paths`` paths of ``n_frames`` frames from the model at ``model_path`` with
    ``np.random.default_rng(seed)`` and write the recording ``output`` (default
    :func:`default_output`) and the PNG beside it, on a canvas of ``size`` ('W,H'; default
    the template's frame size).

    ``template`` and ``fps`` are for a mixed-state model only: the template whose
    shape-space its labels move (a hand-written model has none of its own) and the frame rate
    its hand-set labels are built for.  Raises :class:`~trackcli.run.options.OptionError`
    when they are given for another model, or when a hand-written one has no template.
    """
    import numpy as np

    from trackcli.dynamics.mixed import is_mixed_file
    from trackcli.dynamics.model import load_model
    from trackcli.dynamics.simulate import record_paths, render_paths, simulate_paths
    from trackcli.io.outputs import atomic_paths, output_dir, refuse_overwriting_inputs
    from trackcli.run.options import OptionError

    out = Path(output) if output else default_output(model_path)
    refuse_overwriting_inputs({"-o/--output": out, "the PNG": out.with_suffix(".png")}, {"MODEL": model_path})
    if is_mixed_file(model_path):
        return _simulate_mixed(model_path, template, fps, n_frames, n_paths, seed, out, size)
    if template or fps:
        raise OptionError("--template and --fps apply to mixed-state models only")
    m = load_model(model_path)
    canvas = canvas_size(size)
    paths = simulate_paths(m, n_frames, n_paths, np.random.default_rng(seed))
    png = out.with_suffix(".png")
    with output_dir(out.parent), atomic_paths(png, out) as (png_tmp, out_tmp):  # both outputs or none
        render_paths(m, paths, png_tmp, canvas=canvas)
        record_paths(m, paths, out_tmp, seed=seed)
    return Simulated(out, png, f"{n_paths} paths of {n_frames} frames")


def _simulate_mixed(model_path: str, template: str | None, fps: float | None, n_frames: int, n_paths: int,
                    seed: int, out: Path, size: str | None) -> Simulated:
    from types import SimpleNamespace

    import numpy as np

    from trackcli.dynamics.mixed import load_mixed
    from trackcli.dynamics.simulate import record_paths, render_paths
    from trackcli.io.outputs import atomic_paths, output_dir
    from trackcli.run.model_report import mixed_dynamics_for
    from trackcli.run.options import OptionError
    from trackcli.shapes.template import load_template

    mm = load_mixed(model_path)
    dyn, space = mixed_dynamics_for(mm, template, None, fps)
    if dyn is None:
        raise OptionError(f"{model_path} is a hand-written mixed-state model: give --template")
    tmpl = load_template(template) if template else mm.template
    canvas = canvas_size(size)
    rng = np.random.default_rng(seed)
    sims = [dyn.simulate(n_frames, rng) for _ in range(n_paths)]
    paths = np.stack([p for p, _ in sims])
    labels = np.stack([lab for _, lab in sims])
    events = [i for i, lab in enumerate(mm.labels) if lab.bounce is not None]
    marks = [np.flatnonzero(np.isin(lab, events)) for lab in labels]
    view = SimpleNamespace(space=space, template=tmpl, dynamics=SimpleNamespace(tau=dyn.tau),
                           provenance={"mixed_state_model": str(model_path), "labels": mm.names, **mm.provenance})
    png = out.with_suffix(".png")
    with output_dir(out.parent), atomic_paths(png, out) as (png_tmp, out_tmp):  # both outputs or none
        render_paths(view, paths, png_tmp, canvas=canvas, marks=marks)
        record_paths(view, paths, out_tmp, seed=seed, labels=labels, label_names=mm.names)
    switches = int(sum((np.diff(lab) != 0).sum() for lab in labels))
    visits = ", ".join(f"{n} {float((labels == i).mean()):.0%}" for i, n in enumerate(mm.names))
    return Simulated(out, png, f"{n_paths} paths of {n_frames} frames; {switches} label switches; "
                               f"frames by label: {visits}")
