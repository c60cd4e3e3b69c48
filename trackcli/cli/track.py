"""``trackcli track``: follow the object through clips (:mod:`trackcli.run.tracking`)."""

from __future__ import annotations

import click

from trackcli.cli.common import bars, echo_json
from trackcli.cli.options import (config_option, export_options, json_option, no_rrd_option, outdir_option,
                                  seed_option, template_option, video_options, video_overrides)
from trackcli.trackers import TRACKERS


@click.command("track")
@click.argument("clips", nargs=-1, required=True, type=click.Path())
@config_option()
@click.option("--model", type=click.Path(dir_okay=False),
              help="Model learned by `trackcli learn`, or a mixed-state model (kind: trackcli-mixed: a motion "
                   "label per sample, p_<label> columns; see the README).")
@template_option("Template drawn on this clip: the initial placement (with --model) or, alone, "
                 "the shape to track with hand-set dynamics.")
@click.option("--tracker", type=click.Choice(list(TRACKERS)), default="condensation", show_default=True,
              help="CONDENSATION (particle filter, robust to clutter), the Kalman contour tracker, mht "
                   "(a few Gaussian modes refined by Gauss-Newton steps; settings in mht:), or coupled (a centre "
                   "and rays to parts matched by NCC; needs a structure template from draw --parts; settings in "
                   "coupled:).")
@click.option("--particles", type=click.IntRange(min=1),
              help="CONDENSATION sample-set size N (condensation.particles, default 500); the first frame "
                   "has condensation.initial_particles samples (1500), falling to N over "
                   "condensation.schedule_frames frames (4). Not with a tracker that has no such set.")
@click.option("--threads", type=click.IntRange(min=0, max=256),
              help="Threads that score CONDENSATION's samples (condensation.threads; 0 = every core from 300 "
                   "samples up with the discriminant, 2000 with the numpy models, one below). The results "
                   "do not depend on it.")
@seed_option()
@outdir_option()
@click.option("--smooth", is_flag=True,
              help="Also write smoothed estimates, CLIP.TRACKER.smoothed.csv, and draw them in the recording: "
                   "Kalman: Rauch-Tung-Striebel; CONDENSATION: forward-filtering backward-smoothing of the "
                   "sample weights; both over the whole clip, after tracking it.")
@no_rrd_option("Do not write Rerun recordings.")
@json_option("Print one JSON summary line per clip on stdout.")
@export_options
@video_options
@click.pass_context
def track_cmd(ctx, clips, config, model, template, tracker, particles, threads, seed, outdir, smooth, no_rrd, as_json,
              masks, palette, vot, fps, start, end, step):
    """Follow the object through each CLIP (video file or image folder).

    \b
    What is tracked:
      --model M --template T   the model's shape-space and learned dynamics, placed where T
                               was drawn on this clip (the usual case)
      --model M                the model as learned, starting where its template was drawn
      --template T             T's shape-space with hand-set dynamics (configs/)

    With --model, the measurement settings (edge polarity, normals, smoothing, edge operator,
    threshold, channel) are the model's own, those it was learned with, except the keys
    that -c CONFIG sets; everything else comes from the configuration (-v says which).

    \b
    Per clip, in OUTDIR:
      CLIP.TRACKER.csv         per-frame estimates (see README: track format)
      CLIP.TRACKER.rrd         Rerun recording: frames, contour, particles or gates, series
      CLIP.TRACKER.config.yaml the effective configuration
      CLIP.TRACKER.smoothed.csv with --smooth: smoothed estimates (same columns)
    and one summary line on stdout.  --masks DIR writes each frame's outline filled as
    DIR/FRAME.png (with several clips, DIR/CLIP/FRAME.png), --vot FILE VOT region lines.  With several CLIPS, a clip that fails is reported
    on stderr and the others still run; the exit code is then 1.

    Every frame gets a confidence (0-1) that the estimate is on the object, from the
    contour discriminant and the colour learned on the first frame; a frame is lost
    when it is below 0.5, and the summary line counts those frames.  While lost,
    CONDENSATION also looks for object-coloured regions in a square around where the
    object was last held, growing with the time lost (reacquire.speed; 0: the whole
    frame), and picks the object up again when it shows (reacquire.enabled).
    """
    from trackcli.run.tracking import track_clips

    if not model and not template:
        raise click.UsageError("give --model, --template, or both")
    overrides = {"condensation.particles": particles, "condensation.threads": threads, "seed": seed,
                 **video_overrides(fps, start, end, step)}
    failures = 0
    for outcome in track_clips(clips, config=config, overrides=overrides, outdir=outdir, model=model,
                               template=template, tracker=tracker, rrd=not no_rrd, smooth=smooth,
                               progress=bars(ctx), masks=masks, palette=palette, vot=vot,
                               options={o: k for o, k, v in (("--particles", "condensation.particles", particles),
                                                             ("--threads", "condensation.threads", threads))
                                        if v is not None}):
        if outcome.error is not None:
            failures += 1
            click.echo(f"Error: {outcome.error}", err=True)
        if as_json:
            echo_json(outcome.json(tracker), digits=6)
        elif outcome.error is None:
            click.echo(outcome.summary.line())
            if outcome.exported is not None:
                click.echo(outcome.exported.line())
    if failures:
        click.echo(f"{failures} of {len(clips)} clips failed", err=True)
    ctx.exit(1 if failures else 0)
