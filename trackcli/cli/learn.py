"""``trackcli learn``: learn AR(2) dynamics from training clips (:mod:`trackcli.run.learn`)."""

from __future__ import annotations

import click

from trackcli.cli.common import bars, echo_json
from trackcli.cli.options import (config_option, json_option, no_rrd_option, outdir_option, output_option,
                                  template_option, video_options, video_overrides)


@click.command("learn")
@click.argument("clips", nargs=-1, type=click.Path())
@config_option()
@template_option("Template drawn on the (first) training clip.", required=True)
@output_option("Model file to write (.yaml).", required=True)
@click.option("--cycles", type=click.IntRange(min=1, max=50), help="Track-learn cycles (learning.cycles, default 2).")
@click.option("--shape-space", "shape_space", help="translation, similarity, affine, or pca:K (residual PCA "
              "on top of translation, learned from the tracked outlines). Default: the config's shape_space.")
@click.option("--from-tracks", "from_tracks", multiple=True, type=click.Path(dir_okay=False),
              help="Learn from track CSVs already made instead of tracking CLIPS (repeatable).")
@click.option("--tracks-fps", type=click.FloatRange(min=0, min_open=True),
              help="Frame rate of the clips behind --from-tracks (default: the template clip's, else 25).")
@outdir_option("Folder for the per-cycle tracks and recordings (default: beside the model, MODEL_training/).",
               short=False, default=None)
@click.option("--method", type=click.Choice(["mle", "em"]), default="mle", show_default=True,
              help="mle: maximum likelihood on the tracked shapes (AC Fig 11.6); em: expectation-maximisation "
                   "on the measurements behind them (each frame's aggregated normals, or with --from-tracks "
                   "each shape with its reported std), settings em.tolerance and em.max_iterations.")
@click.option("--labels", "label_files", multiple=True, type=click.Path(dir_okay=False),
              help="Labelled frame ranges (CSV or YAML of start,end,label; frames inclusive), one file per CLIP or "
                   "--from-tracks track in order: writes a mixed-state model with one AR(2) per label and the "
                   "transition matrix counted from the labels.")
@no_rrd_option("Do not write recordings of the training tracks.")
@json_option("Print a JSON summary on stdout.")
@video_options
@click.pass_context
def learn_cmd(ctx, clips, config, template, output, cycles, shape_space, from_tracks, tracks_fps, outdir, method,
              label_files, no_rrd, as_json, fps, start, end, step):
    """Learn AR(2) dynamics from training CLIPS (AC Fig 11.1).

    Tracks each clip with the Kalman contour tracker (hand-set dynamics from the config in
    the first cycle), learns dynamics by maximum likelihood from all clips together
    (statistics pooled, AC Fig 11.6), and repeats with the learned model for --cycles
    cycles.  Writes the model, and per clip and cycle a track CSV and a recording.
    --method em learns instead by EM from what the tracker measured, smoothing each
    sequence under the current model (iterations and log-likelihoods in the model's
    provenance).

    With --labels (one file of labelled frame ranges per clip or track), the clips are
    tracked as above and the model written is a mixed-state model (Blake et al. 1998 §8):
    one AR(2) per label, learned by maximum likelihood from that label's frames pooled over
    the clips, and the transition matrix counted from the label sequences.  Event labels
    (a bounce) are not learned: write them into the file by hand (see the README).

    \b
    Examples:
      trackcli learn --template head.yaml sample_data/train.mp4 -o head-model.yaml --cycles 2
      trackcli learn --template hand.yaml --from-tracks hand.csv --labels hand-labels.csv -o hand.mixed.yaml
    """
    from trackcli.run.learn import learn_model

    learned = learn_model(clips, template=template, output=output, config=config,
                          overrides={"learning.cycles": cycles, **video_overrides(fps, start, end, step)},
                          shape_space=shape_space, from_tracks=from_tracks, tracks_fps=tracks_fps, outdir=outdir,
                          method=method, label_files=label_files, rrd=not no_rrd, progress=bars(ctx))
    if as_json:
        echo_json(learned.report())
        return
    for line in learned.lines():
        click.echo(line)
