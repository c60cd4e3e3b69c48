"""``trackcli draw``: make a template around the object in one frame (:mod:`trackcli.run.drawing`)."""

from __future__ import annotations

import click

from trackcli.cli.common import bars
from trackcli.cli.options import fps_option, output_option


@click.command("draw")
@click.argument("clip", type=click.Path())
@click.option("--frame", "frame_index", type=click.IntRange(min=0), default=0, show_default=True,
              help="Frame of CLIP to draw on.")
@click.option("--points", help="Ordered outline points 'x1,y1 x2,y2 ...', or a file with one 'x,y' per line.")
@click.option("--ellipse", help="Ellipse 'cx,cy,a,b[,angle]': centre, semi-axes (px), angle (degrees).")
@click.option("--box", help="Box 'x,y,w,h' around the object: segmented automatically (GrabCut; on a grey "
              "frame by grey level and local texture; the inscribed ellipse when no object is found). On a clip, "
              "what moves unlike the scene over the next 3 frames (optical flow) seeds one more mask and chooses "
              "among them when it is clear, and GrabCut's other masks are also tracked over the next 14 frames: "
              "one that is clearly better held replaces the frame's choice (-v prints their figures).")
@click.option("--mask", type=click.Path(), help="Binary mask image (non-zero = object), same size as the frame.")
@click.option("--parts", "part_specs", multiple=True, metavar="NAME:x,y,w,h",
              help="A part of a structure template for --tracker coupled (repeatable, at least two), e.g. "
                   "--parts left_eye:341,214,22,14: its box and image patch are stored with the outline. With "
                   "--parts alone the outline is the ellipse around the parts (semi-axes 0.8 and 0.9 of their "
                   "bounding box).")
@click.option("--n-ctrl", type=click.IntRange(min=3, max=200),
              help="Number of spline control points.  [default: 12, or 24 for an outline with detail 12 cannot "
                   "follow, such as an open hand's fingers, where 24 cover it clearly better than its convex hull]")
@click.option("--degree", type=click.IntRange(min=1, max=5), default=2, show_default=True,
              help="Spline degree (2 = quadratic).")
@click.option("--open", "open_curve", is_flag=True, help="Open curve (default closed); only with --points.")
@fps_option("Frame rate of an image folder.")
@output_option("Template file to write (.yaml).", required=True)
@click.option("--preview", type=click.Path(dir_okay=False),
              help="Preview PNG (default: beside the template, same name with .png).")
@click.option("--rrd", type=click.Path(dir_okay=False), help="Also write a Rerun recording of the template.")
@click.option("--n-normals", type=click.IntRange(min=3, max=1000), default=24, show_default=True,
              help="Measurement normals shown in the preview.")
def draw_cmd(clip, frame_index, points, ellipse, box, mask, part_specs, n_ctrl, degree, open_curve, fps, output,
             preview, rrd, n_normals):
    """Make a template: a B-spline outline of the object in one frame of CLIP.

    Give exactly one of --points, --ellipse, --box or --mask.  Writes the template (YAML),
    a PNG preview (curve in green, control polygon in blue, measurement normals in yellow)
    and, with --rrd, a recording.  With --parts the template is also a structure template
    for --tracker coupled: each part's box and image patch are kept.

    When the fit strays from the outline (by more than a tenth of the object's size), draw
    falls back and says so, in a warning and in the template's `source`: thin parts opened
    away, a refit that may not fold, twice the control points (when --n-ctrl is not given),
    or the outline's convex hull (more control points, --n-ctrl, follow more detail).

    \b
    Examples:
      trackcli draw sample_data/train.mp4 --box 172,91,135,155 -o head.yaml
      trackcli draw clip.mp4 --frame 10 --ellipse 320,240,40,55 --n-ctrl 10 -o head.yaml
      trackcli draw face.mp4 --parts left_eye:341,214,22,14 --parts right_eye:376,214,22,14 \\
          --parts mouth:352,262,34,16 -o face.yaml
    """
    from trackcli.run.drawing import draw_template, ellipse_around_parts, parse_parts

    chosen = [n for n, v in (("--points", points), ("--ellipse", ellipse), ("--box", box), ("--mask", mask)) if v]
    parts = parse_parts(part_specs)
    if parts and not chosen:
        ellipse, chosen = ellipse_around_parts(parts), ["--ellipse"]
    if len(chosen) != 1:
        raise click.UsageError("give exactly one of --points, --ellipse, --box, --mask"
                               + (f" (got {', '.join(chosen)})" if chosen else ""))
    if open_curve and not points:
        raise click.UsageError("--open goes with --points (boxes, masks and ellipses give closed outlines)")
    drawn = draw_template(clip, output=output, frame_index=frame_index, points=points, ellipse=ellipse, box=box,
                          mask=mask, parts=parts, n_ctrl=n_ctrl, degree=degree, open_curve=open_curve, fps=fps,
                          preview=preview, rrd=rrd, n_normals=n_normals, progress=bars())
    click.echo(f"wrote {drawn.output} and {drawn.preview}" + (f" and {drawn.rrd}" if drawn.rrd else ""))
