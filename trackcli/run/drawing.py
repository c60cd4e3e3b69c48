"""``trackcli draw``: a template made from one frame of a clip, written with its preview.

:func:`draw_template` takes the outline from ordered points or an ellipse
(:mod:`trackcli.shapes.draw`), a box (segmented by :mod:`trackcli.segment`, and for a clip
confirmed on the frames that follow, :mod:`trackcli.run.confirm`) or a mask image, and fits a
B-spline to it (:func:`fit_template`: without ``--n-ctrl`` with as many control points as the
outline needs, :func:`fit_covering`; falling back where the fit strays from the outline); it
writes the template, its PNG preview (:func:`render_preview`) and optionally a recording
(:func:`record_template`), all or none.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, ContextManager, Sequence

import numpy as np

from trackcli.segment.grabcut import LEAK_EXTENT
from trackcli.segment.masks import mask_outline
from trackcli.segment.motion import MOTION_FRAMES
from trackcli.shapes.draw import canonical_start, fit_error, polygon_mask, resample_polygon

log = logging.getLogger(__name__)

#: a fit that strayed from the outline is replaced by a fit without folds when that covers the
#: object (IoU with the outline) by at least this much more than the convex hull does; else
#: the hull is taken
REFIT_GAIN = 0.1
#: control points ``draw`` starts from when none are asked for, and the most it grows to
#: (:func:`fit_template` with ``detail_ctrl``)
DEFAULT_CTRL = 12
DETAIL_CTRL = 64
#: the control points grow (through :data:`CTRL_STEPS`) until the curve's IoU with the outline
#: reaches TARGET_IOU, or STALL_STEPS steps in a row each gain less than MIN_GAIN; of the fits
#: made, the one with the fewest control points within MIN_GAIN of the best is kept
TARGET_IOU = 0.95
MIN_GAIN = 0.005
STALL_STEPS = 2
CTRL_STEPS = (12, 16, 20, 24, 32, 40, 48, 64, 80, 96, 128)
#: a fit follows an outline resampled to one point per pixel of its length, within these bounds
FIT_POINTS = (256, 2000)


def fit_template(outline: np.ndarray, n_ctrl: int, *, degree: int = 2, closed: bool = True, clip: str | None = None,
                 frame: int = 0, frame_size: tuple[int, int] | None = None, source: str = "",
                 detail_ctrl: int | None = None, _quiet: bool = False):
    """Fit a B-spline to an ordered outline; return a Template.

    With ``detail_ctrl`` > ``n_ctrl`` (``draw`` without ``--n-ctrl``) a closed outline gets as
    many control points as it needs, from ``n_ctrl`` up to ``detail_ctrl``
    (:func:`fit_covering`).  Otherwise the curve has ``n_ctrl`` control points, and a fit that
    strays from the outline falls back (thin parts opened away, a refit without folds, the
    convex hull; see ``draw``).
    """
    from trackcli.shapes.fit import fit
    from trackcli.shapes.template import Template

    outline = np.asarray(outline, dtype=float)
    if closed:
        outline = canonical_start(outline)
    if len(outline) < n_ctrl:
        # too few points to pin every control point: resample the polygon densely first
        outline = resample_polygon(outline, max(4 * n_ctrl, 64), closed)

    def make(Q: np.ndarray, note: str = "") -> Template:
        n = len(Q) // 2
        return Template(np.column_stack([Q[:n], Q[n:]]), degree=degree, closed=closed, clip=clip,
                        frame=frame, frame_size=frame_size, source=source + note)

    # a trial fit (draw --box trying its masks) says nothing
    warn = log.warning if not _quiet else (lambda *args: None)
    if closed and detail_ctrl is not None and detail_ctrl > n_ctrl:
        cover = fit_covering(outline, n_ctrl, detail_ctrl, degree=degree)
        if not _quiet:
            log.info("%s", cover.describe())
        if cover.iou < TARGET_IOU:
            warn("the curve covers the outline to IoU %.2f only (%d control points; up to %d tried)",
                 cover.iou, cover.n_ctrl, cover.tried[-1][0])
        return make(cover.Q, cover.note())
    template = make(fit(outline, n_ctrl, degree=degree, closed=closed))
    if not (closed and len(outline) >= 3):
        return template
    import cv2

    from trackcli.run.evaluate import polygon_iou
    from trackcli.shapes.spline import dense_polygon

    size = float(np.sqrt(abs(cv2.contourArea(outline.astype(np.float32)))))
    err = fit_error(template, outline)
    tol = max(3.0, 0.1 * size)
    if err <= tol:
        return template
    # Thin parts (a strand of reflection, a tail) can throw the least-squares fit far off the
    # outline: remove them with an opening about 1/8 of the object's size and fit again.
    lo = outline.min(axis=0) - 2
    hi = outline.max(axis=0) + 2
    shape = (int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1)
    m = polygon_mask(outline - lo, shape)
    k = max(3, int(round(size / 8)) | 1)
    m = cv2.morphologyEx(m, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    opened = canonical_start(mask_outline(m) + lo) if m.any() else None
    # the parts taken away must be thin ones beside the object (a strand of reflection), not
    # one of its ends (a swan's neck and head): the object drawn keeps its extent, as when a
    # leak is taken out (LEAK_EXTENT)
    keeps_extent = opened is not None and bool(np.all(
        np.ptp(opened, axis=0) / np.maximum(np.ptp(outline, axis=0), 1.0) >= LEAK_EXTENT))
    if opened is not None:
        smooth_t = make(fit(opened, n_ctrl, degree=degree, closed=True), " (thin parts removed)")
        err_s = fit_error(smooth_t, opened)
        if err_s <= tol and keeps_extent:
            warn("the outline has thin parts the %d-control-point fit strayed on (%.0f px off); "
                 "they were removed (%.0f px)", n_ctrl, err, err_s)
            return smooth_t
    # The refinement can also fold the curve into a loop where the outline turns sharply (a
    # bust's neck: 12 control points ended 19 px off the outline, with or without the opening).
    # Fit again refining without folds (strict), on the outline and on the opened one when it
    # kept the object's extent; the closer fit within the tolerance is kept if it covers the
    # object clearly better than the convex hull (below), which smooths over a mask's errors
    # but takes in background (beside a bust's neck, under a swan's).
    hull = cv2.convexHull(outline.astype(np.float32))[:, 0, :].astype(float)
    tries = [(outline, " (fitted without folds)")]
    if keeps_extent:
        tries.append((opened, " (thin parts removed, fitted without folds)"))
    hull_iou = polygon_iou(hull, outline)

    def covers(t) -> float:  # how well a fit covers the object: IoU with the outline
        return polygon_iou(dense_polygon(t.Q, t.basis()), outline)

    best = None
    for pts, note in tries:
        t = make(fit(resample_polygon(pts, max(16 * n_ctrl, 192), True), n_ctrl, degree=degree, closed=True,
                     strict=True), note)
        e = fit_error(t, pts)
        if e <= tol and (best is None or e < best[0]):
            best = (e, t)
    if best is not None and covers(best[1]) >= hull_iou + REFIT_GAIN:
        warn("the %d-control-point fit folded on the outline (%.0f px off it); "
             "refitted without folds (%.0f px)", n_ctrl, err, best[0])
        return best[1]
    # The convex hull is smooth, always fits, and is what a contour of this many control
    # points can track.
    hull = resample_polygon(canonical_start(hull), max(8 * n_ctrl, 128), True)
    # strict: without it the refinement folded the curve back along the hull's straight sides
    # (crossing's pedestrian, 30 runs: P@20 0.80 with the folded template, 0.97)
    warn("the outline has detail %d control points cannot follow (fit %.0f px off it); "
         "using its convex hull (more control points: --n-ctrl)", n_ctrl, err)
    return make(fit(hull, n_ctrl, degree=degree, closed=True, strict=True), " (convex hull)")


@dataclasses.dataclass(frozen=True)
class Covering:
    """The fit :func:`fit_covering` kept: control vector ``Q`` of ``n_ctrl`` control points,
    its ``iou`` with the outline, and the IoU of each number of control points tried
    (``tried``, in the order tried)."""

    Q: np.ndarray
    n_ctrl: int
    iou: float
    tried: tuple[tuple[int, float], ...]

    def note(self) -> str:
        """What the template's source says about the fit."""
        return f" ({self.n_ctrl} control points, IoU {self.iou:.2f} with the outline)"

    def describe(self) -> str:
        """One line for the log: the control points tried and what each covered."""
        steps = ", ".join(f"{n}: {iou:.3f}" for n, iou in self.tried)
        return f"fitted with {self.n_ctrl} control points (IoU with the outline for {steps})"


def fit_covering(outline: np.ndarray, least: int, most: int, *, degree: int = 2) -> Covering:
    """A closed B-spline that covers the closed ``outline``, with as few control points
    between ``least`` and ``most`` as that takes.

    The number of control points grows through :data:`CTRL_STEPS` (``least`` first, ``most``
    last) until the filled curve's IoU with the filled outline reaches :data:`TARGET_IOU`, or
    :data:`STALL_STEPS` steps in a row each gain less than :data:`MIN_GAIN`; of the fits made,
    the one with the fewest control points within :data:`MIN_GAIN` of the best IoU is kept.
    Each fit is :func:`trackcli.shapes.draw.fit_closed` (parameters by arc length and by the
    outline's bends, refined locally, so the curve does not fold or loop however many
    control points it has).  The target was chosen on DAVIS train (eight sequences tracked,
    J 0.54 at 0.95, 0.53 at 0.97 with ten more control points on average).

    Thin parts (a kite's lines, a flamingo's legs) are followed as far as that covers the
    outline: with parameters that only move locally they cannot throw the curve into loops
    or folds.  (Opening parts thinner than 5 px away first was measured and left out: DAVIS
    train, eight sequences tracked, J 0.54 without, 0.52 with.)
    """
    from trackcli.run.evaluate import polygon_iou
    from trackcli.shapes.draw import fit_closed
    from trackcli.shapes.spline import SplineBasis, dense_polygon

    outline = np.asarray(outline, dtype=float)
    length = float(np.hypot(*np.diff(np.vstack([outline, outline[:1]]), axis=0).T).sum())
    pts = resample_polygon(outline, int(np.clip(length, max(FIT_POINTS[0], 4 * most), FIT_POINTS[1])), True)
    steps = sorted({least, most} | {n for n in CTRL_STEPS if least < n < most})
    fits: list[tuple[float, int, np.ndarray]] = []  # (IoU, n, Q)
    for n in steps:
        Q = fit_closed(pts, n, degree=degree)
        fits.append((polygon_iou(dense_polygon(Q, SplineBasis(n, degree, True), 16 * n), outline), n, Q))
        gains = np.diff([f[0] for f in fits])[-STALL_STEPS:]
        if fits[-1][0] >= TARGET_IOU or (len(gains) == STALL_STEPS and np.all(gains < MIN_GAIN)):
            break
    top = max(f[0] for f in fits)
    iou, n, Q = next(f for f in fits if f[0] >= top - MIN_GAIN)
    return Covering(Q, n, iou, tuple((f[1], f[0]) for f in fits))


def render_preview(image_bgr: np.ndarray, template, *, n_normals: int = 24, half_width: float = 15.0) -> np.ndarray:
    """Draw the curve (green), control polygon (blue) and measurement normals (yellow) over the frame."""
    import cv2

    from trackcli.shapes.spline import dense_polygon

    basis = template.basis()
    Q = template.Q
    vis = image_bgr.copy()
    scale = max(1, int(round(max(vis.shape[:2]) / 640)))
    sampler = basis.sampler(basis.measurement_params(n_normals))
    pts, nrm = sampler.points_normals(Q)

    def ipts(p: np.ndarray) -> np.ndarray:
        return np.round(np.asarray(p) * 16).astype(np.int32).reshape(-1, 1, 2)

    for p, n in zip(pts, nrm):
        a, b = p - half_width * n, p + half_width * n
        cv2.line(vis, tuple(ipts(a)[0, 0]), tuple(ipts(b)[0, 0]), (0, 220, 255), scale, cv2.LINE_AA, shift=4)
    cp = template.control_points
    cv2.polylines(vis, [ipts(cp)], template.closed, (255, 120, 0), scale, cv2.LINE_AA, shift=4)
    for c in cp:
        cv2.circle(vis, tuple(ipts(c)[0, 0]), 3 * 16 * scale, (255, 120, 0), -1, cv2.LINE_AA, shift=4)
    curve = dense_polygon(Q, basis)
    cv2.polylines(vis, [ipts(curve)], template.closed, (0, 255, 0), 2 * scale, cv2.LINE_AA, shift=4)
    for p in pts:
        cv2.circle(vis, tuple(ipts(p)[0, 0]), 2 * 16 * scale, (0, 0, 255), -1, cv2.LINE_AA, shift=4)
    return vis


def record_template(path, image_bgr: np.ndarray, template, *, n_normals: int = 24, half_width: float = 15.0):
    """Recording of a template over its frame: curve, control polygon, measurement normals."""
    from trackcli.io.recording import Recording
    from trackcli.shapes.spline import dense_polygon

    basis = template.basis()
    sampler = basis.sampler(basis.measurement_params(n_normals))
    pts, nrm = sampler.points_normals(template.Q)
    with Recording(path, blueprint="draw") as rec:
        rec.set_frame(template.frame, 0.0)
        rec.log_frame(image_bgr)
        rec.log_segments("video/normals", pts - half_width * nrm, pts + half_width * nrm, color=(255, 220, 0))
        rec.log_contour("video/control_polygon", template.control_points, color=(0, 120, 255), width=1.0,
                        closed=template.closed)
        rec.log_points("video/control_points", template.control_points, colors=(0, 120, 255), radii=3.0)
        rec.log_contour("video/template", dense_polygon(template.Q, basis), color=(0, 255, 0), width=2.0,
                        closed=template.closed)
        rec.log_params("params", template.to_dict())
    return path

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
    return fit_template(outline, n_ctrl or DEFAULT_CTRL, degree=degree, frame_size=size,
                        detail_ctrl=None if n_ctrl else DETAIL_CTRL, **kw)


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
    from trackcli.run import confirm
    from trackcli.run.clips import no_progress
    from trackcli.segment import grabcut, masks
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
            # read once: the first few show what moves, all of them try the masks
            after = next_frames(video, frame.index, confirm.CONFIRM_FRAMES - 1)
            later = [f.image for f in after[:MOTION_FRAMES]]
            # GrabCut takes seconds on a large frame (longer on a grey one, whose texture is segmented too)
            with bar("segmenting the box", grabcut.segment_runs(frame.image, bool(later))) as seg_bar:
                seg = grabcut.segment_candidates(frame.image, tuple(b), progress=seg_bar.update, later=later)
            mask_image, note = confirm_mask(seg, frame, after, video.fps, lambda m: fit_outline(
                masks.mask_outline(m), n_ctrl, degree, size, _quiet=True), bar)
            outline = masks.mask_outline(mask_image)
            source = f"box {box} ({seg.method}{note})"
        else:
            mask_image = masks.load_mask(mask, size)
            outline = masks.object_outline(mask_image)
            source = f"mask {mask}"
        template = fit_outline(outline, n_ctrl, degree, size, closed=not open_curve, clip=str(clip),
                               frame=frame_index, source=source)
        if box or mask:  # the region itself, which the spline only approximates (outline refinement)
            from trackcli.observe.region import mask_polygons

            template = dataclasses.replace(template, region=tuple(mask_polygons(mask_image)) or None)
        if box:
            template = dataclasses.replace(template, box=tuple(b))
        if parts:
            cut = structure.cut_parts(cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY), parts)
            template = dataclasses.replace(template, extra={**template.extra, "parts": structure.parts_to_yaml(cut)})
        vis = render_preview(frame.image, template, n_normals=n_normals)
        for _, (x, y, w, h) in parts:
            cv2.rectangle(vis, (int(round(x)), int(round(y))), (int(round(x + w)), int(round(y + h))),
                          (0, 200, 255), 1)
        ok, buf = cv2.imencode(".png", vis)
        with output_dir(out.parent), output_dir(png.parent), output_dir(Path(rrd).parent if rrd else out.parent):
            with atomic_paths(out, png, *([rrd] if rrd else [])) as tmps:  # all outputs or none
                save_template(tmps[0], template)
                tmps[1].write_bytes(buf.tobytes())
                if rrd:
                    record_template(tmps[2], frame.image, template, n_normals=n_normals)
    log.info("template %s (%d control points) from %s", out, template.n_ctrl, source)
    return Drawn(out, png, rrd, template, source)


def next_frames(video: Any, index: int, n: int) -> list[Any]:
    """Up to ``n`` frames of ``video`` after frame ``index`` (fewer at its end)."""
    from trackcli.errors import VideoError

    out = []
    for i in range(index + 1, min(index + 1 + n, video.n_total)):
        try:
            out.append(video.read(i))
        except VideoError:  # a file's frame count is an estimate: its true end came first
            break
    return out


def confirm_mask(seg: Any, frame: Any, after: Sequence[Any], fps: float, fit: Callable[[Any], Any],
                 progress: Callable[[str, int], ContextManager[Any]]) -> tuple[Any, str]:
    """``draw --box``: the mask of ``seg`` that the frames ``after`` the drawn one (``frame``,
    of a clip at ``fps``) hold best (:func:`trackcli.run.confirm.confirm`), and what to add to
    the template's source about it.  ``fit(mask)`` makes a template as ``draw`` does."""
    from trackcli.run import confirm

    order = confirm.to_try(seg.masks, seg.chosen)
    if seg.agreement is not None:
        # the next frames' motion has spoken first: only masks as much what moves as the choice
        # (within MOTION_GAIN) are tried; a still region is easily "held"
        from trackcli.segment.grabcut import MOTION_GAIN

        order = [i for i in order if seg.agreement[i] >= seg.agreement[seg.chosen] - MOTION_GAIN]
    if len(order) < 2:  # one mask (or the inscribed ellipse): nothing to choose
        return seg.mask, ""
    frames = [frame, *after]
    if len(frames) - 1 < confirm.CONFIRM_LEAST:
        return seg.mask, ""
    with progress(f"trying {len(order)} masks on the next frames", len(order)) as bar:
        best, trials = confirm.confirm(seg.masks, order, fit, frames, fps, progress=bar.update)
    for t in trials:
        log.info("mask %d of %d%s: over frames %d-%d, confidence %.3f, score %.1f (%.2f of the first frame's)",
                 t.index + 1, len(seg.masks), " (the frame's choice)" if t.index == seg.chosen else "",
                 frame.index + 1, frame.index + len(frames) - 1, t.confidence, t.score, t.held)
    if best == seg.chosen:
        return seg.mask, ""
    return seg.masks[best], f"; the mask the next {len(frames) - 1} frames held best"
