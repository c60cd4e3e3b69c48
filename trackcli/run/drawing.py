"""``trackcli draw``: a template made from one frame of a clip, written with its preview.

:func:`draw_template` takes the outline from ordered points, an ellipse, a box (segmented,
and for a clip confirmed on the frames that follow, :mod:`trackcli.run.confirm`) or a mask
image, fits the B-spline of :func:`trackcli.shapes.draw.fit_template`, and writes the
template, its PNG preview and optionally a recording, all or none.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, ContextManager, Sequence

log = logging.getLogger(__name__)

#: a part of a structure template: ``(name, (x, y, w, h))``
PartSpec = tuple[str, tuple[float, float, float, float]]


@dataclass(frozen=True)
class Drawn:
    """What :func:`draw_template` wrote: the template (and its object), the preview, the recording."""

    output: Path
    preview: Path
    rrd: str | None
    template: Any
    source: str


def parse_parts(specs: Sequence[str]) -> list[PartSpec]:
    """``--parts NAME:x,y,w,h`` values, each checked (:func:`trackcli.shapes.structure.parse_part`)."""
    from trackcli.shapes import structure

    return [structure.parse_part(p) for p in specs]


def ellipse_around_parts(specs: Sequence[PartSpec]) -> str:
    """The ``--ellipse`` around the parts' boxes: semi-axes 0.8 and 0.9 of their bounding box."""
    import numpy as np

    xy = np.array([[x, y, x + w, y + h] for _, (x, y, w, h) in specs])
    lo, hi = xy[:, :2].min(axis=0), xy[:, 2:].max(axis=0)
    c, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    return f"{c[0]:.2f},{c[1]:.2f},{1.6 * half[0]:.2f},{1.8 * half[1]:.2f}"


def fit_outline(outline: Any, n_ctrl: int | None, degree: int, size: tuple[int, int], **kw: Any) -> Any:
    """``draw``'s B-spline fit of ``outline`` (the written template and ``--box``'s trial ones alike):
    ``n_ctrl`` control points, or the default with more where the outline has detail."""
    from trackcli.shapes import draw

    return draw.fit_template(outline, n_ctrl or draw.DEFAULT_CTRL, degree=degree, frame_size=size,
                             detail_ctrl=None if n_ctrl else draw.DETAIL_CTRL, **kw)


def draw_template(clip: str, *, output: str, frame_index: int = 0, points: str | None = None,
                  ellipse: str | None = None, box: str | None = None, mask: str | None = None,
                  parts: Sequence[PartSpec] = (), n_ctrl: int | None = None, degree: int = 2,
                  open_curve: bool = False, fps: float | None = None, preview: str | None = None,
                  rrd: str | None = None, n_normals: int = 24,
                  progress: Callable[[str, int], ContextManager[Any]] | None = None) -> Drawn:
    """Make the template of the outline given by the one of ``points``, ``ellipse``, ``box`` or
    ``mask`` (the option's text) on frame ``frame_index`` of ``clip`` and write it to ``output``
    with its preview (default: ``output`` with ``.png``) and, with ``rrd``, a recording.

    ``parts`` (from :func:`parse_parts`) makes it a structure template: each part's box and
    grey patch are stored with it.  ``progress(label, n)`` (optional) returns a progress bar
    for the segmentation and the mask trials of ``box``.
    """
    import cv2

    from trackcli.io.outputs import atomic_paths, check_output_folders, output_dir, refuse_overwriting_inputs
    from trackcli.io.video import open_video
    from trackcli.run.clips import no_progress
    from trackcli.shapes import draw, structure
    from trackcli.shapes.template import save_template

    bar = progress or (lambda label, n: no_progress())
    out = Path(output)
    png = Path(preview) if preview else out.with_suffix(".png")
    points_file = points if points and Path(points).is_file() else None
    refuse_overwriting_inputs({"-o/--output": out, "--preview": png, "--rrd": rrd},
                              {"CLIP": clip, "--mask": mask, "--points": points_file})
    check_output_folders(out, png, rrd)
    # kept open until the outputs are written: --box reads on from the drawn frame to try its masks
    with open_video(clip, fps=fps) as video:
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
            with bar("segmenting the box", draw.segment_runs(frame.image)) as seg_bar:
                seg = draw.segment_candidates(frame.image, tuple(b), progress=seg_bar.update)
            mask_image, note = confirm_mask(seg, video, frame, lambda m: fit_outline(
                draw.mask_outline(m), n_ctrl, degree, size, _quiet=True), bar)
            outline = draw.mask_outline(mask_image)
            source = f"box {box} ({seg.method}{note})"
        else:
            outline = draw.mask_outline(draw.load_mask(mask, size))
            source = f"mask {mask}"
        template = fit_outline(outline, n_ctrl, degree, size, closed=not open_curve, clip=str(clip),
                               frame=frame_index, source=source)
        if box:
            template = dataclasses.replace(template, box=tuple(b))
        if parts:
            cut = structure.cut_parts(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), parts)
            template = dataclasses.replace(template, extra={**template.extra, "parts": structure.parts_to_yaml(cut)})
        vis = draw.render_preview(frame.image, template, n_normals=n_normals)
        for _, (x, y, w, h) in parts:
            cv2.rectangle(vis, (int(round(x)), int(round(y))), (int(round(x + w)), int(round(y + h))),
                          (0, 200, 255), 1)
        ok, buf = cv2.imencode(".png", vis)
        with output_dir(out.parent), output_dir(png.parent), output_dir(Path(rrd).parent if rrd else out.parent):
            with atomic_paths(out, png, *([rrd] if rrd else [])) as tmps:  # all outputs or none
                save_template(tmps[0], template)
                tmps[1].write_bytes(buf.tobytes())
                if rrd:
                    draw.record_template(tmps[2], frame.image, template, n_normals=n_normals)
    log.info("template %s (%d control points) from %s", out, template.n_ctrl, source)
    return Drawn(out, png, rrd, template, source)


def confirm_mask(seg: Any, video: Any, frame: Any, fit: Callable[[Any], Any],
                 progress: Callable[[str, int], ContextManager[Any]]) -> tuple[Any, str]:
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
    with progress(f"trying {len(order)} masks on the next frames", len(order)) as bar:
        best, trials = confirm.confirm(seg.masks, order, fit, frames, video.fps, progress=bar.update)
    for t in trials:
        log.info("mask %d of %d%s: over frames %d-%d, confidence %.3f, score %.1f (%.2f of the first frame's)",
                 t.index + 1, len(seg.masks), " (the frame's choice)" if t.index == seg.chosen else "",
                 frame.index + 1, frame.index + len(frames) - 1, t.confidence, t.score, t.held)
    if best == seg.chosen:
        return seg.mask, ""
    return seg.masks[best], f"; the mask the next {len(frames) - 1} frames held best"
