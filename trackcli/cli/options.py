"""The options several commands share, each declared once.

Every decorator here declares an option's names, type and default in one place; where the
option means something different to each command (what ``-o`` writes, what ``--json``
prints), the command passes its own ``help`` text.  Nothing here imports more than Click,
so ``trackcli --help`` stays instant.
"""

from __future__ import annotations

from typing import Any, Callable

import click

Decorator = Callable[[Callable[..., Any]], Callable[..., Any]]

CONFIG_HELP = "Configuration file (YAML) or preset name (`trackcli config list`)."
SEED_HELP = "Random seed (same seed, same numbers)."


def config_option(help: str = CONFIG_HELP) -> Decorator:
    """``-c/--config CONFIG``: a configuration file or preset (``config``)."""
    return click.option("-c", "--config", type=click.Path(dir_okay=False), help=help)


def json_option(help: str) -> Decorator:
    """``--json``: machine-readable results on stdout (``as_json``)."""
    return click.option("--json", "as_json", is_flag=True, help=help)


def output_option(help: str, *, required: bool = False, folder: bool = False) -> Decorator:
    """``-o/--output PATH``: the file (or, with ``folder``, file or folder) a command writes (``output``)."""
    return click.option("-o", "--output", type=click.Path() if folder else click.Path(dir_okay=False),
                        required=required, help=help)


def outdir_option(help: str = "Folder for the outputs.", *, short: bool = True,
                  default: str | None = "trackcli-out") -> Decorator:
    """``-o/--outdir FOLDER`` (``--outdir`` alone with ``short=False``): where outputs go (``outdir``)."""
    names = ("-o", "--outdir") if short else ("--outdir",)
    return click.option(*names, type=click.Path(file_okay=False), default=default,
                        show_default=default is not None, help=help)


def template_option(help: str, *, required: bool = False) -> Decorator:
    """``--template T``: a template file written by ``trackcli draw`` (``template``)."""
    return click.option("--template", type=click.Path(dir_okay=False), required=required, help=help)


def seed_option(help: str = SEED_HELP, *, default: int | None = None) -> Decorator:
    """``--seed N``: the random seed, a whole number >= 0 (``seed``)."""
    return click.option("--seed", type=click.IntRange(min=0), default=default, show_default=default is not None,
                        help=help)


def fps_option(help: str) -> Decorator:
    """``--fps RATE``: a frame rate, > 0 (``fps``)."""
    return click.option("--fps", type=click.FloatRange(min=0, min_open=True), help=help)


def no_rrd_option(help: str) -> Decorator:
    """``--no-rrd``: write no Rerun recordings (``no_rrd``)."""
    return click.option("--no-rrd", is_flag=True, help=help)


def object_option(help: str) -> Decorator:
    """``--object ID``: which object of a truth CSV with several (``object_id``)."""
    return click.option("--object", "object_id", type=click.IntRange(min=0), default=0, show_default=True, help=help)


def frames_option(help: str, *, default: int | None = None, most: int | None = None) -> Decorator:
    """``--frames N``: a number of frames, at least 2 (``n_frames``)."""
    return click.option("--frames", "n_frames", type=click.IntRange(min=2, max=most), default=default,
                        show_default=default is not None, help=help)


def model_argument() -> Decorator:
    """The ``MODEL`` argument: a model file written by ``trackcli learn`` (``model_path``)."""
    return click.argument("model_path", metavar="MODEL", type=click.Path(dir_okay=False))


def quiet_option(help: str) -> Decorator:
    """``-q/--quiet`` (also given before the command: ``trackcli -q ...``)."""
    return click.option("-q", "--quiet", is_flag=True, help=help)


def export_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--masks DIR``, ``--palette``, ``--vot FILE``: each frame's outline as a mask PNG, and as a
    VOT region line (``masks``, ``palette``, ``vot``)."""
    for opt in reversed([
        click.option("--masks", type=click.Path(file_okay=False),
                     help="Write the filled outline of every frame as a mask PNG into this folder, named as the "
                          "frames (DAVIS style: 0 background, 255 object)."),
        click.option("--palette", is_flag=True,
                     help="With --masks: 8-bit palette PNGs, the object at index 1 (DAVIS-2017 style)."),
        click.option("--vot", type=click.Path(dir_okay=False),
                     help="Write VOT region lines to this file: one polygon 'x1,y1,x2,y2,...' per frame "
                          "('0' where there is no outline)."),
    ]):
        f = opt(f)
    return f


def video_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--fps``, ``--start``, ``--end``, ``--step``: which frames of a clip are read."""
    for opt in reversed([
        fps_option("Frame rate of image folders (they carry none); for a video file it replaces the rate "
                   "the file reports."),
        click.option("--start", type=click.IntRange(min=0), help="First frame (inclusive)."),
        click.option("--end", type=click.IntRange(min=1), help="Last frame (exclusive)."),
        click.option("--step", type=click.IntRange(min=1), help="Use every STEP-th frame."),
    ]):
        f = opt(f)
    return f


def video_overrides(fps: float | None, start: int | None, end: int | None, step: int | None) -> dict[str, Any]:
    """The settings :func:`video_options` override (``None``: not given)."""
    return {"video.fps": fps, "video.start": start, "video.end": end, "video.step": step}
