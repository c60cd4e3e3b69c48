"""The ``trackcli`` command line.

Commands are thin: they parse options, resolve inputs and outputs, call the library and
write results.  Every :class:`~trackcli.errors.TrackcliError` becomes a one-line message on
stderr and the exit code of its class; progress bars and logs go to stderr, results to
stdout or files.
"""

from __future__ import annotations

import logging
import sys

import click

from . import __version__
from .errors import TrackcliError

log = logging.getLogger("trackcli")


class TrackcliGroup(click.Group):
    """Click group that turns library errors into one-line messages and exit codes."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except TrackcliError as exc:
            click.echo(f"Error: {exc}", err=True)
            ctx.exit(exc.exit_code)
        except KeyboardInterrupt:
            click.echo("Interrupted.", err=True)
            ctx.exit(130)


@click.group(cls=TrackcliGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="trackcli")
@click.option("-v", "--verbose", count=True, help="More log output (repeat for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr; no progress bars.")
@click.pass_context
def cli(ctx: click.Context, verbose: int, quiet: bool) -> None:
    """Follow the outline of an object through video, even in dense clutter.

    \b
    The pipeline (Blake & Isard):
      draw    make a B-spline template around the object in one frame
      learn   track training clips with a Kalman contour tracker and learn AR(2) dynamics
      track   follow the object in test footage with CONDENSATION (or Kalman)
      eval    score estimates against ground truth

    Every run writes a Rerun recording (.rrd) and CSV files of the estimates.
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr)
    ctx.ensure_object(dict)
    ctx.obj["quiet"] = quiet


# ---------------------------------------------------------------------------------------------
# config


@cli.group("config")
def config_group() -> None:
    """Show, explain and check configuration files."""


@config_group.command("show")
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--comments", is_flag=True, help="Explain every setting in a comment.")
def config_show(file: str | None, comments: bool) -> None:
    """Print the effective configuration: the defaults, overridden by FILE if given.

    The output is itself a valid configuration file:
    `trackcli config show --comments > my.yaml` starts a new one.
    """
    from .config import dump_yaml, load_settings, render_commented

    settings = load_settings(file)
    click.echo(render_commented(settings) if comments else dump_yaml(settings), nl=False)


@config_group.command("check")
@click.argument("file", type=click.Path(dir_okay=False))
def config_check(file: str) -> None:
    """Validate FILE; exit 0 if it is valid, 3 with the reason if not."""
    from .config import load_settings

    load_settings(file)
    click.echo(f"{file}: OK")


# ---------------------------------------------------------------------------------------------
# draw


@cli.command("draw")
@click.argument("clip", type=click.Path())
@click.option("--frame", "frame_index", type=click.IntRange(min=0), default=0, show_default=True,
              help="Frame of CLIP to draw on.")
@click.option("--points", help="Ordered outline points 'x1,y1 x2,y2 ...', or a file with one 'x,y' per line.")
@click.option("--ellipse", help="Ellipse 'cx,cy,a,b[,angle]': centre, semi-axes (px), angle (degrees).")
@click.option("--box", help="Box 'x,y,w,h' around the object: segmented automatically (GrabCut).")
@click.option("--mask", type=click.Path(), help="Binary mask image (non-zero = object), same size as the frame.")
@click.option("--n-ctrl", type=click.IntRange(min=3, max=200), default=12, show_default=True,
              help="Number of spline control points.")
@click.option("--degree", type=click.IntRange(min=1, max=5), default=2, show_default=True,
              help="Spline degree (2 = quadratic).")
@click.option("--open", "open_curve", is_flag=True, help="Open curve (default closed); only with --points.")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), help="Frame rate of an image folder.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True, help="Template file to write (.yaml).")
@click.option("--preview", type=click.Path(dir_okay=False),
              help="Preview PNG (default: beside the template, same name with .png).")
@click.option("--rrd", type=click.Path(dir_okay=False), help="Also write a Rerun recording of the template.")
@click.option("--n-normals", type=click.IntRange(min=3, max=1000), default=24, show_default=True,
              help="Measurement normals shown in the preview.")
def draw_cmd(clip, frame_index, points, ellipse, box, mask, n_ctrl, degree, open_curve, fps, output, preview, rrd, n_normals):
    """Make a template: a B-spline outline of the object in one frame of CLIP.

    Give exactly one of --points, --ellipse, --box or --mask.  Writes the template (YAML),
    a PNG preview (curve in green, control polygon in blue, measurement normals in yellow)
    and, with --rrd, a recording.

    \b
    Examples:
      trackcli draw sample_data/train.mp4 --box 200,90,90,150 -o head.yaml
      trackcli draw clip.mp4 --frame 10 --ellipse 320,240,40,55 --n-ctrl 10 -o head.yaml
    """
    from pathlib import Path

    import cv2

    from . import draw
    from .template import save_template
    from .video import open_video

    chosen = [n for n, v in (("--points", points), ("--ellipse", ellipse), ("--box", box), ("--mask", mask)) if v]
    if len(chosen) != 1:
        raise click.UsageError("give exactly one of --points, --ellipse, --box, --mask"
                               + (f" (got {', '.join(chosen)})" if chosen else ""))
    if open_curve and not points:
        raise click.UsageError("--open goes with --points (boxes, masks and ellipses give closed outlines)")
    with open_video(clip, fps=fps) as video:
        frame = video.read(frame_index)
    size = (frame.image.shape[1], frame.image.shape[0])
    if points:
        outline = draw.parse_points(points)
        source = "points"
    elif ellipse:
        outline = draw.ellipse_outline(*draw.parse_numbers(ellipse, (4, 5), "--ellipse"))
        source = f"ellipse {ellipse}"
    elif box:
        b = draw.parse_numbers(box, 4, "--box")
        outline = draw.mask_outline(draw.segment_box(frame.image, tuple(b)))
        source = f"box {box} (GrabCut)"
    else:
        outline = draw.mask_outline(draw.load_mask(mask, size))
        source = f"mask {mask}"
    template = draw.fit_template(outline, n_ctrl, degree=degree, closed=not open_curve, clip=str(clip),
                                 frame=frame_index, frame_size=size, source=source)
    out = save_template(output, template)
    png = Path(preview) if preview else out.with_suffix(".png")
    vis = draw.render_preview(frame.image, template, n_normals=n_normals)
    ok, buf = cv2.imencode(".png", vis)
    from .outputs import atomic_path

    with atomic_path(png) as tmp:
        tmp.write_bytes(buf.tobytes())
    if rrd:
        from .recording import record_template

        record_template(rrd, frame.image, template, n_normals=n_normals)
    log.info("template %s (%d control points) from %s", out, n_ctrl, source)
    click.echo(f"wrote {out} and {png}" + (f" and {rrd}" if rrd else ""))


def main() -> None:
    cli(prog_name="trackcli")


if __name__ == "__main__":  # pragma: no cover
    main()
