"""``trackcli render``: draw a track's outline on its clip (:mod:`trackcli.run.rendering`)."""

from __future__ import annotations

import click

from trackcli.cli.common import bars
from trackcli.cli.options import export_options, object_option, output_option, video_options


@click.command("render")
@click.argument("track", type=click.Path(dir_okay=False))
@click.argument("clip", type=click.Path())
@output_option("Output file or folder (default beside TRACK: NAME.mp4, NAME.sheet.png or NAME_frames/).",
               folder=True)
@click.option("--sheet", "sheet", type=click.IntRange(min=1, max=400),
              help="Write a contact sheet (PNG) of this many frames spread over the selection, instead of a video.")
@click.option("--png", "png", is_flag=True, help="Write one PNG per frame into a folder, instead of a video.")
@click.option("--tile-width", type=click.IntRange(min=32, max=4000), default=240, show_default=True,
              help="Width of each contact-sheet frame (px; frames are only shrunk).")
@click.option("--truth", type=click.Path(), help="Ground truth (as for eval) whose box is drawn in green.")
@object_option("Object id in a truth CSV with several objects.")
@click.option("--no-label", is_flag=True, help="No frame number, LOST or confidence text on the frames.")
@export_options
@video_options
@click.pass_context
def render_cmd(ctx, track, clip, output, sheet, png, tile_width, truth, object_id, no_label, masks, palette, vot, fps,
               start, end, step):
    """Draw the estimated outline of TRACK (a track CSV) on the frames of CLIP.

    CLIP is the video file or image folder that was tracked.  The outline comes from the
    CSV's outline columns, so no model or template is needed.  By default the frames of the
    track are drawn (--start/--end/--step select others) into an MP4 beside TRACK (H.264;
    .avi: Motion JPEG).  Lost frames show the outline dashed in grey; with --truth the true
    box is drawn in green.  --masks DIR and --vot FILE write every frame of the track as
    mask PNGs named as the frames, and as VOT region lines, instead of pictures.

    \b
    Examples:
      trackcli render out/test.condensation.csv sample_data/test.mp4
      trackcli render out/test.condensation.csv sample_data/test.mp4 --sheet 12 -o sheet.png
      trackcli render out/crossing.kalman.csv ../footage/crossing --png --truth ../footage/crossing
      trackcli render out/boat.condensation.csv davis/boat/img --masks out/boat-masks
    """
    if masks or vot:
        from trackcli.run.export import check_export_outputs, export_track

        if sheet or png or output:
            raise click.UsageError("--masks/--vot write masks and region lines; give them without --sheet, --png or -o")
        if palette and not masks:
            raise click.UsageError("--palette goes with --masks")
        check_export_outputs(masks, vot, inputs={"TRACK": track, "CLIP": clip})
        exported = export_track(track, clip, masks=masks, vot=vot, palette=palette, fps=fps)
        click.echo(f"wrote {exported.line()}")
        return
    if palette:
        raise click.UsageError("--palette goes with --masks")
    from trackcli.run.rendering import render_track

    if sheet and png:
        raise click.UsageError("give --sheet or --png, not both")
    kind = "sheet" if sheet else ("frames" if png else "video")
    result = render_track(track, clip, output, kind=kind, truth=truth, object_id=object_id, progress=bars(ctx),
                          sheet_frames=sheet or 12, tile_width=tile_width, fps=fps, start=start, end=end, step=step,
                          label=not no_label)
    what = {"video": f"video ({result.codec})", "frames": "PNG frames", "sheet": "contact sheet"}[kind]
    click.echo(f"wrote {result.output}: {what} of {result.frames} frames, {result.with_estimate} with an estimate")
