"""The ``trackcli`` command line.

Commands are thin: they parse options, resolve inputs and outputs, call the library and
write results.  Every :class:`~trackcli.errors.TrackcliError` becomes a one-line message on
stderr and the exit code of its class; progress bars and logs go to stderr, results to
stdout or files.

One module (over 600 lines): Click commands only, one function per command with its
options; the work of each is in :mod:`trackcli.run` and the other packages.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import sys
from pathlib import Path

import click

from trackcli import __version__
from trackcli.errors import TrackcliError
from trackcli.trackers import TRACKERS

log = logging.getLogger("trackcli")


class TrackcliGroup(click.Group):
    """Click group that turns every error into one line on stderr and an exit code.

    - library errors (:class:`~trackcli.errors.TrackcliError`): the code of their class;
    - an invalid option value (Click's ``BadParameter``): 3, like an invalid setting;
    - other usage errors (missing or unknown options or arguments, conflicting options): 2;
    - a file system error nothing else translated: 4, naming the file;
    - Ctrl-C: 130.
    """

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except TrackcliError as exc:
            _fail(ctx, str(exc), exc.exit_code)
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


# ---------------------------------------------------------------------------------------------
# config


@cli.group("config")
def config_group() -> None:
    """Show (with every setting explained), list and check configuration files and presets."""


@config_group.command("show")
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--comments", is_flag=True, help="Explain every setting in a comment.")
def config_show(file: str | None, comments: bool) -> None:
    """Print the effective configuration: the defaults, overridden by FILE if given.

    The output is itself a valid configuration file:
    `trackcli config show --comments > my.yaml` starts a new one.
    """
    from trackcli.settings import dump_yaml, load_settings, render_commented

    settings = load_settings(file)
    click.echo(render_commented(settings) if comments else dump_yaml(settings), nl=False)


@config_group.command("list")
def config_list() -> None:
    """List the preset configurations that ship with trackcli, with their purpose.

    Use a preset by name from any folder: `trackcli track -c tight ...`.  A file of the
    same name in the current folder wins over the preset.
    """
    from trackcli.settings import preset_purpose, presets

    found = presets()
    width = max((len(n) for n in found), default=0)
    for name, path in found.items():
        click.echo(f"{name:<{width}}  {preset_purpose(path)}")


@config_group.command("check")
@click.argument("file", type=click.Path(dir_okay=False))
def config_check(file: str) -> None:
    """Validate FILE; exit 0 if it is valid, 3 with the reason if not."""
    from trackcli.settings import load_settings

    load_settings(file)
    click.echo(f"{file}: OK")


# ---------------------------------------------------------------------------------------------
# draw


@cli.command("draw")
@click.argument("clip", type=click.Path())
@click.option("--frame", "frame_index", type=click.IntRange(min=0), default=0, show_default=True,
              help="Frame of CLIP to draw on.")
@click.option("--points", help="Ordered outline points 'x1,y1 x2,y2 ...', or a file with one 'x,y' per line.")
@click.option("--ellipse", help="Ellipse 'cx,cy,a,b[,angle]': centre, semi-axes (px), angle (degrees).")
@click.option("--box", help="Box 'x,y,w,h' around the object: segmented automatically (GrabCut; on a grey "
              "frame by grey level and local texture; the inscribed ellipse when no object is found). On a clip, "
              "GrabCut's other masks are also tracked over the next 14 frames, and one that is clearly better held "
              "replaces the frame's choice (-v prints their figures).")
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
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), help="Frame rate of an image folder.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True, help="Template file to write (.yaml).")
@click.option("--preview", type=click.Path(dir_okay=False),
              help="Preview PNG (default: beside the template, same name with .png).")
@click.option("--rrd", type=click.Path(dir_okay=False), help="Also write a Rerun recording of the template.")
@click.option("--n-normals", type=click.IntRange(min=3, max=1000), default=24, show_default=True,
              help="Measurement normals shown in the preview.")
def draw_cmd(clip, frame_index, points, ellipse, box, mask, part_specs, n_ctrl, degree, open_curve, fps, output, preview, rrd, n_normals):
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
    from pathlib import Path

    import cv2
    import numpy as np

    from trackcli.shapes import draw, structure
    from trackcli.run import drawing
    from trackcli.segment import grabcut, masks
    from trackcli.io.outputs import atomic_paths, check_output_folders, output_dir, refuse_overwriting_inputs
    from trackcli.shapes.template import save_template
    from trackcli.io.video import open_video

    chosen = [n for n, v in (("--points", points), ("--ellipse", ellipse), ("--box", box), ("--mask", mask)) if v]
    specs = [structure.parse_part(p) for p in part_specs]
    if specs and not chosen:
        xy = np.array([[x, y, x + w, y + h] for _, (x, y, w, h) in specs])
        lo, hi = xy[:, :2].min(axis=0), xy[:, 2:].max(axis=0)
        c, half = (lo + hi) / 2.0, (hi - lo) / 2.0
        ellipse = f"{c[0]:.2f},{c[1]:.2f},{1.6 * half[0]:.2f},{1.8 * half[1]:.2f}"
        chosen = ["--ellipse"]
    if len(chosen) != 1:
        raise click.UsageError("give exactly one of --points, --ellipse, --box, --mask"
                               + (f" (got {', '.join(chosen)})" if chosen else ""))
    if open_curve and not points:
        raise click.UsageError("--open goes with --points (boxes, masks and ellipses give closed outlines)")
    out = Path(output)
    png = Path(preview) if preview else out.with_suffix(".png")
    points_file = points if points and Path(points).is_file() else None
    refuse_overwriting_inputs({"-o/--output": out, "--preview": png, "--rrd": rrd},
                              {"CLIP": clip, "--mask": mask, "--points": points_file})
    check_output_folders(out, png, rrd)
    # kept open until the command ends: --box reads on from the drawn frame to try its masks
    video = click.get_current_context().with_resource(open_video(clip, fps=fps))
    frame = video.read(frame_index)
    size = (frame.image.shape[1], frame.image.shape[0])
    draw.check_frame_size(size, str(clip))
    if points:
        outline = draw.parse_points(points)
        draw.check_outline_in_frame(outline, size, "--points", closed=not open_curve)
        source = "points"
    elif ellipse:
        outline = draw.ellipse_outline(*draw.parse_numbers(ellipse, (4, 5), "--ellipse"))
        draw.check_outline_in_frame(outline, size, "--ellipse")
        source = f"ellipse {ellipse}"
    elif box:
        b = draw.parse_numbers(box, 4, "--box")
        # GrabCut takes seconds on a large frame (longer on a grey one, whose texture is segmented too)
        with _progress(click.get_current_context(), grabcut.segment_runs(frame.image), "segmenting the box") as bar:
            seg = grabcut.segment_candidates(frame.image, tuple(b), progress=bar.update)
        mask_image, note = _confirm_mask(seg, video, frame, lambda m: _fit_outline(masks.mask_outline(m), n_ctrl,
                                                                                    degree, size, _quiet=True))
        outline = masks.mask_outline(mask_image)
        source = f"box {box} ({seg.method}{note})"
    else:
        outline = masks.object_outline(masks.load_mask(mask, size))
        source = f"mask {mask}"
    template = _fit_outline(outline, n_ctrl, degree, size, closed=not open_curve, clip=str(clip), frame=frame_index,
                            source=source)
    if box:
        template = dataclasses.replace(template, box=tuple(b))
    if specs:
        parts = structure.cut_parts(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), specs)
        template = dataclasses.replace(template, extra={**template.extra, "parts": structure.parts_to_yaml(parts)})
    vis = drawing.render_preview(frame.image, template, n_normals=n_normals)
    for name, (x, y, w, h) in specs:
        cv2.rectangle(vis, (int(round(x)), int(round(y))), (int(round(x + w)), int(round(y + h))), (0, 200, 255), 1)
    ok, buf = cv2.imencode(".png", vis)
    with output_dir(out.parent), output_dir(png.parent), output_dir(Path(rrd).parent if rrd else out.parent):
        with atomic_paths(out, png, *([rrd] if rrd else [])) as tmps:  # all outputs or none
            save_template(tmps[0], template)
            tmps[1].write_bytes(buf.tobytes())
            if rrd:
                drawing.record_template(tmps[2], frame.image, template, n_normals=n_normals)
    log.info("template %s (%d control points) from %s", out, template.n_ctrl, source)
    click.echo(f"wrote {out} and {png}" + (f" and {rrd}" if rrd else ""))


def _fit_outline(outline, n_ctrl, degree: int, size: tuple[int, int], **kw):
    """``draw``'s B-spline fit of ``outline`` (the written template and ``--box``'s trial ones alike)."""
    from trackcli.run import drawing

    return drawing.fit_template(outline, n_ctrl or drawing.DEFAULT_CTRL, degree=degree, frame_size=size,
                                detail_ctrl=None if n_ctrl else drawing.DETAIL_CTRL, **kw)


def _confirm_mask(seg, video, frame, fit):
    """``draw --box``: the mask of ``seg`` that the frames of ``video`` after the drawn one
    (``frame``) hold best (:func:`trackcli.run.confirm.confirm`), and what to add to the
    template's source about it.  ``fit(mask)`` makes a template as ``draw`` does."""
    from trackcli.errors import VideoError
    from trackcli.run import confirm

    order = confirm.to_try(seg.masks, seg.chosen)
    if len(order) < 2:  # one mask (or the inscribed ellipse): nothing to choose
        return seg.mask, ""
    frames = [frame]
    for i in range(frame.index + 1, min(frame.index + confirm.CONFIRM_FRAMES, video.n_total)):
        try:
            frames.append(video.read(i))
        except VideoError:  # a file's frame count is an estimate: its true end came first
            break
    if len(frames) - 1 < confirm.CONFIRM_LEAST:
        return seg.mask, ""
    with _progress(click.get_current_context(), len(order), f"trying {len(order)} masks on the next frames") as bar:
        best, trials = confirm.confirm(seg.masks, order, fit, frames, video.fps, progress=bar.update)
    for t in trials:
        log.info("mask %d of %d%s: over frames %d-%d, confidence %.3f, score %.1f (%.2f of the first frame's)",
                 t.index + 1, len(seg.masks), " (the frame's choice)" if t.index == seg.chosen else "",
                 frame.index + 1, frame.index + len(frames) - 1, t.confidence, t.score, t.held)
    if best == seg.chosen:
        return seg.mask, ""
    return seg.masks[best], f"; the mask the next {len(frames) - 1} frames held best"


# ---------------------------------------------------------------------------------------------
# shared helpers


def _settings(config: str | None, overrides: dict):
    from trackcli.settings import load_settings

    return load_settings(config, {k: v for k, v in overrides.items() if v is not None})


def _explicit_keys(config: str | None, overrides: dict) -> set[str]:
    """Dotted keys the user set: every key of the configuration file, and the options given."""
    from trackcli.settings import read_yaml

    keys = {k for k, v in overrides.items() if v is not None}

    def walk(node, prefix: str) -> None:
        for k, v in node.items():
            key = f"{prefix}{k}"
            if isinstance(v, dict) and v:
                walk(v, key + ".")
            else:
                keys.add(key)

    if config is not None:
        walk(read_yaml(config), "")
    return keys


def _open(clip: str, settings):
    from trackcli.io.video import open_video

    v = settings.video
    return open_video(clip, fps=v.fps, start=v.start, end=v.end, step=v.step)


def _progress(ctx: click.Context, length: int, label: str):
    quiet = bool(ctx.find_root().obj and ctx.find_root().obj.get("quiet"))
    import os

    hidden = quiet or not sys.stderr.isatty() and os.environ.get("TRACKCLI_PROGRESS") != "1"
    return click.progressbar(length=length, label=label, file=sys.stderr, show_pos=True, width=30,
                             hidden=hidden)


def _echo_json(obj) -> None:
    import json

    click.echo(json.dumps(obj, allow_nan=False, default=_json_default))


def _json_default(o):
    import numpy as np

    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _clean_json(d, digits: int | None = None):
    """NaN and infinities become null; with ``digits``, floats keep that many significant digits."""
    import math

    if isinstance(d, dict):
        return {k: _clean_json(v, digits) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [_clean_json(v, digits) for v in d]
    if isinstance(d, float) and not math.isfinite(d):
        return None
    if isinstance(d, float) and digits is not None:
        return float(f"{d:.{digits}g}")
    return d


video_options = [
    click.option("--fps", type=click.FloatRange(min=0, min_open=True),
                 help="Frame rate of image folders (they carry none); for a video file it replaces the rate "
                      "the file reports."),
    click.option("--start", type=click.IntRange(min=0), help="First frame (inclusive)."),
    click.option("--end", type=click.IntRange(min=1), help="Last frame (exclusive)."),
    click.option("--step", type=click.IntRange(min=1), help="Use every STEP-th frame."),
]


def with_video_options(f):
    for opt in reversed(video_options):
        f = opt(f)
    return f


def _video_overrides(fps, start, end, step) -> dict:
    return {"video.fps": fps, "video.start": start, "video.end": end, "video.step": step}


# ---------------------------------------------------------------------------------------------
# track


@cli.command("track")
@click.argument("clips", nargs=-1, required=True, type=click.Path())
@click.option("-c", "--config", type=click.Path(dir_okay=False),
              help="Configuration file (YAML) or preset name (`trackcli config list`).")
@click.option("--model", type=click.Path(dir_okay=False),
              help="Model learned by `trackcli learn`, or a mixed-state model (kind: trackcli-mixed: a motion "
                   "label per sample, p_<label> columns; see the README).")
@click.option("--template", type=click.Path(dir_okay=False),
              help="Template drawn on this clip: the initial placement (with --model) or, alone, "
                   "the shape to track with hand-set dynamics.")
@click.option("--tracker", type=click.Choice(list(TRACKERS)), default="condensation", show_default=True,
              help="CONDENSATION (particle filter, robust to clutter), the Kalman contour tracker, mht "
                   "(a few Gaussian modes refined by Gauss-Newton steps; settings in mht:), or coupled (a centre "
                   "and rays to parts matched by NCC; needs a structure template from draw --parts; settings in "
                   "coupled:).")
@click.option("--particles", type=click.IntRange(min=1), help="CONDENSATION sample-set size N (condensation.particles, default 500).")
@click.option("--threads", type=click.IntRange(min=0, max=256),
              help="Threads that score CONDENSATION's samples (condensation.threads; 0 = every core from 300 "
                   "samples up with the discriminant, 2000 with the numpy models, one below). The results "
                   "do not depend on it.")
@click.option("--seed", type=click.IntRange(min=0), help="Random seed (same seed, same numbers).")
@click.option("-o", "--outdir", type=click.Path(file_okay=False), default="trackcli-out", show_default=True,
              help="Folder for the outputs.")
@click.option("--smooth", is_flag=True,
              help="Also write smoothed estimates, CLIP.TRACKER.smoothed.csv, and draw them in the recording: "
                   "Kalman: Rauch-Tung-Striebel; CONDENSATION: forward-filtering backward-smoothing of the "
                   "sample weights; both over the whole clip, after tracking it.")
@click.option("--no-rrd", is_flag=True, help="Do not write Rerun recordings.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON summary line per clip on stdout.")
@with_video_options
@click.pass_context
def track_cmd(ctx, clips, config, model, template, tracker, particles, threads, seed, outdir, smooth, no_rrd, as_json, fps,
              start, end, step):
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
    and one summary line on stdout.  With several CLIPS, a clip that fails is reported
    on stderr and the others still run; the exit code is then 1.

    Every frame gets a confidence (0-1) that the estimate is on the object, from the
    contour discriminant and the colour learned on the first frame; a frame is lost
    when it is below 0.5, and the summary line counts those frames.  While lost,
    CONDENSATION also looks for object-coloured regions in a square around where the
    object was last held, growing with the time lost (condensation.reacquire_speed; 0:
    the whole frame), and picks the object up again when it shows (condensation.reacquire).
    """
    from trackcli.dynamics.model import load_model
    from trackcli.run.clips import clip_json, clip_name, track_clip
    from trackcli.shapes.template import load_template

    if not model and not template:
        raise click.UsageError("give --model, --template, or both")
    overrides = {"condensation.particles": particles, "condensation.threads": threads, "seed": seed, **_video_overrides(fps, start, end, step)}
    settings = _settings(config, overrides)
    explicit = _explicit_keys(config, overrides) if model else None
    given = [f"{k}={v}" for k, v in overrides.items() if v is not None]
    log.info("settings: %s%s%s", f"config {config}" if config else "the defaults",
             f", options {', '.join(given)}" if given else "", f"; dynamics and shape-space from model {model}"
             if model else "")
    stems = [clip_name(c) for c in clips]
    if len(set(stems)) != len(stems):
        raise click.UsageError("two clips have the same name; run them into different --outdir folders")
    # files shared by every clip are checked once, before any clip runs
    if model:
        from trackcli.dynamics.mixed import is_mixed_file, load_mixed

        load_mixed(model) if is_mixed_file(model) else load_model(model)
    if template:
        load_template(template)
    failures = 0
    for clip, stem in zip(clips, stems):
        try:
            summary = track_clip(clip, settings=settings, outdir=outdir, model=model, template=template,
                                 tracker=tracker, name=stem, rrd=not no_rrd, smooth=smooth,
                                 progress=lambda label, n: _progress(ctx, n, label), explicit=explicit,
                                 inputs={"-c/--config": config})
        except TrackcliError as exc:
            if len(clips) == 1:
                raise
            failures += 1
            message = str(exc)
            message = message if message.startswith(str(clip)) else f"{clip}: {message}"
            click.echo(f"Error: {message}", err=True)
            if as_json:
                _echo_json(clip_json(stem, clip, tracker, error=message))
            continue
        if as_json:
            _echo_json(_clean_json(clip_json(stem, clip, tracker, summary), digits=6))
        else:
            click.echo(summary.line())
    if failures:
        click.echo(f"{failures} of {len(clips)} clips failed", err=True)
    ctx.exit(1 if failures else 0)


# ---------------------------------------------------------------------------------------------
# learn


@cli.command("learn")
@click.argument("clips", nargs=-1, type=click.Path())
@click.option("-c", "--config", type=click.Path(dir_okay=False),
              help="Configuration file (YAML) or preset name (`trackcli config list`).")
@click.option("--template", type=click.Path(dir_okay=False), required=True,
              help="Template drawn on the (first) training clip.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), required=True, help="Model file to write (.yaml).")
@click.option("--cycles", type=click.IntRange(min=1, max=50), help="Track-learn cycles (learning.cycles, default 2).")
@click.option("--shape-space", "shape_space", help="translation, similarity, affine, or pca:K (residual PCA "
              "on top of translation, learned from the tracked outlines). Default: the config's shape_space.")
@click.option("--from-tracks", "from_tracks", multiple=True, type=click.Path(dir_okay=False),
              help="Learn from track CSVs already made instead of tracking CLIPS (repeatable).")
@click.option("--tracks-fps", type=click.FloatRange(min=0, min_open=True),
              help="Frame rate of the clips behind --from-tracks (default: the template clip's, else 25).")
@click.option("--outdir", type=click.Path(file_okay=False),
              help="Folder for the per-cycle tracks and recordings (default: beside the model, MODEL_training/).")
@click.option("--method", type=click.Choice(["mle", "em"]), default="mle", show_default=True,
              help="mle: maximum likelihood on the tracked shapes (AC Fig 11.6); em: expectation-maximisation "
                   "on the measurements behind them (each frame's aggregated normals, or with --from-tracks "
                   "each shape with its reported std), settings em.tolerance and em.max_iterations.")
@click.option("--labels", "label_files", multiple=True, type=click.Path(dir_okay=False),
              help="Labelled frame ranges (CSV or YAML of start,end,label; frames inclusive), one file per CLIP or "
                   "--from-tracks track in order: writes a mixed-state model with one AR(2) per label and the "
                   "transition matrix counted from the labels.")
@click.option("--no-rrd", is_flag=True, help="Do not write recordings of the training tracks.")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary on stdout.")
@with_video_options
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
    from pathlib import Path

    from trackcli.settings import dump_yaml
    from trackcli.dynamics.model import save_model
    from trackcli.io.outputs import output_dir, refuse_overwriting_inputs, write_text
    from trackcli.run.clips import check_template_frame, template_space
    from trackcli.shapes.template import load_template
    from trackcli.run.train import learn_from_tracks, parse_shape_space, read_labels, train
    from trackcli.errors import DataError

    settings = _settings(config, {"learning.cycles": cycles, **_video_overrides(fps, start, end, step)})
    tmpl = load_template(template)
    # labelled ranges are checked before anything is tracked
    ranges = read_labels(label_files, len(from_tracks or clips)) if label_files else None
    out_model = Path(output)
    inputs = {"--template": template, "-c/--config": config,
              **{f"--from-tracks {t}": t for t in from_tracks}, **{f"CLIP {c}": c for c in clips}}
    if from_tracks:
        if clips:
            raise click.UsageError("give training CLIPS or --from-tracks, not both")
        refuse_overwriting_inputs({"-o/--output": out_model}, inputs)
        rate = tracks_fps or settings.video.fps or 25.0
        model = learn_from_tracks(from_tracks, tmpl, settings, 1.0 / rate, shape_space, method)
        if label_files:
            mixed = _learn_labelled(from_tracks, label_files, ranges, model, 1.0 / rate, settings,
                                    {"tracks": list(from_tracks)})
            _save_labelled(mixed, out_model, as_json)
            return
        save_model(out_model, model)
        _learn_report(model, [], out_model, as_json)
        return
    if not clips:
        raise click.UsageError("give at least one training CLIP (or --from-tracks)")
    kind, _ = parse_shape_space(shape_space, settings.shape_space)
    template_space(tmpl, template, "affine" if kind == "pca" else kind)  # a degenerate outline names its file
    work = Path(outdir or out_model.with_name(out_model.stem + "_training"))
    refuse_overwriting_inputs({"-o/--output": out_model, "the training configuration": work / "config.yaml"}, inputs)
    videos = []
    try:
        for c in clips:
            videos.append(_open(c, settings))
        for v in videos:
            check_template_frame(tmpl, v)

        def bar(label, n):
            return _progress(ctx, n, label)

        with output_dir(work):
            try:
                model, records = train(videos, tmpl, settings, cycles=settings.learning.cycles,
                                       shape_space=shape_space, outdir=work, write_rrd=not no_rrd, progress=bar,
                                       method=method)
            except DataError as exc:  # the tracks that could not be learned from are kept to look at
                kept = sorted(p.name for p in work.glob("*.csv"))
                if not kept:
                    raise
                raise DataError(f"{exc} (the training tracks, {', '.join(kept)}, are kept in {work})") from None
            if label_files:
                tracks = [str(r.csv) for r in records[-1].runs]
                mixed = _learn_labelled(tracks, label_files, ranges, model, 1.0 / videos[0].fps, settings,
                                        {"clips": list(clips), "cycles": settings.learning.cycles})
            # written with the results: a run that fails leaves no configuration behind
            write_text(work / "config.yaml", dump_yaml(settings))
            if label_files:
                _save_labelled(mixed, out_model, as_json)
                return
            save_model(out_model, model)
    finally:
        for v in videos:
            v.close()
    _learn_report(model, records, out_model, as_json)


def _learn_labelled(tracks, label_files, ranges, model, tau, settings, provenance):
    """``learn --labels``: the mixed-state model from the final tracks (:func:`trackcli.run.train.learn_labelled`)."""
    from trackcli.run.train import learn_labelled

    return learn_labelled(tracks, label_files, model.template, model.space, tau, settings, provenance, ranges=ranges)


def _save_labelled(mixed, out_model, as_json) -> None:
    from trackcli.dynamics.mixed import save_mixed

    save_mixed(out_model, mixed)
    rep = mixed.provenance.get("mixed_learning", {})
    if as_json:
        _echo_json(_clean_json({"model": str(out_model), "kind": "mixed-state", "labels": mixed.names,
                                "transitions": mixed.T.tolist(), "learning": rep}))
        return
    click.echo(f"wrote mixed-state model {out_model}: labels {', '.join(mixed.names)}")
    for name, r in rep.get("labels", {}).items():
        click.echo(f"  {name}: {r['triples']} frame triples from {r['runs']} run(s), residual RMS "
                   f"{r['residual_rms']:.3g}, spectral radius {r['spectral_radius']:.4f}")
    click.echo("  transitions: " + "; ".join(f"{n} -> " + ", ".join(f"{v:.3f}" for v in row)
                                             for n, row in zip(mixed.names, mixed.T)))


def _learn_report(model, records, path, as_json: bool) -> None:
    rep = model.provenance.get("learning", {})
    cycles = [{"cycle": r.cycle, "seconds": round(r.seconds, 3),
               "clips": [{"clip": s.clip, "frames": s.frames, "lost": s.frames_lost,
                          "seconds": round(s.wall_seconds, 3)} for s in r.runs]} for r in records]
    if as_json:
        _echo_json(_clean_json({"model": str(path), "cycles": cycles, "learning": rep,
                                "modes": [_mode_dict(m, model.space.H) for m in model.dynamics.modes()]}))
        return
    for c in cycles:
        per = ", ".join(f"{Path_name(x['clip'])} {x['seconds']:.1f} s ({x['frames']} frames, {x['lost']} lost)"
                        for x in c["clips"])
        click.echo(f"cycle {c['cycle']}: {c['seconds']:.1f} s: {per}")
    for r in records:
        if "em" in r.report:
            click.echo(f"cycle {r.cycle}: {_em_line(r.report['em'])}")
    if not records and "em" in rep:
        click.echo(_em_line(rep["em"]))
    rho = rep.get("spectral_radius")
    click.echo(f"wrote {path}: {model.space.kind} shape-space ({model.space.Nx} components), "
               f"spectral radius {rho if rho is None else round(rho, 4)}; see `trackcli inspect {path}`")


def _em_line(em: dict) -> str:
    path = em["log_likelihood"]
    state = "converged" if em["converged"] else "not converged (em.max_iterations)"
    return (f"EM {em['iterations']} iteration(s), {state}; log-likelihood of the measurements "
            f"{path[0]:.1f} -> {path[-1]:.1f}")


def Path_name(p: str) -> str:
    from pathlib import Path

    return Path(p).name


def _mode_dict(m, H=None) -> dict:
    return {"eigenvalue_modulus": m.modulus, "damping_per_s": m.beta, "frequency_hz": m.frequency,
            "decay_time_s": m.decay_time, "period_s": m.period, "stable": m.stable,
            "dominant": [[int(i), float(w)] for i, w in m.dominant(3, H)]}


# ---------------------------------------------------------------------------------------------
# inspect and simulate


@cli.command("inspect")
@click.argument("model_path", metavar="MODEL", type=click.Path(dir_okay=False))
@click.option("--template", type=click.Path(dir_okay=False),
              help="Show the model placed by this template, as `track --model MODEL --template T` uses it "
                   "on the clip where T was drawn.")
@click.option("-c", "--config", type=click.Path(dir_okay=False),
              help="Configuration whose placement settings apply, as for `track -c` (default: the defaults).")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True),
              help="Frame rate of the clip where T was drawn (default: the model's).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def inspect_cmd(model_path, template, config, fps, as_json):
    """Show a model: shape-space, dynamics, modes (AC eqs 11.10-11.13), steady-state spread.

    \b
    With --template T: the model placed where (and at the size) T was drawn, as tracking
    that clip uses it: its mean, stability and modes, next to the learned spectral
    radius.  The placement settings (noise factors, coupling) are those of -c CONFIG, as
    for `track`.

    A mixed-state model (kind: trackcli-mixed) is shown label by label: each label's model
    and modes (a hand-written one needs --template for the modes), the transition matrix,
    the mean stay in each label and the initial distribution.
    """
    import numpy as np

    from trackcli.dynamics.mixed import is_mixed_file
    from trackcli.dynamics.model import load_model, place_dynamics, place_space
    from trackcli.shapes.template import load_template

    if is_mixed_file(model_path):
        _inspect_mixed(model_path, template, config, fps, as_json)
        return
    m = load_model(model_path)
    dyn, space = m.dynamics, m.space
    placement = None
    if template:
        tmpl = load_template(template)
        settings = _settings(config, {})
        space, X0 = place_space(m.space, tmpl)
        report: list = []
        tau = 1.0 / fps if fps else m.dynamics.tau
        p = settings.placement
        dyn = place_dynamics(m.dynamics, space, X0, tau, translation_noise=p.translation_noise,
                             deformation_noise=p.deformation_noise, coupling=p.coupling,
                             max_spectral_radius=settings.learning.max_spectral_radius, report=report)
        r = report[0]
        placement = {"template": str(template), "scale": r.scale, "coupling": r.coupling,
                     "translation_noise": p.translation_noise, "deformation_noise": p.deformation_noise,
                     "learned_spectral_radius": r.learned_radius, "spectral_radius": r.radius,
                     "restabilised": r.restabilised, "limit": r.limit,
                     "centroid": [float(v) for v in space.origin]}
    try:
        rms = dyn.rms_displacement(space.H)
        Es = space.translation_projector()
        rms_t = dyn.rms_displacement(space.H, Es)
        rms_d = dyn.rms_displacement(space.H, np.eye(space.Nx) - Es)
    except Exception:  # unstable or constant-velocity models have no steady state
        rms = rms_t = rms_d = None
    modes = dyn.modes()
    names = list(space.names)
    info = {
        "model": str(model_path),
        "shape_space": {"kind": space.kind, "components": names, "control_points": space.Nq,
                        "degree": space.basis.degree, "closed": space.basis.closed},
        "frame_interval_s": dyn.tau,
        "spectral_radius": dyn.spectral_radius(),
        "stable": dyn.is_stable(),
        "mean": dict(zip(names, map(float, dyn.mean))),
        "steady_state_rms_px": {"total": rms, "translation": rms_t, "deformation": rms_d},
        "A1": dyn.A1.tolist(), "A2": dyn.A2.tolist(), "B0": dyn.B0.tolist(),
        "modes": [_mode_dict(x, space.H) for x in modes],
        "provenance": m.provenance,
    }
    if placement is not None:
        info["placement"] = placement
    if as_json:
        _echo_json(_clean_json(info))
        return
    fmt = lambda v: "n/a" if v is None else f"{v:.2f}"  # noqa: E731
    click.echo(f"model {model_path}" + (f", placed by template {template}" if placement else ""))
    if placement is not None:
        click.echo(f"  placement     centroid ({placement['centroid'][0]:.1f}, {placement['centroid'][1]:.1f}) px, "
                   f"size {placement['scale']:.3f} x the model's template, coupling {placement['coupling']}, "
                   f"noise factors {placement['translation_noise']:g} (translation), "
                   f"{placement['deformation_noise']:g} (rest)")
        click.echo(f"                spectral radius {placement['learned_spectral_radius']:.4f} learned -> "
                   f"{placement['spectral_radius']:.4f} placed"
                   + (f" (re-stabilised: modes pulled in to {placement['limit']:.4f})" if placement["restabilised"] else ""))
    click.echo(f"  shape-space   {space.kind}: {', '.join(names)} ({space.Nq} control points, degree "
               f"{space.basis.degree}, {'closed' if space.basis.closed else 'open'})")
    click.echo(f"  frame interval {dyn.tau:.4g} s ({1 / dyn.tau:.3g} frames/s)")
    click.echo(f"  stability     spectral radius {dyn.spectral_radius():.4f} ({dyn.stability()})")
    click.echo(f"  steady-state RMS displacement: total {fmt(rms)} px, translation {fmt(rms_t)} px, "
               f"deformation {fmt(rms_d)} px")
    click.echo("  mean X         " + ", ".join(f"{n}={v:.4g}" for n, v in zip(names, dyn.mean)))
    click.echo("  modes (slowest first):")
    for row in _mode_rows(modes, space):
        click.echo(row)
    prov = m.provenance
    if prov:
        src = prov.get("clips") or prov.get("tracks") or []
        click.echo(f"  learned from  {', '.join(map(str, src))} ({prov.get('cycles', 0)} cycle(s))")


def _mode_rows(modes, space) -> list[str]:
    """The table of ``modes`` (AR2.modes()) that ``inspect`` prints, a line each, header first."""
    import numpy as np

    names = list(space.names)
    rows = ["    |lambda|  damping(1/s)  freq(Hz)  decay(s)  period(s)  dominant components"]
    for x in modes:
        dom = ", ".join(f"{names[i]} {w:.2f}" for i, w in x.dominant(3, space.H))
        per = f"{x.period:9.3f}" if np.isfinite(x.period) else "        -"
        dec = f"{x.decay_time:8.3f}" if np.isfinite(x.decay_time) else "     inf"
        rows.append(f"    {x.modulus:8.4f}  {x.beta:12.3f}  {x.frequency:8.3f}  {dec}  {per}  {dom}"
                    + ("" if x.stable else "  no decay" if x.modulus == 1.0 else "  UNSTABLE"))
    return rows


def _mixed_dynamics_for(mm, template, config, fps):
    """The mixed model's labels on a shape-space (the template's, or the model's own), or
    ``(None, None)`` for a hand-written model without a template."""
    from trackcli.run.clips import mixed_dynamics_on
    from trackcli.shapes.template import load_template

    if not template and mm.space is None:
        return None, None
    tmpl = load_template(template) if template else None
    learned = [lab.ar2.tau for lab in mm.labels if lab.ar2 is not None]
    rate = fps or (1.0 / learned[0] if learned else _clip_fps(tmpl.clip if tmpl is not None else None) or 25.0)
    space, dynamics, _ = mixed_dynamics_on(mm, tmpl, template, _settings(config, {}), 1.0 / rate)
    return dynamics, space


def _clip_fps(clip) -> float | None:
    """The frame rate of the clip a template was drawn on, when it can be opened here."""
    from trackcli.io.video import open_video

    if not clip:
        return None
    try:
        with open_video(clip) as v:
            return float(v.fps)
    except Exception:  # the clip moved or is not readable here: the caller falls back
        return None


def _inspect_mixed(model_path, template, config, fps, as_json: bool) -> None:
    """``inspect`` of a mixed-state model: every label's model (and modes), T, the label durations."""
    import numpy as np

    from trackcli.dynamics.ar2 import AR2
    from trackcli.dynamics.mixed import load_mixed

    mm = load_mixed(model_path)
    dyn, space = _mixed_dynamics_for(mm, template, config, fps)
    T = mm.T
    stay = np.diag(T)
    durations = [None if s >= 1 else float(1.0 / (1.0 - s)) for s in stay]
    labels = []
    for i, lab in enumerate(mm.labels):
        d: dict = {"name": lab.name, "kind": lab.kind, "mean_duration_frames": durations[i]}
        if lab.bounce is not None:
            d["bounce"] = lab.bounce.to_dict()
            if dyn is not None:
                d["bounce"]["contact_px"] = float(dyn.models[i].contact)
        elif lab.handset is not None:
            d["dynamics"] = lab.handset_raw
        if dyn is not None and isinstance(dyn.models[i], AR2):
            ar = dyn.models[i]
            d["spectral_radius"] = ar.spectral_radius()
            d["modes"] = [_mode_dict(x, space.H) for x in ar.modes()]
        labels.append(d)
    info = {"model": str(model_path), "kind": "mixed-state", "labels": labels, "transitions": T.tolist(),
            "initial": mm.initial_distribution().tolist(),
            "initial_source": "given" if mm.initial is not None else "stationary distribution of T",
            "provenance": mm.provenance}
    if space is not None:
        info["shape_space"] = {"kind": space.kind, "components": list(space.names)}
        info["frame_interval_s"] = dyn.tau
    if as_json:
        _echo_json(_clean_json(info))
        return
    names = mm.names
    click.echo(f"mixed-state model {model_path}: {len(names)} labels ({', '.join(names)})"
               + (f", on template {template}" if template else ""))
    if space is not None:
        click.echo(f"  shape-space   {space.kind}: {', '.join(space.names)}; frame interval {dyn.tau:.4g} s")
    width = max(len(n) for n in names)
    click.echo("  transitions T[i, j] = P(next label j | label i):")
    click.echo("    " + " " * width + "  " + "  ".join(f"{n:>{max(width, 6)}}" for n in names))
    for n, row in zip(names, T):
        click.echo(f"    {n:>{width}}  " + "  ".join(f"{v:>{max(width, 6)}.4f}" for v in row))
    init = mm.initial_distribution()
    click.echo("  initial       " + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, init))
               + ("" if mm.initial is not None else " (stationary distribution of T)"))
    for i, lab in enumerate(mm.labels):
        dur = "stays for good" if durations[i] is None else f"mean stay {durations[i]:.3g} frame(s)"
        click.echo(f"  label {lab.name} ({lab.kind}; {dur})")
        if lab.bounce is not None:
            b = lab.bounce
            line = (f"floor y = {b.point[1]:g} px" if b.normal == (0.0, -1.0)
                    else f"line through ({b.point[0]:g}, {b.point[1]:g}) with normal ({b.normal[0]:.3g}, {b.normal[1]:.3g})")
            contact = f", outline reaches {dyn.models[i].contact:.1f} px from its centre towards it" if dyn else ""
            click.echo(f"    bounce on the {line}{contact}; restitution {b.restitution:g}, friction {b.friction:g}, "
                       f"rebound noise {b.noise:g} x the impact speed; other components move as {b.base}")
            continue
        if lab.handset is not None:
            click.echo(f"    hand-set: {lab.handset_raw}")
        if dyn is None:
            click.echo("    (give --template to see its modes on a template's shape-space)")
            continue
        ar = dyn.models[i]
        click.echo(f"    spectral radius {ar.spectral_radius():.4f}; modes (slowest first):")
        for row in _mode_rows(ar.modes(), space):
            click.echo("  " + row)


@cli.command("simulate")
@click.argument("model_path", metavar="MODEL", type=click.Path(dir_okay=False))
@click.option("--frames", "n_frames", type=click.IntRange(min=2, max=1_000_000), default=250, show_default=True,
              help="Length of each sample path.")
@click.option("--paths", "n_paths", type=click.IntRange(min=1, max=20), default=3, show_default=True,
              help="Number of sample paths.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), help="Recording (.rrd) to write "
              "(default: MODEL_sim.rrd); a PNG of the trajectories is written beside it.")
@click.option("--size", help="Canvas 'W,H' for the PNG (default: the template's frame size).")
@click.option("--template", type=click.Path(dir_okay=False),
              help="Mixed-state model: the template whose shape-space its labels move (needed by a hand-written "
                   "model, which has none of its own).")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True),
              help="Mixed-state model: frame rate the hand-set labels are built for (default: the template's clip's, "
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
    from pathlib import Path

    import numpy as np

    from trackcli.dynamics.model import load_model
    from trackcli.dynamics.simulate import render_paths, simulate_paths, record_paths

    from trackcli.io.outputs import atomic_paths, output_dir, refuse_overwriting_inputs

    from trackcli.dynamics.mixed import is_mixed_file

    out = Path(output) if output else Path(model_path).with_name(Path(model_path).stem + "_sim.rrd")
    refuse_overwriting_inputs({"-o/--output": out, "the PNG": out.with_suffix(".png")}, {"MODEL": model_path})
    if is_mixed_file(model_path):
        _simulate_mixed(model_path, template, fps, n_frames, n_paths, seed, out, size)
        return
    if template or fps:
        raise click.UsageError("--template and --fps apply to mixed-state models only")
    m = load_model(model_path)
    canvas = _canvas_size(size)
    paths = simulate_paths(m, n_frames, n_paths, np.random.default_rng(seed))
    png = out.with_suffix(".png")
    with output_dir(out.parent), atomic_paths(png, out) as (png_tmp, out_tmp):  # both outputs or none
        render_paths(m, paths, png_tmp, canvas=canvas)
        record_paths(m, paths, out_tmp, seed=seed)
    click.echo(f"wrote {out} and {png} ({n_paths} paths of {n_frames} frames)")


def _canvas_size(size: str | None) -> tuple[int, int] | None:
    """``--size 'W,H'`` of simulate's PNG, checked (None: the template's frame size)."""
    if not size:
        return None
    from trackcli.errors import ConfigError
    from trackcli.shapes.draw import parse_numbers

    w, h = parse_numbers(size, 2, "--size")
    if not all(float(v).is_integer() and 16 <= v <= 16384 for v in (w, h)):
        raise ConfigError(f"--size: expected a width and height in whole pixels from 16 to 16384, got {size!r}")
    return int(w), int(h)


def _simulate_mixed(model_path, template, fps, n_frames, n_paths, seed, out, size) -> None:
    from types import SimpleNamespace

    import numpy as np

    from trackcli.dynamics.mixed import load_mixed
    from trackcli.dynamics.simulate import record_paths, render_paths
    from trackcli.io.outputs import atomic_paths, output_dir
    from trackcli.shapes.template import load_template

    mm = load_mixed(model_path)
    dyn, space = _mixed_dynamics_for(mm, template, None, fps)
    if dyn is None:
        raise click.UsageError(f"{model_path} is a hand-written mixed-state model: give --template")
    tmpl = load_template(template) if template else mm.template
    canvas = _canvas_size(size)
    rng = np.random.default_rng(seed)
    sims = [dyn.simulate(n_frames, rng) for _ in range(n_paths)]
    paths = np.stack([p for p, _ in sims])
    labels = np.stack([lab for _, lab in sims])
    events = [i for i, lab in enumerate(mm.labels) if lab.bounce is not None]
    marks = [np.flatnonzero(np.isin(lab, events)) for lab in labels]
    view = SimpleNamespace(space=space, template=tmpl, dynamics=SimpleNamespace(tau=dyn.tau),
                           provenance={"mixed_state_model": str(model_path), "labels": mm.names, **mm.provenance})
    png = out.with_suffix(".png")
    with output_dir(out.parent), atomic_paths(png, out) as (png_tmp, out_tmp):  # both outputs or none
        render_paths(view, paths, png_tmp, canvas=canvas, marks=marks)
        record_paths(view, paths, out_tmp, seed=seed, labels=labels, label_names=mm.names)
    switches = int(sum((np.diff(lab) != 0).sum() for lab in labels))
    visits = ", ".join(f"{n} {float((labels == i).mean()):.0%}" for i, n in enumerate(mm.names))
    click.echo(f"wrote {out} and {png} ({n_paths} paths of {n_frames} frames; {switches} label switches; "
               f"frames by label: {visits})")


# ---------------------------------------------------------------------------------------------
# eval


@cli.command("eval")
@click.argument("tracks", nargs=-1, required=True, type=click.Path(dir_okay=False), metavar="PRED...")
@click.argument("truth", type=click.Path())
@click.option("--threshold", type=click.FloatRange(min=0, min_open=True), default=20.0, show_default=True,
              help="Centre-error threshold (px) for precision.")
@click.option("--lost-threshold", type=click.FloatRange(min=0, min_open=True),
              help="Also count a frame lost when its centre error exceeds this (px).")
@click.option("--object", "object_id", type=click.IntRange(min=0), default=0, show_default=True,
              help="Object id in a trackcli truth CSV with several objects.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Write the precision plot (0-50 px) and the success plot (IoU 0-1) of all PRED to this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the scores as one JSON object per PRED.")
@click.pass_context
def eval_cmd(ctx, tracks, truth, threshold, lost_threshold, object_id, plot_path, as_json):
    """Score estimates PRED (one or more track CSVs) against ground truth TRUTH.

    TRUTH is a trackcli truth CSV (sample_data/*.truth.csv), a benchmark box file (one
    'x,y,w,h' line per frame, comma or whitespace separated; VOT's 8-number polygons are
    scored by the rectangle around them), or a folder holding
    groundtruth_rect.txt / groundtruth.txt.  Frames are matched by index; when a track and
    the truth cover different frames, a warning says which frames were scored.

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
    """
    from trackcli.run.evaluate import coverage_notes, format_table, load_track, load_truth, score_frames, summarise

    quiet = bool(ctx.find_root().obj and ctx.find_root().obj.get("quiet"))
    if plot_path:
        from trackcli.io.outputs import refuse_overwriting_inputs

        refuse_overwriting_inputs({"--plot": plot_path},
                                  {"TRUTH": truth, **{f"PRED {k + 1}": t for k, t in enumerate(tracks)}})
    gt = load_truth(truth, object_id=object_id)
    labels = None
    if plot_path or len(tracks) > 1:
        from trackcli.run.plots import track_labels

        labels = track_labels(tracks)
    curves = []
    for k, path in enumerate(tracks):
        pred = load_track(path)
        scores = score_frames(pred, gt, lost_threshold=lost_threshold)
        result = summarise(scores, threshold=threshold)
        notes = coverage_notes(pred, gt, scores)
        if notes and not quiet:
            click.echo(f"Warning: {'; '.join(notes)}", err=True)
        if plot_path:
            from trackcli.run.plots import curves as make_curves

            curves.append(make_curves(labels[k], scores, threshold))
        if as_json:
            _echo_json(_clean_json({"kind": "eval", "track": str(path), "truth": str(truth), **result.to_dict(),
                                    "warnings": notes}, digits=6))
        else:
            if len(tracks) > 1:
                click.echo(("\n" if k else "") + f"== {labels[k]} ({path})")
            click.echo(format_table(result))
    if plot_path:
        from trackcli.run.plots import write_plots

        out = write_plots(plot_path, curves, threshold=threshold)
        if not as_json:
            click.echo(f"wrote {out}")


# ---------------------------------------------------------------------------------------------
# render


@cli.command("render")
@click.argument("track", type=click.Path(dir_okay=False))
@click.argument("clip", type=click.Path())
@click.option("-o", "--output", type=click.Path(),
              help="Output file or folder (default beside TRACK: NAME.mp4, NAME.sheet.png or NAME_frames/).")
@click.option("--sheet", "sheet", type=click.IntRange(min=1, max=400),
              help="Write a contact sheet (PNG) of this many frames spread over the selection, instead of a video.")
@click.option("--png", "png", is_flag=True, help="Write one PNG per frame into a folder, instead of a video.")
@click.option("--tile-width", type=click.IntRange(min=32, max=4000), default=240, show_default=True,
              help="Width of each contact-sheet frame (px; frames are only shrunk).")
@click.option("--truth", type=click.Path(), help="Ground truth (as for eval) whose box is drawn in green.")
@click.option("--object", "object_id", type=click.IntRange(min=0), default=0, show_default=True,
              help="Object id in a truth CSV with several objects.")
@click.option("--no-label", is_flag=True, help="No frame number, LOST or confidence text on the frames.")
@with_video_options
@click.pass_context
def render_cmd(ctx, track, clip, output, sheet, png, tile_width, truth, object_id, no_label, fps, start, end, step):
    """Draw the estimated outline of TRACK (a track CSV) on the frames of CLIP.

    CLIP is the video file or image folder that was tracked.  The outline comes from the
    CSV's outline columns, so no model or template is needed.  By default the frames of the
    track are drawn (--start/--end/--step select others) into an MP4 beside TRACK.  Lost
    frames show the outline dashed in grey; with --truth the true box is drawn in green.

    \b
    Examples:
      trackcli render out/test.condensation.csv sample_data/test.mp4
      trackcli render out/test.condensation.csv sample_data/test.mp4 --sheet 12 -o sheet.png
      trackcli render out/crossing.kalman.csv ../footage/crossing --png --truth ../footage/crossing
    """
    from trackcli.run.render import default_output, render

    if sheet and png:
        raise click.UsageError("give --sheet or --png, not both")
    kind = "sheet" if sheet else ("frames" if png else "video")
    out = output or default_output(track, kind)
    _refuse_rendering_over_inputs(Path(out), kind, track=track, clip=clip, truth=truth)
    gt = None
    if truth:
        from trackcli.run.evaluate import load_truth

        gt = load_truth(truth, object_id=object_id)
    bar_holder: dict = {}

    def opened(n: int) -> None:
        bar_holder["bar"] = _progress(ctx, n, "rendering").__enter__()

    try:
        result = render(track, clip, out, kind=kind, sheet_frames=sheet or 12, tile_width=tile_width, truth=gt,
                        fps=fps, start=start, end=end, step=step, label=not no_label,
                        progress=lambda k: bar_holder["bar"].update(k), on_open=opened)
    finally:
        if "bar" in bar_holder:
            bar_holder["bar"].__exit__(None, None, None)
    what = {"video": f"video ({result.codec})", "frames": "PNG frames", "sheet": "contact sheet"}[kind]
    click.echo(f"wrote {result.output}: {what} of {result.frames} frames, {result.with_estimate} with an estimate")


def _refuse_rendering_over_inputs(out: Path, kind: str, *, track: str, clip: str, truth: str | None) -> None:
    """One-line errors for a render output that would write over its inputs or into the
    image folder it reads (where a new image would become a frame of the clip)."""
    from trackcli.errors import ConfigError
    from trackcli.io.outputs import refuse_overwriting_inputs
    from trackcli.io.video import IMAGE_SUFFIXES
    from trackcli.run.render import VIDEO_SUFFIXES

    refuse_overwriting_inputs({"-o/--output": out}, {"TRACK": track, "CLIP": clip, "--truth": truth})
    if kind == "sheet" and out.suffix.lower() != ".png":
        raise click.UsageError(f"--sheet writes a PNG image; give an output name ending in .png, not {out.name!r}")
    if kind == "video" and out.suffix.lower() not in VIDEO_SUFFIXES and not out.is_dir():
        raise click.UsageError(f"a video's name ends in {', '.join(VIDEO_SUFFIXES[:-1])} or {VIDEO_SUFFIXES[-1]}, "
                               f"not {out.name!r} (--png writes a folder of frames, --sheet N one PNG image)")
    folder = Path(clip)
    if not folder.is_dir():
        return
    frame_folders = [folder, folder / "img"]
    target = out if kind == "frames" else out.parent
    for f in frame_folders:
        with contextlib.suppress(OSError):
            if f.is_dir() and target.exists() and os.path.samefile(target, f) and (
                    kind == "frames" or out.suffix.lower() in IMAGE_SUFFIXES):
                raise ConfigError(f"{out}: would write images into the frames folder of CLIP ({f}); "
                                  "choose another output")


# ---------------------------------------------------------------------------------------------
# view


@cli.command("view")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("--web", is_flag=True, help="Serve the web viewer over HTTP instead (for machines without a screen); "
              "open the printed address in a browser.")
@click.option("--port", type=click.IntRange(min=1, max=65535), help="Port of the web viewer (with --web).")
def view_cmd(recording, web, port):
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
    ctx = click.get_current_context()
    ctx.exit(run_viewer(cmd))


# ---------------------------------------------------------------------------------------------
# sample data


@cli.command("sample-data")
@click.argument("outdir", type=click.Path(file_okay=False))
@click.option("--seed", type=click.IntRange(min=0), help="Random seed (default: the seed of the committed sample_data/).")
@click.option("--clip", "clips", multiple=True,
              type=click.Choice(["train", "test", "three_heads", "bouncing_ball"]),
              help="Generate only this clip (repeatable; default all).")
@click.option("--frames", "n_frames", type=click.IntRange(min=2), help="Shorter (or longer) clips, for quick tries.")
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
    kwargs = {"seed": sample_data.DEFAULT_SEED if seed is None else seed, "clips": chosen,
              "n_frames": n_frames, "truth_only": truth_only}
    total = sum(n_frames or sample_data.default_n_frames(c) for c in chosen)
    with _progress(ctx, 0 if truth_only else total, "rendering") as bar:
        paths = sample_data.generate(outdir, progress=lambda clip, i, n: bar.update(1), **kwargs)
    for p in paths:
        click.echo(str(p))


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


from trackcli.cli.batch import batch_cmd  # noqa: E402

cli.add_command(batch_cmd)

if __name__ == "__main__":  # pragma: no cover
    main()
