"""``trackcli view``: open a recording in the Rerun viewer (:mod:`trackcli.io.viewer`)."""

from __future__ import annotations

import logging

import click

log = logging.getLogger("trackcli")


@click.command("view")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("--web", is_flag=True, help="Serve the web viewer over HTTP instead (for machines without a screen); "
              "open the printed address in a browser.")
@click.option("--port", type=click.IntRange(min=1, max=65535), help="Port of the web viewer (with --web).")
@click.pass_context
def view_cmd(ctx, recording, web, port):
    """Open RECORDING (.rrd) in the Rerun viewer.

    Runs the native viewer that comes with trackcli's rerun-sdk (the 'rerun' program) and
    waits until it is closed.  Without a screen (DISPLAY unset), says so and what to do
    instead: --web, or copying the file to a machine with rerun-sdk 0.41 installed.
    """
    from trackcli.io.viewer import check_recording, run_viewer, viewer_command

    if port is not None and not web:
        raise click.UsageError("--port goes with --web")
    cmd = viewer_command(check_recording(recording), web=web, port=port)
    log.info("running %s", " ".join(cmd))
    ctx.exit(run_viewer(cmd))
