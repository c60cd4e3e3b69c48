"""``trackcli eval``: score estimates against ground truth (:mod:`trackcli.run.scoring`)."""

from __future__ import annotations

import click

from trackcli.cli.common import echo_json, is_quiet
from trackcli.cli.options import json_option, object_option


@click.command("eval")
@click.argument("tracks", nargs=-1, required=True, type=click.Path(), metavar="PRED...")
@click.argument("truth", type=click.Path())
@click.option("--threshold", type=click.FloatRange(min=0, min_open=True), default=20.0, show_default=True,
              help="Centre-error threshold (px) for precision.")
@click.option("--lost-threshold", type=click.FloatRange(min=0, min_open=True),
              help="Also count a frame lost when its centre error exceeds this (px).")
@object_option("Object id in a trackcli truth CSV with several objects.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Write the precision plot (0-50 px) and the success plot (IoU 0-1) of all PRED to this PNG "
                   "(against true masks: J and F per frame).")
@json_option("Print the scores as one JSON object per PRED (against true masks, with J and F per frame).")
@click.pass_context
def eval_cmd(ctx, tracks, truth, threshold, lost_threshold, object_id, plot_path, as_json):
    """Score estimates PRED (one or more track CSVs) against ground truth TRUTH.

    TRUTH is a trackcli truth CSV (sample_data/*.truth.csv), a benchmark box file (one
    'x,y,w,h' line per frame, comma or whitespace separated; VOT's 8-number polygons are
    scored by the rectangle around them), or a folder holding
    groundtruth_rect.txt / groundtruth.txt.  Frames are matched by index; when a track and
    the truth cover different frames, a warning says which frames were scored.

    TRUTH may also be a folder of true masks (DAVIS: SEQ/masks/00000.png, ...); each PRED is
    then a folder of masks (track --masks) or a track CSV, and the scores are DAVIS-2016's:
    J (mask IoU) and F (boundary F-measure), their mean, recall and decay over the frames,
    the first and the last left out, and J&F.

    \b
    Metrics: centre error (mean, median, max, px), precision at --threshold, success AUC,
    mean IoU, frames lost, and outline IoU when the track CSV has outline columns and the
    truth has outlines (a sample-data truth with its CLIP.outline.json beside it).

    \b
    Success AUC follows the OTB convention: the mean, over the 21 overlap thresholds
    t = 0, 0.05, ..., 1, of the fraction of frames with IoU > t.  No IoU exceeds 1, so a
    perfect track scores 20/21 = 0.952, not 1.

    \b
    Examples:
      trackcli eval out/test.condensation.csv sample_data/test.truth.csv
      trackcli eval out/test.condensation.csv out/test.kalman.csv sample_data/test.truth.csv --plot pr.png
      trackcli eval out/boat-masks davis/boat/masks --plot jf.png
    """
    from pathlib import Path

    from trackcli.run.mask_eval import is_mask_folder

    if is_mask_folder(truth):
        _eval_masks(ctx, tracks, truth, plot_path, as_json)
        return
    folders = [t for t in tracks if Path(t).is_dir()]
    if folders:
        raise click.BadParameter(f"{folders[0]} is a folder: a folder of masks is scored against a folder of "
                                 "true masks (TRUTH, e.g. SEQ/masks)", param_hint="PRED")
    from trackcli.run.evaluate import format_table
    from trackcli.run.scoring import score_tracks, write_score_plots

    quiet = is_quiet(ctx)
    scored = []
    for k, s in enumerate(score_tracks(tracks, truth, threshold=threshold, lost_threshold=lost_threshold,
                                       object_id=object_id, plot=plot_path)):
        scored.append(s)
        if s.notes and not quiet:
            click.echo(f"Warning: {'; '.join(s.notes)}", err=True)
        if as_json:
            echo_json(s.json(truth), digits=6)
            continue
        if len(tracks) > 1:
            click.echo(("\n" if k else "") + f"== {s.label} ({s.path})")
        click.echo(format_table(s.result))
    if plot_path:
        out = write_score_plots(plot_path, scored, threshold)
        if not as_json:
            click.echo(f"wrote {out}")


def _eval_masks(ctx, preds, truth, plot_path, as_json) -> None:
    """``eval`` against a folder of true masks: DAVIS J and F (:mod:`trackcli.run.mask_eval`)."""
    from trackcli.run.mask_eval import format_mask_table, score_predictions, write_mask_plot

    quiet = is_quiet(ctx)
    scored = []
    for k, (label, result) in enumerate(score_predictions(list(preds), truth, plot=plot_path)):
        scored.append((label, result))
        if result.notes and not quiet:
            click.echo(f"Warning: {'; '.join(result.notes)}", err=True)
        if as_json:
            echo_json(result.to_dict(), digits=6)
            continue
        if len(preds) > 1:
            click.echo(("\n" if k else "") + f"== {label} ({result.pred})")
        click.echo(format_mask_table(result))
    if plot_path:
        out = write_mask_plot(plot_path, scored)
        if not as_json:
            click.echo(f"wrote {out}")
