"""Templates drawn on a frame: the B-spline fit of an outline, its preview and recording.

``trackcli draw`` gets an ordered outline from :mod:`trackcli.shapes.draw` (points, an
ellipse) or :mod:`trackcli.segment` (a mask, a box) and fits a B-spline to it here
(:func:`fit_template`), falling back where the fit strays from the outline; the result is
shown over its frame as a PNG (:func:`render_preview`) and, on request, a recording
(:func:`record_template`).
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from trackcli.segment.grabcut import LEAK_EXTENT
from trackcli.segment.masks import mask_outline
from trackcli.shapes.draw import canonical_start, fit_error, polygon_mask, resample_polygon

log = logging.getLogger(__name__)

#: a fit that strayed from the outline is replaced by a fit without folds when that covers the
#: object (IoU with the outline) by at least this much more than the convex hull does; else
#: the hull is taken
REFIT_GAIN = 0.1
#: control points of ``draw`` when none are asked for; an outline with detail that many cannot
#: follow (an open hand's fingers) is fitted with DETAIL_CTRL before the convex hull is taken
DEFAULT_CTRL = 12
DETAIL_CTRL = 24


def fit_template(outline: np.ndarray, n_ctrl: int, *, degree: int = 2, closed: bool = True, clip: str | None = None,
                 frame: int = 0, frame_size: tuple[int, int] | None = None, source: str = "",
                 detail_ctrl: int | None = None, _quiet: bool = False):
    """Fit a B-spline with ``n_ctrl`` control points to an ordered outline; return a Template.

    A fit that strays from the outline falls back (thin parts opened away, a refit without
    folds, the convex hull; see ``draw``).  With ``detail_ctrl`` > ``n_ctrl``, an outline that
    would get its convex hull is first fitted with ``detail_ctrl`` control points, and that fit
    is taken if it is not a hull itself and covers the object (IoU with the outline) at least
    :data:`REFIT_GAIN` better than the hull: the fingers of an open hand rather than the hull
    about them, which takes in the background between them.
    """
    from trackcli.shapes.spline import fit
    from trackcli.shapes.template import Template

    outline = np.asarray(outline, dtype=float)
    if closed:
        outline = canonical_start(outline)
    if len(outline) < n_ctrl:
        # too few points to pin every control point: resample the polygon densely first
        outline = resample_polygon(outline, max(4 * n_ctrl, 64), closed)
    def make(Q: np.ndarray, note: str = "") -> Template:
        return Template(np.column_stack([Q[:n_ctrl], Q[n_ctrl:]]), degree=degree, closed=closed, clip=clip,
                        frame=frame, frame_size=frame_size, source=source + note)

    template = make(fit(outline, n_ctrl, degree=degree, closed=closed))
    warn = log.warning if not _quiet else (lambda *args: None)  # a trial fit says nothing
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
    # A deep, narrow concavity (a swan's neck, an arm held out) that n_ctrl control points
    # cannot follow can also throw the fit off.  More control points may follow it (an open
    # hand's fingers); taken only where they cover the object clearly better than the hull,
    # which smooths over a mask's errors (a plastic bag's crumpled outline).
    if detail_ctrl is not None and detail_ctrl > n_ctrl:
        detailed = fit_template(outline, detail_ctrl, degree=degree, closed=True, clip=clip, frame=frame,
                                frame_size=frame_size, source=source, _quiet=True)
        iou = covers(detailed)
        if not detailed.source.endswith(" (convex hull)") and iou >= hull_iou + REFIT_GAIN:
            warn("the outline has detail %d control points cannot follow (fit %.0f px off it); "
                 "fitted with %d, which cover it better than its convex hull (IoU %.2f against %.2f)",
                 n_ctrl, err, detail_ctrl, iou, hull_iou)
            return dataclasses.replace(detailed, source=detailed.source + f" ({detail_ctrl} control points)")
    # The convex hull is smooth, always fits, and is what a contour of this many control
    # points can track.
    hull = resample_polygon(canonical_start(hull), max(8 * n_ctrl, 128), True)
    # strict: without it the refinement folded the curve back along the hull's straight sides
    # (crossing's pedestrian, 30 runs: P@20 0.80 with the folded template, 0.97)
    warn("the outline has detail %d control points cannot follow (fit %.0f px off it); "
         "using its convex hull (more control points: --n-ctrl)", n_ctrl, err)
    return make(fit(hull, n_ctrl, degree=degree, closed=True, strict=True), " (convex hull)")


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
