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


def main() -> None:
    cli(prog_name="trackcli")


if __name__ == "__main__":  # pragma: no cover
    main()
