"""The ``trackcli batch`` command: track and score every clip of a manifest.

Thin by design: it reads the manifest with :func:`trackcli.run.batch.load_manifest`, runs
:func:`trackcli.run.batch.run_batch`, prints one progress line per finished clip on stderr and
the results on stdout (a table, or JSON lines with ``--json``).
"""

from __future__ import annotations

import json
import logging
import math

from typing import TYPE_CHECKING

import click

from trackcli.cli.common import is_quiet
from trackcli.cli.options import json_option, outdir_option, quiet_option

if TYPE_CHECKING:  # the batch machinery (numpy, OpenCV) loads when a batch runs, not for --help
    from trackcli.run import batch


@click.command("batch")
@click.argument("manifest", type=click.Path(dir_okay=False))
@click.option("-j", "--jobs", "workers", type=click.IntRange(min=1),
              help="Clips run at once, each in its own process (default 1: one after another, in this process).")
@click.option("--scheduler", metavar="ADDRESS",
              help="Run the clips on a Dask cluster (e.g. tcp://host:8786) whose workers see the same "
                   "paths; needs pip install 'trackcli[dask]'.")
@outdir_option("Output folder: one subfolder per clip, and summary.json.")
@click.option("--force", is_flag=True, help="Run clips again even when their outputs are complete and current.")
@json_option("JSON lines on stdout: one object per clip (kind: clip), then one summary (kind: summary).")
@quiet_option("No progress lines on stderr (failed clips are still reported).")
@click.option("--masks", is_flag=True, help="Also write every clip's outlines as mask PNGs, OUTDIR/NAME/masks/ "
              "(as the manifest's masks: true does for one clip).")
@click.option("--palette", is_flag=True, help="With --masks: 8-bit palette PNGs, the object at index 1.")
@click.option("--vot", is_flag=True, help="Also write every clip's VOT region lines, OUTDIR/NAME/NAME.TRACKER.vot.txt.")
@click.pass_context
def batch_cmd(ctx, manifest, workers, scheduler, outdir, force, as_json, quiet, masks, palette, vot):
    """Track (and score) every clip listed in MANIFEST, a YAML file.

    \b
    Manifest (paths relative to its folder):
      format: 1
      defaults: {model: head-model.yaml, tracker: condensation, seed: 0,
                 settings: {condensation.particles: 300}}
      clips:
        - {clip: test.mp4, template: head-test.yaml, truth: test.truth.csv}
        - {clip: crossing/, fps: 25, template: crossing.yaml, name: crossing}

    Per clip, in OUTDIR/NAME/: the track CSV, recording and effective configuration as
    `trackcli track` writes them, score.json (with a truth) and result.json, written
    last.  A clip whose result.json is present and current is skipped (--force runs
    it again).  A clip that fails is reported and the others go on; so does a clip whose
    entry names a file that does not exist: every other clip runs, and the missing ones
    are listed at the end (when none can run, nothing is written: exit status 4).

    Exit status: 0 if every clip succeeded, 1 if any failed or was missing an input, 3 or 4
    for a bad manifest.

    \b
    Example:
      trackcli batch clips.yaml --jobs 2 -o results --json | python3 -c 'import json, sys; ...'
    """
    if scheduler and workers:
        raise click.UsageError("give --jobs (local processes) or --scheduler (Dask), not both")
    if palette and not masks:
        raise click.UsageError("--palette goes with --masks")
    quiet = quiet or is_quiet(ctx)
    if quiet:
        logging.getLogger("trackcli").setLevel(logging.ERROR)
    from trackcli.run import batch

    if scheduler:
        batch.require_dask()
    m = batch.load_manifest(manifest)
    batch.check_runnable(m)
    m = batch.with_exports(m, masks=("palette" if palette else "grey") if masks else None,
                           vot=vot)
    total = len(m.jobs)
    done = 0

    def report(r: "batch.JobResult") -> None:
        nonlocal done
        done += 1
        if r.status == "failed":
            click.echo(f"[{done}/{total}] {r.name}: {'MISSING INPUT' if r.missing else 'FAILED'}: {r.error}", err=True)
        elif not quiet:
            click.echo(f"[{done}/{total}] {r.name}: {_progress_text(r)}", err=True)
        if not quiet:
            for w in r.warnings:
                click.echo(f"Warning: {w}", err=True)

    from trackcli.io.outputs import output_dir

    with output_dir(outdir):  # a batch that cannot start (no scheduler) leaves no empty folder
        result = batch.run_batch(m, outdir, workers=workers or 1, scheduler=scheduler, force=force,
                                 on_result=report)
    if as_json:
        for r in result.results:
            click.echo(json.dumps({"kind": "clip", **r.to_dict()}, allow_nan=False))
        click.echo(json.dumps({"kind": "summary", "manifest": str(m.path), **result.summary()}, allow_nan=False))
    else:
        click.echo(format_table(result))
    missing = [r for r in result.results if r.missing]
    if missing:
        click.echo(f"Error: {len(missing)} of {total} clips did not run, an input is missing: "
                   + "; ".join(r.error for r in missing), err=True)
    ctx.exit(0 if result.succeeded else 1)


def _progress_text(r: batch.JobResult) -> str:
    what = "skipped, outputs complete" if r.status == "skipped" else f"done in {r.seconds:.1f} s"
    parts = [f"{r.frames} frames"]
    if r.tracker_fps is not None and math.isfinite(r.tracker_fps):
        parts.append(f"{r.tracker_fps:.0f} frames/s")
    if r.precision is not None:
        parts.append(f"precision {r.precision:.3f}")
    if r.success_auc is not None:
        parts.append(f"AUC {r.success_auc:.3f}")
    return f"{what} ({', '.join(parts)})"


def format_table(result: batch.BatchResult) -> str:
    """The summary table: one row per clip, then a totals line."""
    def num(v, fmt: str) -> str:
        return "-" if v is None or not math.isfinite(v) else format(v, fmt)

    head = ("clip", "status", "frames", "fps", "precision", "centre err", "AUC", "seconds")
    rows = [(r.name, r.status, "-" if r.frames is None else str(r.frames), num(r.tracker_fps, ".1f"),
             num(r.precision, ".3f"), num(r.centre_error_mean, ".2f"), num(r.success_auc, ".3f"),
             f"{r.seconds:.1f}") for r in result.results]
    widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(head)]

    def line(cells) -> str:
        first = f"{cells[0]:<{widths[0]}}  {cells[1]:<{widths[1]}}"
        return (first + "".join(f"  {c:>{w}}" for c, w in zip(cells[2:], widths[2:]))).rstrip()

    s = result.summary()
    total = (f"{s['clips']} clips: {s['ok']} ok, {s['skipped']} skipped, {s['failed']} failed, "
             f"{result.seconds:.1f} s ({result.executor}); results in {result.outdir}")
    return "\n".join([line(head), *map(line, rows), total])
