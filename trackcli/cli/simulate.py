"""``trackcli simulate``: random sample paths of a model (:mod:`trackcli.run.simulation`)."""

from __future__ import annotations

import click

from trackcli.cli.options import fps_option, frames_option, model_argument, output_option, seed_option, template_option


@click.command("simulate")
@model_argument()
@frames_option("Length of each sample path.", default=250, most=1_000_000)
@click.option("--paths", "n_paths", type=click.IntRange(min=1, max=20), default=3, show_default=True,
              help="Number of sample paths.")
@seed_option("Random seed.", default=0)
@output_option("Recording (.rrd) to write (default: MODEL_sim.rrd); a PNG of the trajectories is written beside it.")
@click.option("--size", help="Canvas 'W,H' for the PNG (default: the template's frame size).")
@template_option("Mixed-state model: the template whose shape-space its labels move (needed by a hand-written "
                 "model, which has none of its own).")
@fps_option("Mixed-state model: frame rate the hand-set labels are built for (default: the template's clip's, "
            "else 25).")
def simulate_cmd(model_path, n_frames, n_paths, seed, output, size, template, fps):
    """Draw random sample paths from a model (AC Fig 11.7): the quickest sanity check.

    The PNG shows, for each path, the centroid trajectory and the contour every 10th frame
    over a blank canvas with the template in grey; the recording animates the paths.

    \b
    A mixed-state model's paths switch label as its transition matrix says; the PNG marks
    each frame an event label (a bounce) moved, and the recording has each path's label
    as a series (label index) and the labels' names in its parameters.
    """
    from trackcli.run.simulation import simulate_model

    done = simulate_model(model_path, n_frames=n_frames, n_paths=n_paths, seed=seed, output=output, size=size,
                          template=template, fps=fps)
    click.echo(f"wrote {done.output} and {done.png} ({done.summary})")
