"""``trackcli sample-data``: generate the synthetic sample clips (:mod:`trackcli.sample_data`)."""

from __future__ import annotations

import click

from trackcli.cli.common import progress
from trackcli.cli.options import frames_option, seed_option


@click.command("sample-data")
@click.argument("outdir", type=click.Path(file_okay=False))
@seed_option("Random seed (default: the seed of the committed sample_data/).")
@click.option("--clip", "clips", multiple=True,
              type=click.Choice(["train", "test", "three_heads", "bouncing_ball"]),
              help="Generate only this clip (repeatable; default all).")
@frames_option("Shorter (or longer) clips, for quick tries.")
@click.option("--truth-only", is_flag=True, help="Write the ground truth files but not the videos.")
@click.pass_context
def sample_data_cmd(ctx, outdir, seed, clips, n_frames, truth_only):
    """Generate the synthetic sample clips with exact per-frame ground truth into OUTDIR.

    \b
    train.mp4          head-and-shoulders moving gently over a clean background
    test.mp4           the same object moving agilely over heavy clutter, brief occlusion
    three_heads.mp4    three similar heads, one walking in front of the other two
    bouncing_ball.mp4  a ball bouncing under gravity
    Each clip comes with CLIP.truth.csv (centroid, box, pose, visible fraction per frame)
    and CLIP.outline.json (the true outline).  The same seed gives the same truth files.
    """
    from trackcli import sample_data

    chosen = list(clips) or list(sample_data.CLIP_NAMES)
    total = sum(n_frames or sample_data.default_n_frames(c) for c in chosen)
    with progress(ctx, 0 if truth_only else total, "rendering") as bar:
        paths = sample_data.generate(outdir, seed=sample_data.DEFAULT_SEED if seed is None else seed, clips=chosen,
                                     n_frames=n_frames, truth_only=truth_only,
                                     progress=lambda clip, i, n: bar.update(1))
    for p in paths:
        click.echo(str(p))
