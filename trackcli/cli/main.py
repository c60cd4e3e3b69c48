"""The ``trackcli`` command group: global options, errors as one line and an exit code.

Each command lives in its own module of this package and is thin: it parses its options,
calls one function of :mod:`trackcli.run` (or another library package) and prints or writes
the result.  Every :class:`~trackcli.errors.TrackcliError` becomes a one-line message on
stderr and the exit code of its class; progress bars and logs go to stderr, results to
stdout or files.  Command modules import only Click at module level, so ``trackcli --help``
loads neither numpy nor OpenCV.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys

import click

from trackcli import __version__
from trackcli.cli import (batch, config, draw, evaluate, inspect_model, learn, render, sample_data, simulate, track,
                          view)
from trackcli.errors import TrackcliError


class TrackcliGroup(click.Group):
    """Click group that turns every error into one line on stderr and an exit code.

    - library errors (:class:`~trackcli.errors.TrackcliError`): the code of their class (those of
      code 2, :class:`~trackcli.run.options.OptionError`, point to the command's help as Click's do);
    - an invalid option value (Click's ``BadParameter``): 3, like an invalid setting;
    - other usage errors (missing or unknown options or arguments, conflicting options): 2;
    - a file system error nothing else translated: 4, naming the file;
    - Ctrl-C: 130.
    """

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except TrackcliError as exc:
            message = str(exc).strip()
            if exc.exit_code == 2 and ctx.invoked_subcommand:  # options that do not go together, as Click's
                message = f"{' '.join(message.split())} (see '{ctx.command_path} {ctx.invoked_subcommand} --help')"
            _fail(ctx, message, exc.exit_code)
        except click.MissingParameter as exc:
            _fail(ctx, _usage_line(exc), 2)
        except click.BadParameter as exc:
            _fail(ctx, _usage_line(exc), 3)
        except click.UsageError as exc:
            _fail(ctx, _usage_line(exc), 2)
        except KeyboardInterrupt:
            click.echo("Interrupted.", err=True)
            ctx.exit(130)
        except BrokenPipeError:  # the reader of stdout stopped (`| head`): nothing more to say
            with contextlib.suppress(OSError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            ctx.exit(0)
        except OSError as exc:
            name = f"{exc.filename}: " if exc.filename else ""
            _fail(ctx, f"{name}{exc.strerror or exc}", 4)
        except (MemoryError, RecursionError) as exc:
            _fail(ctx, f"out of {'memory' if isinstance(exc, MemoryError) else 'stack'} "
                       "(is an input unreasonably large or deeply nested?)", 1)


def _fail(ctx: click.Context, message: str, code: int) -> None:
    lines = str(message).strip().splitlines() or [""]
    click.echo(f"Error: {lines[0]}", err=True)
    ctx.exit(code)


def _usage_line(exc: click.UsageError) -> str:
    """Click's message, and where to find help, on one line."""
    text = " ".join(exc.format_message().split())
    if exc.ctx is not None and exc.ctx.command is not None and exc.ctx.parent is not None:
        text += f" (see '{exc.ctx.command_path} --help')"
    return text


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
      track   follow the object in test footage with CONDENSATION (or the Kalman,
              multiple-hypothesis and coupled-parts trackers)
      eval    score estimates against ground truth (and plot them)
      render  draw the estimated outline on the frames: video, PNGs, contact sheet
      view    open a recording in the Rerun viewer
      batch   run many clips from a manifest, locally or on a Dask cluster

    Every run writes a Rerun recording (.rrd) and CSV files of the estimates.
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", stream=sys.stderr)
    ctx.ensure_object(dict)
    ctx.obj["quiet"] = quiet


for _command in (config.config_group, draw.draw_cmd, track.track_cmd, learn.learn_cmd, inspect_model.inspect_cmd,
                 simulate.simulate_cmd, evaluate.eval_cmd, render.render_cmd, view.view_cmd,
                 sample_data.sample_data_cmd, batch.batch_cmd):
    cli.add_command(_command)


def main() -> None:
    """The ``trackcli`` executable: run the command, then leave without the interpreter's teardown.

    Every command has closed its outputs when it returns (files are written under temporary
    names and renamed, recordings disconnected, worker threads joined), so after flushing
    the standard streams the process ends at once: tearing down numpy, OpenCV, numba and
    Rerun module by module took about 0.4 s, a tenth of a short ``track`` run.  Under a
    debugger, profiler or coverage tool the interpreter exits normally.
    """
    # no pandas import by pyarrow in this process and its workers (trackcli.io.recording)
    os.environ.setdefault("TRACKCLI_PANDAS_CHECK", "0")
    try:
        cli.main(prog_name="trackcli")
        code = 0
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    if sys.gettrace() is not None or sys.getprofile() is not None:
        sys.exit(code)  # under a debugger, profiler or coverage tool: let it write its results
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    main()
