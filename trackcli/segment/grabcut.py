"""The object inside a box, segmented with GrabCut (OpenCV): ``draw --box``.

The box is seeded as GrabCut's rectangle (outside = background; on a grey frame with the
frame's local texture too), on the whole frame and on the box's surroundings; each mask is
offered again without background leaking in through the box's edge and, on a colour frame,
with the colours of its surroundings pruned from its rim; the candidates are ranked by how
well they separate the colours inside and outside near the box and how much of the box they
span (:func:`segment_candidates`).  The outline of the chosen mask is traced by
:func:`trackcli.segment.masks.mask_outline`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Sequence

import numpy as np

from trackcli.errors import ConfigError
from trackcli.shapes.draw import MIN_OUTLINE_SIDE

log = logging.getLogger(__name__)

#: the local GrabCut sees the box and a ring this fraction of its size wide around it
SEGMENT_MARGIN = 0.1
#: how much better (in :func:`colour_separation`, near the whole-frame mask's) another mask
#: must be to replace the whole-frame one, other things equal (see :func:`_choice_score`)
SEPARATION_MARGIN = 0.01
#: a box within this many pixels of the frame's edge is segmented in the frame extended by
#: :data:`EDGE_PAD` pixels of its edge repeated
EDGE_TOUCH = 2
EDGE_PAD = 8
#: ... and a box reaching farther beyond the frame than this share of its width (height)
#: inside it is cut there: beyond the edge the frame holds no more than its edge repeated
BEYOND_SHARE = 0.25
#: a candidate mask whose bounding rectangle spans less than this share of the box's width or
#: height is kept only if every candidate does
BOX_SPAN = 0.7
#: the masks left are chosen by the Bhattacharyya distance of their inside and outside colours
#: plus this weight times their span (the smaller of the shares of the box's width and height
#: their bounding rectangle covers)
SPAN_WEIGHT = 2.0
#: background leaking in: largest colour difference (CIE Lab, 8-bit, on the 5x5-blurred frame)
#: between the mask just inside the box's edge and the frame just outside it
LEAK_COLOUR = 15.0
#: background leaking in: largest step between neighbouring pixels (Lab, 8-bit, blurred) of the
#: region flooded from the edge
LEAK_STEP = 3
#: background leaking in: largest step between neighbouring pixels (Lab, 8-bit, blurred) on the
#: line across the box's edge from inside the mask to outside the box (no edge on the way)
LEAK_JUMP = 6
#: background leaking in: the mask without the leak must keep this share of the width and height
LEAK_EXTENT = 0.9
#: on a grey frame GrabCut also sees texture: the grey level with its local mean and standard
#: deviation over a Gaussian window of this sigma (px), the deviation scaled by TEXTURE_GAIN
TEXTURE_SIGMA = 3.0
TEXTURE_GAIN = 4.0
#: pruning a mask by colour: its core is where the distance to the mask's edge is at least this
#: share of the largest; outside the core, pixels whose colour (8x8x8 BGR bins) is commoner
#: outside the mask near the box than in the core are offered to GrabCut as probable background
PRUNE_CORE = 0.3
PRUNE_BINS = 8
#: ... and GrabCut runs again within the box grown by this share of its size on every side
PRUNE_WINDOW = 1.0
#: pruning a mask by regions: its core is where the distance to the mask's edge is at least
#: this share of the largest (a panel taken in beside a bust can be wider than the 30 % rim);
#: outside it, pixels where the log-ratio of the surroundings' colour frequency to the core's,
#: averaged over a square window of this share of the box's smaller side, is positive are
#: offered to GrabCut as probable background (a striped panel whose dark stripes have the
#: object's colour is still mostly the surroundings' colours)
REGION_CORE = 0.65
REGION_WINDOW = 0.08
#: with the next frames' motion (:mod:`trackcli.segment.motion`), a candidate replaces the
#: colours' choice when its agreement with what moves is higher by this much
MOTION_GAIN = 0.05


def segment_runs(image_bgr: np.ndarray, motion: bool = False) -> int:
    """The GrabCut runs :func:`segment_box` makes at most on this frame (its ``progress`` steps):
    the whole frame and the box's surroundings, each possibly again without a leak (4); on a
    colour frame each of these masks possibly again pruned by colour and by regions (12), on a
    grey frame all of it again on its texture image (8); with ``motion`` (later frames given to
    :func:`segment_candidates`) one run more, seeded by what moves."""
    from trackcli.observe.discriminant import is_grey

    return (8 if is_grey(image_bgr) else 12) + int(motion)


@dataclasses.dataclass(frozen=True, eq=False)
class Segmentation:
    """The masks :func:`segment_candidates` found for a box and the one it chose.

    ``masks`` are uint8 masks of the frame's size (0 or 255), the candidates among which the
    choice of :func:`segment_box` is made (those spanning the box, see there); ``chosen`` is
    the index of that choice and ``method`` how it was found (``"GrabCut"``, or
    :data:`FALLBACK_METHOD`, whose only mask is the ellipse inscribed in the box).
    ``agreement`` is each mask's :func:`trackcli.segment.motion.agreement` with what moves in
    the box, when the later frames showed a moving object (else None).
    """

    masks: tuple[np.ndarray, ...]
    chosen: int
    method: str
    agreement: tuple[float, ...] | None = None

    @property
    def mask(self) -> np.ndarray:
        """The chosen mask."""
        return self.masks[self.chosen]


def segment_box(image_bgr: np.ndarray, box: tuple[float, float, float, float], *, iterations: int = 5,
                progress: Callable[[int], None] | None = None) -> np.ndarray:
    """Segment the object inside ``box = (x, y, w, h)`` with GrabCut; returns a uint8 mask
    (the ellipse inscribed in the box when GrabCut found no clear object, see
    :attr:`Segmentation.method`).  ``progress(1)`` is called after each of the at most
    :func:`segment_runs` GrabCut runs (a second or more each on a large frame).  The mask is
    :attr:`Segmentation.mask` of :func:`segment_candidates`.

    Everything outside the box is background.  GrabCut runs on the whole frame, and on the
    box with a ring of :data:`SEGMENT_MARGIN` times its size around it, where the background
    model is the object's immediate surroundings.  Each mask may then have background that
    leaked in through the box's edge taken out (:func:`_unleak`): the wall behind a swan's
    neck, between its head and back, is inside a tight box and GrabCut's first object model
    takes it in.  Candidates whose extent is less than :data:`BOX_SPAN` of the box's width or
    height are left out when another one spans it: the box was drawn around the whole object.
    Of the others, the mask with the highest :func:`_choice_score` (how different its inside
    and outside are in colour near the box, :func:`colour_separation`, as a Bhattacharyya
    distance, plus :data:`SPAN_WEIGHT` times the smaller of the shares of the box's width and
    height it covers) is kept, if that beats the whole-frame mask's by more than
    :data:`SEPARATION_MARGIN` of separation would; otherwise the whole-frame mask is.  A box
    that reaches the frame's edge is segmented in the frame extended by its edge pixels
    repeated, so that GrabCut has background beyond the box on that side too.

    Measured against true outlines (frame 0 of 16 generator seeds of both sample clips, tight
    and 15 % loose boxes; 12 frames of three DAVIS sequences), the mean IoU of the whole-frame
    run alone is 0.883, of the local run alone 0.895, of the choice between them 0.897.
    Taking out leaks (``bench/segmentation.py --seeds 1,...,16 --every 5``: 96 frames of the
    three sample clips, 30 DAVIS frames) leaves the sample clips at 0.937 and lifts DAVIS from
    0.704 to 0.769: four of ten black-swan frames go from 0.45 to 0.93, and nothing else moves
    by more than 0.001.  The span rule and the edge (seeds 1, ..., 28: 168 sample-clip frames)
    lift the cluttered clip from 0.912 to 0.919 (its worst from 0.69 to 0.81) and the
    three-heads walker from 0.959 to 0.974 with tight boxes (worst 0.74 to 0.97) and from
    0.938 to 0.961 with loose ones; DAVIS stays at 0.768.  The span in the score (seeds
    1, ..., 106, tight boxes) changes the cluttered clip's mask on 8 seeds (mean IoU of the
    8: 0.878 to 0.937): on 7 the mask chosen before spanned 86-87 % of the box's height (on
    seed 90, the bust without its hair).
    On a grey frame (:func:`trackcli.observe.discriminant.is_grey`) GrabCut also runs, on the
    whole frame and on the box's surroundings, on :func:`texture_image`, and the choice is by
    :func:`texture_separation`: on grey copies of the frames (seeds 1, ..., 8) the cluttered
    clip's mean IoU goes from 0.60 to 0.87, DAVIS from 0.51 to 0.53.
    On a colour frame each mask is also offered with the colours of its surroundings pruned
    from its rim (:func:`_prune`); the pruned masks are chosen by the same rule.  Frame 0's
    box of 30 generator seeds of the cluttered clip goes from 0.916 to 0.927 (15 % loose
    boxes: 0.884 to 0.909), of the 48 clips of ``bench/other_clips.py`` from 0.830 to 0.847
    (37 masks change; the largest loss is 0.03), of the five real clips with a first outline
    from 0.796 to 0.802; the three-heads walker is unchanged.
    Each mask is also offered pruned by regions (``_prune`` with :data:`REGION_CORE` and
    :data:`REGION_WINDOW`): the surroundings' colours averaged over a window, outside a core
    of the mask's deepest part, so that a panel whose stripes are mostly the object's colour
    goes whole.  Of the 48 clips of ``bench/other_clips.py`` the mean goes from 0.859 to 0.873
    (open hands whose masks filled the gaps between the fingers: ``other_hand_0_04`` 0.81 to
    0.91, ``other_hand_3_04`` 0.80 to 0.89; ``other_leaf_0_08`` 0.74 to 0.93; the largest loss
    ``other_bust_3_03`` 0.88 to 0.81), the cluttered sample clip of seeds 1-30 from 0.927 to
    0.929 (loose boxes 0.909 to 0.914); the real clips' first frames are unchanged.
    Each mask is cleaned:
    small specks removed by a morphological opening, holes filled, the largest region kept.
    """
    return segment_candidates(image_bgr, box, iterations=iterations, progress=progress).mask


def segment_candidates(image_bgr: np.ndarray, box: tuple[float, float, float, float], *, iterations: int = 5,
                       progress: Callable[[int], None] | None = None,
                       later: Sequence[np.ndarray] = ()) -> Segmentation:
    """The candidate masks of :func:`segment_box` for ``box`` and its choice among them (see
    there), for a caller that can judge them further (``draw --box`` tracks them over the
    frames that follow, :mod:`trackcli.run.confirm`).

    With ``later``, the next few frames of the clip (:data:`trackcli.segment.motion.MOTION_FRAMES`),
    what moves unlike the scene is a cue too (:mod:`trackcli.segment.motion`): GrabCut runs once
    more with the box's moving pixels as probable object and its still ones as probable
    background, and a candidate that is clearly more what moves than the colours' choice
    (:func:`trackcli.segment.motion.agreement` higher by :data:`MOTION_GAIN`) replaces it."""
    import cv2

    from trackcli.segment.motion import motion_residual

    residual = motion_residual(image_bgr, later, box) if len(later) else None

    h_img, w_img = image_bgr.shape[:2]
    x, y, w, h = box
    if w <= 0 or h <= 0:
        raise ConfigError(f"--box: width and height must be positive, got {w:g}x{h:g}")
    x0, y0 = int(round(max(0.0, x))), int(round(max(0.0, y)))
    x1, y1 = int(round(min(float(w_img), x + w))), int(round(min(float(h_img), y + h)))
    if min(w, h) < MIN_OUTLINE_SIDE:
        raise ConfigError(f"--box {x:g},{y:g},{w:g},{h:g}: spans only {w:g}x{h:g} px (at least "
                          f"{MIN_OUTLINE_SIDE} px each way)")
    if x1 - x0 < MIN_OUTLINE_SIDE or y1 - y0 < MIN_OUTLINE_SIDE:
        raise ConfigError(f"--box {x:g},{y:g},{w:g},{h:g}: lies (almost) outside the {w_img}x{h_img} frame "
                          f"(at least {MIN_OUTLINE_SIDE}x{MIN_OUTLINE_SIDE} px of it must be inside)")
    if min(x0, y0) <= EDGE_TOUCH or x1 >= w_img - EDGE_TOUCH or y1 >= h_img - EDGE_TOUCH:
        # the box reaches the frame's edge: GrabCut has no background on that side, and a
        # pocket of background enclosed by the object, the edge and the box's other sides
        # stays in the mask; the frame's edge pixels repeated beyond it (and beyond any part of
        # the box outside the frame) give it that background.  Beyond the frame the box is cut
        # to BEYOND_SHARE of its extent inside (a box in another resolution's coordinates, or
        # "the whole frame" typed as a huge box, would otherwise pad the frame to gigapixels)
        reach_x, reach_y = BEYOND_SHARE * (x1 - x0), BEYOND_SHARE * (y1 - y0)
        bx0, by0 = max(x, x0 - reach_x), max(y, y0 - reach_y)
        bx1, by1 = min(x + w, x1 + reach_x), min(y + h, y1 + reach_y)
        seg = (x, y, w, h)  # as given unless cut (to the bit: the same mask as before the cut existed)
        if (bx0, by0, bx1, by1) != (x, y, x + w, y + h):
            seg = (bx0, by0, bx1 - bx0, by1 - by0)
            log.warning("--box %g,%g,%g,%g: reaches beyond the %dx%d frame by more than a quarter of its size "
                        "inside it; segmenting %g,%g,%g,%g", x, y, w, h, w_img, h_img, *seg)
        p = EDGE_PAD + int(math.ceil(max(0.0, -seg[0], -seg[1], seg[0] + seg[2] - w_img, seg[1] + seg[3] - h_img)))
        big = cv2.copyMakeBorder(image_bgr, p, p, p, p, cv2.BORDER_REPLICATE)
        if residual is not None:
            residual = cv2.copyMakeBorder(residual, p, p, p, p, cv2.BORDER_REPLICATE)
        masks, chosen, method, agreement = _segment(big, (seg[0] + p, seg[1] + p, seg[2], seg[3]),
                                         (x0 + p, y0 + p, x1 - x0, y1 - y0), iterations, progress, residual)
        masks = [np.ascontiguousarray(m[p:-p, p:-p]) for m in masks]
    else:
        masks, chosen, method, agreement = _segment(image_bgr, box, (x0, y0, x1 - x0, y1 - y0), iterations, progress,
                                         residual)
    if method == FALLBACK_METHOD:
        log.warning("--box %g,%g,%g,%g: automatic segmentation found no clear object; using the ellipse "
                    "inscribed in the box", x, y, w, h)
    return Segmentation(tuple(masks), chosen, method, agreement)


#: the method :func:`segment_box` names when GrabCut found no object
FALLBACK_METHOD = "inscribed ellipse"


def _segment(image_bgr: np.ndarray, box: tuple[float, float, float, float], rect: tuple[int, int, int, int],
             iterations: int, progress: Callable[[int], None] | None = None,
             residual: np.ndarray | None = None) -> tuple[list[np.ndarray], int, str, tuple[float, ...] | None]:
    """:func:`segment_candidates` of a checked box, ``rect`` its whole-pixel part inside the
    frame, ``residual`` the motion cue's (or None): ``(masks, chosen, method, agreement)``."""
    import cv2

    from trackcli.segment import motion

    from trackcli.observe.discriminant import is_grey

    def tick() -> None:
        if progress is not None:
            progress(1)

    h_img, w_img = image_bgr.shape[:2]
    x, y, w, h = box
    x0, y0 = rect[:2]
    x1, y1 = x0 + rect[2], y0 + rect[3]
    cx0 = int(max(0.0, math.floor(x - SEGMENT_MARGIN * w)))
    cy0 = int(max(0.0, math.floor(y - SEGMENT_MARGIN * h)))
    cx1 = int(min(float(w_img), math.ceil(x + w + SEGMENT_MARGIN * w)))
    cy1 = int(min(float(h_img), math.ceil(y + h + SEGMENT_MARGIN * h)))
    # a grey frame gives GrabCut the grey level only, and an object as dark as its surroundings
    # (a bust on a dark patterned wall) is lost; its texture still tells them apart
    texture = texture_image(image_bgr) if is_grey(image_bgr) else None
    candidates: list[np.ndarray | None] = []
    for image in (image_bgr,) if texture is None else (image_bgr, texture):
        candidates.append(_grabcut(image, box, iterations))
        tick()
        if (cx0, cy0, cx1, cy1) != (0, 0, w_img, h_img):
            sub = _grabcut(np.ascontiguousarray(image[cy0:cy1, cx0:cx1]), (x - cx0, y - cy0, w, h), iterations)
            tick()
            if sub is not None:
                local = np.zeros((h_img, w_img), np.uint8)
                local[cy0:cy1, cx0:cx1] = sub
                candidates.append(local)
    moves = motion.moving(residual, rect) if residual is not None else None
    if moves is not None:
        # GrabCut's colour models learned from what moves in the box and what stays with the scene
        labels = np.full((h_img, w_img), cv2.GC_BGD, np.uint8)
        labels[y0:y1, x0:x1] = cv2.GC_PR_BGD
        labels[moves] = cv2.GC_PR_FGD
        candidates.append(_clean_mask(_run_grabcut(image_bgr, labels, None, iterations, cv2.GC_INIT_WITH_MASK), rect))
        tick()
    candidates = [c for c in candidates if c is not None]
    if not candidates:
        # GrabCut finds nothing convincing (small or low-contrast objects): the ellipse
        # inscribed in the box is the honest fallback, and the user is told (segment_box)
        fallback = np.zeros((h_img, w_img), np.uint8)
        box_rr = (((x0 + x1) / 2.0, (y0 + y1) / 2.0), (float(x1 - x0), float(y1 - y0)), 0.0)
        cv2.ellipse(fallback, box_rr, 255, -1)
        return [fallback], 0, FALLBACK_METHOD, None
    lab = cv2.cvtColor(cv2.GaussianBlur(image_bgr, (5, 5), 0), cv2.COLOR_BGR2Lab)
    unleaked = []
    for c in list(candidates):
        unleaked.append(_unleak(image_bgr, lab, c, rect, iterations))
        tick()
    candidates += [m for m in unleaked if m is not None]
    if texture is None:
        pruned = []
        for c in candidates:
            pruned.append(_prune(image_bgr, c, box, rect, iterations))
            tick()
        for c in candidates:
            pruned.append(_prune(image_bgr, c, box, rect, iterations, core_share=REGION_CORE, window=REGION_WINDOW))
            tick()
        candidates += [m for m in pruned if m is not None]
    # the box was drawn around the object: a mask that spans much less of it has lost a part
    # (a bust's head, whose colours are common around it), so such masks are chosen only when
    # every candidate is one
    spans = [min(r[2] / rect[2], r[3] / rect[3]) for r in (cv2.boundingRect(c) for c in candidates)]
    every = list(candidates)
    if any(sp >= BOX_SPAN for sp in spans):
        candidates, spans = map(list, zip(*[(c, sp) for c, sp in zip(candidates, spans) if sp >= BOX_SPAN]))
    # the first (the whole-frame mask, the older default) stays unless another one is clearly better
    separation = [colour_separation(image_bgr, c, box) if texture is None else texture_separation(texture, c, box)
                  for c in candidates]
    score = [_choice_score(sep, sp) for sep, sp in zip(separation, spans)]
    best = int(np.argmax(score))
    # SEPARATION_MARGIN of 1 - BC about the whole-frame mask's BC, on the distance -ln BC
    margin = SEPARATION_MARGIN / max(1.0 - separation[0], 1e-6)
    chosen = best if score[best] > score[0] + margin else 0
    if moves is None:
        return candidates, chosen, "GrabCut", None
    # a mask that is clearly more what moves unlike the scene than the colours' choice wins, even
    # one the span rule left out: the motion tells a lost part (a flamingo's still legs) from
    # background taken in
    agree = [motion.agreement(c, moves, rect) for c in every]
    of = {id(c): a for c, a in zip(every, agree)}  # every candidate kept is one of `every`
    mover = int(np.argmax(agree))
    if agree[mover] > of[id(candidates[chosen])] + MOTION_GAIN:
        if not any(c is every[mover] for c in candidates):
            candidates.append(every[mover])
        chosen = next(i for i, c in enumerate(candidates) if c is every[mover])
    return candidates, chosen, "GrabCut", tuple(of[id(c)] for c in candidates)


def _choice_score(separation: float, span: float) -> float:
    """How a candidate mask is ranked: the Bhattacharyya distance ``-ln BC`` of its inside and
    outside histograms (``separation`` is ``1 - BC``), plus :data:`SPAN_WEIGHT` times its span.

    On the distance a small gain in separation counts for more where the colours are already
    well apart: a mask with ``BC`` 0.001 is not given up for one spanning a loose box further
    with ``BC`` 0.01 (background let in), while between masks at ``BC`` 0.24 and 0.30 the
    one spanning the box wins (a bust with its hair).  The whole-frame mask is replaced only by a
    mask that scores more than :data:`SEPARATION_MARGIN` divided by its ``BC`` higher: to first
    order, a mask of the same span that separates the colours by that margin better."""
    return -math.log(max(1.0 - separation, 1e-6)) + SPAN_WEIGHT * span


def colour_separation(image_bgr: np.ndarray, mask: np.ndarray, box: tuple[float, float, float, float], *,
                      margin: float = 0.25) -> float:
    """How different the colours inside and outside ``mask`` are near ``box``, in [0, 1].

    ``1 - BC`` for the Bhattacharyya coefficient ``BC`` of the hue–saturation histograms
    (16×16 bins) of the pixels inside and outside the mask, within the box grown by
    ``margin`` of its size on every side.
    """
    import cv2

    window = _near_box(mask.shape, box, margin)
    hsv = cv2.cvtColor(np.ascontiguousarray(image_bgr[window]), cv2.COLOR_BGR2HSV)
    return _separation(hsv, (0, 1), (0, 180, 0, 256), mask[window])


def _near_box(shape: tuple[int, ...], box: tuple[float, float, float, float], margin: float) -> tuple[slice, slice]:
    """The rows and columns of an image of ``shape`` within ``box`` grown by ``margin`` of its size."""
    x, y, w, h = box
    h_img, w_img = shape[:2]
    X0, Y0 = int(max(0, x - margin * w)), int(max(0, y - margin * h))
    X1, Y1 = int(min(w_img, x + w + margin * w)), int(min(h_img, y + h + margin * h))
    return slice(Y0, Y1), slice(X0, X1)


def _separation(image: np.ndarray, channels: tuple[int, int], ranges: tuple[int, int, int, int],
                mask: np.ndarray) -> float:
    """``1 - BC`` of the 16×16-bin histograms of two ``channels`` of ``image`` inside and
    outside ``mask`` (same size)."""
    import cv2

    image = np.ascontiguousarray(image)
    inside = (mask > 0).astype(np.uint8)
    hists = []
    for m in (inside, 1 - inside):
        hist = cv2.calcHist([image], list(channels), m, [16, 16], list(ranges)).ravel()
        hists.append(hist / max(float(hist.sum()), 1.0))
    return float(1.0 - np.sqrt(hists[0] * hists[1]).sum())


def texture_image(image_bgr: np.ndarray) -> np.ndarray:
    """A grey frame as three channels: the grey level, its local mean and its local standard
    deviation times :data:`TEXTURE_GAIN` (Gaussian window of sigma :data:`TEXTURE_SIGMA`), uint8."""
    import cv2

    from trackcli.observe.discriminant import local_mean_deviation

    g = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    mean, sd = local_mean_deviation(g, TEXTURE_SIGMA)
    return np.clip(np.dstack([g, mean, sd * TEXTURE_GAIN]) + 0.5, 0, 255).astype(np.uint8)


def texture_separation(texture: np.ndarray, mask: np.ndarray, box: tuple[float, float, float, float], *,
                       margin: float = 0.25) -> float:
    """:func:`colour_separation` for a grey frame, from its :func:`texture_image`: ``1 - BC``
    of the histograms of grey level and local standard deviation (16×16 bins)."""
    window = _near_box(mask.shape, box, margin)
    return _separation(texture[window], (0, 2), (0, 256, 0, 256), mask[window])


def _grabcut(image_bgr: np.ndarray, box: tuple[float, float, float, float], iterations: int) -> np.ndarray | None:
    """GrabCut initialised with ``box`` on ``image_bgr``, cleaned (:func:`_clean_mask`);
    None when it finds no region of at least 15 % of the box."""
    import cv2

    h_img, w_img = image_bgr.shape[:2]
    x, y, w, h = box
    x0, y0 = int(round(max(0.0, x))), int(round(max(0.0, y)))
    x1, y1 = int(round(min(float(w_img), x + w))), int(round(min(float(h_img), y + h)))
    rect = (x0, y0, x1 - x0, y1 - y0)
    mask = np.zeros((h_img, w_img), np.uint8)
    # GrabCut needs some background: if the box covers the whole frame, shrink it by a pixel.
    if rect[2] >= w_img - 1 and rect[3] >= h_img - 1:
        rect = (1, 1, w_img - 2, h_img - 2)
    return _clean_mask(_run_grabcut(image_bgr, mask, rect, iterations, cv2.GC_INIT_WITH_RECT), rect)


def _run_grabcut(image_bgr: np.ndarray, mask: np.ndarray, rect, iterations: int, mode: int) -> np.ndarray:
    """One GrabCut run from a rectangle or a labelled ``mask``; the object as a 0/255 mask."""
    import cv2

    bgd = np.zeros((1, 65), np.float64)
    fgd = np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)  # GrabCut's GMM initialisation uses OpenCV's RNG: keep runs reproducible
    cv2.grabCut(image_bgr, mask, rect, bgd, fgd, iterations, mode)
    return np.where((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD), 255, 0).astype(np.uint8)


def _clean_mask(fg: np.ndarray, rect) -> np.ndarray | None:
    """Specks opened away, gaps closed, the largest region kept with its holes filled; None
    when that region covers less than 15 % of ``rect = (x, y, w, h)``."""
    import cv2

    k = max(3, int(round(min(rect[2], rect[3]) * 0.03)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    fg = cv2.morphologyEx(fg, cv2.MORPH_OPEN, kernel)
    fg = cv2.morphologyEx(fg, cv2.MORPH_CLOSE, kernel)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n <= 1 or stats[1:, cv2.CC_STAT_AREA].max() < 0.15 * rect[2] * rect[3]:
        return None
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    fg = np.where(labels == largest, 255, 0).astype(np.uint8)
    # fill holes: everything not reachable from the border as background is object
    contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(fg)
    cv2.drawContours(filled, contours, -1, 255, thickness=cv2.FILLED)
    return filled


def _leak_seeds(lab: np.ndarray, mask: np.ndarray, rect) -> list[tuple[int, int]]:
    """Points of ``mask`` near the edge of ``rect`` where the frame goes on unchanged across it.

    A tight box touches its object, but the object stops at the edge: what lies just outside
    differs from it.  Where the mask, a little inside the edge (3 % of the box's smaller side,
    at least 3 px), has the colour of the frame as far and 4 px more beyond it (within
    :data:`LEAK_COLOUR` in Lab), with no step of more than :data:`LEAK_JUMP` on the line
    between the two, over a run of at least 3 % of that side, the mask has most likely taken
    in background that goes on beyond the box.
    """
    h_img, w_img = mask.shape
    x0, y0, w, h = rect
    inset = max(3, int(round(0.03 * min(w, h))))
    gap = 2 * inset + 4  # from the inner probe to the outer one
    xs, ys = np.arange(x0, x0 + w), np.arange(y0, y0 + h)
    sides = []
    if y0 - inset - 4 >= 0:  # top edge: probe inside at y0 + inset, outside at y0 - inset - 4
        sides.append((xs, np.full(w, y0 + inset), 0, -gap))
    if y0 + h + inset + 4 <= h_img:
        sides.append((xs, np.full(w, y0 + h - 1 - inset), 0, gap))
    if x0 - inset - 4 >= 0:
        sides.append((np.full(h, x0 + inset), ys, -gap, 0))
    if x0 + w + inset + 4 <= w_img:
        sides.append((np.full(h, x0 + w - 1 - inset), ys, gap, 0))
    seeds: list[tuple[int, int]] = []
    k = np.arange(gap + 1)
    for px, py, dx, dy in sides:
        # the profile across the edge, from the inner probe to the outer one
        line = lab[py[:, None] + np.sign(dy) * k, px[:, None] + np.sign(dx) * k].astype(np.float32)
        jumps = np.abs(np.diff(line, axis=1)).max(axis=(1, 2))
        same = ((mask[py, px] > 0) & (np.linalg.norm(line[:, 0] - line[:, -1], axis=1) < LEAK_COLOUR)
                & (jumps <= LEAK_JUMP))
        min_run = max(3, int(0.03 * px.size))
        # runs of `same` at least min_run long
        edges = np.flatnonzero(np.diff(np.concatenate(([0], same.astype(np.int8), [0]))))
        for start, stop in zip(edges[::2], edges[1::2]):
            if stop - start >= min_run:
                seeds.extend(zip(px[start:stop].tolist(), py[start:stop].tolist()))
    return seeds


def _unleak(image_bgr: np.ndarray, lab: np.ndarray, mask: np.ndarray, rect, iterations: int) -> np.ndarray | None:
    """``mask`` with the background that leaked in through the box's edge taken out, or None
    when nothing leaked (:func:`_leak_seeds`).

    From the leak points the mask is flooded where neighbouring pixels differ by at most
    :data:`LEAK_STEP` (blurred Lab); that region is marked probable background, the rest of the
    mask probable object, and GrabCut runs again from these labels, so its object model is
    learned without the leaked region.
    """
    import cv2

    seeds = _leak_seeds(lab, mask, rect)
    if not seeds:
        return None
    h_img, w_img = mask.shape
    # floodFill's mask: 1 blocks (outside the object's mask), 2 marks what the flood reached
    fill = np.ones((h_img + 2, w_img + 2), np.uint8)
    fill[1:-1, 1:-1] = (mask == 0)
    flags = 4 | cv2.FLOODFILL_MASK_ONLY | (2 << 8)
    step = (LEAK_STEP,) * 3
    for sx, sy in seeds:
        if fill[sy + 1, sx + 1] == 0:
            cv2.floodFill(lab, fill, (sx, sy), 0, step, step, flags)
    leaked = fill[1:-1, 1:-1] == 2
    x0, y0, w, h = rect
    labels = np.full((h_img, w_img), cv2.GC_BGD, np.uint8)
    labels[y0:y0 + h, x0:x0 + w] = cv2.GC_PR_BGD
    labels[(mask > 0) & ~leaked] = cv2.GC_PR_FGD
    if not (labels == cv2.GC_PR_FGD).any():
        return None
    out = _clean_mask(_run_grabcut(image_bgr, labels, None, iterations, cv2.GC_INIT_WITH_MASK), rect)
    if out is None:
        return None
    # the box was drawn around the object: taking out a leak must not shrink it
    kept, before = np.array(cv2.boundingRect(out)[2:]), np.array(cv2.boundingRect(mask)[2:])
    return None if np.any(kept < LEAK_EXTENT * before) else out


def _prune(image_bgr: np.ndarray, mask: np.ndarray, box: tuple[float, float, float, float], rect,
           iterations: int, *, core_share: float = PRUNE_CORE, window: float = 0.0) -> np.ndarray | None:
    """``mask`` with the parts near its edge that have the colours of its surroundings taken
    out, or None when it has none.

    GrabCut's object model is learned from the whole box, so colours that are rare around the
    box but common inside it (the gap between two fingers over an orange disc, a panel beside
    a bust) can end up in the object.  The mask's core (distance to its edge at least
    ``core_share`` of the largest) is taken as surely object.  Outside it, with ``window`` 0,
    pixels whose colour (:data:`PRUNE_BINS` bins per BGR channel) is commoner outside the mask,
    within the box grown by a quarter of its size (as in :func:`colour_separation`), than in
    the core are marked probable background; with ``window`` > 0, pixels where the log-ratio
    of the two frequencies (each with half a count added per bin), averaged over a square of
    ``window`` times the box's smaller side, is positive: a region of the surroundings'
    colours is taken out whole even where some of its pixels have the object's colours (dark
    stripes on a panel beside a dark shirt).  The rest of the mask is probable object, and
    GrabCut runs again from these labels on the box grown by :data:`PRUNE_WINDOW` of its size
    on every side: its background model is learned from the object's surroundings, and the
    run costs the same on any size of frame.
    """
    import cv2

    # everything happens within the window GrabCut runs on (the mask lies in the box, and the
    # colours' window, a quarter of the box around it, lies within it too)
    ys, xs = _near_box(mask.shape, box, PRUNE_WINDOW)
    oy, ox = ys.start, xs.start
    inside = mask[ys, xs] > 0
    dist = cv2.distanceTransform(inside.astype(np.uint8), cv2.DIST_L2, 5)
    core = dist >= core_share * float(dist.max())
    shift = 8 - int(round(math.log2(PRUNE_BINS)))
    q = (image_bgr[ys, xs] >> shift).astype(np.int32)
    colour = (q[..., 0] * PRUNE_BINS + q[..., 1]) * PRUNE_BINS + q[..., 2]
    ny, nx = _near_box(mask.shape, box, 0.25)
    near = slice(ny.start - oy, ny.stop - oy), slice(nx.start - ox, nx.stop - ox)
    near_colour, near_in, near_core = colour[near], inside[near], core[near]
    n_bins = PRUNE_BINS ** 3
    x0, y0, w, h = rect
    n_core, n_out = int(near_core.sum()), int((~near_in).sum())
    in_core = np.bincount(near_colour[near_core], minlength=n_bins)
    outside = np.bincount(near_colour[~near_in], minlength=n_bins)
    if window > 0:
        ratio = np.log(((outside + 0.5) / (n_out + 0.5 * n_bins)) / ((in_core + 0.5) / (n_core + 0.5 * n_bins)))
        k = max(3, int(round(window * min(w, h)))) | 1
        surroundings = cv2.boxFilter(ratio.astype(np.float32)[colour], -1, (k, k)) > 0
    else:
        surroundings = (outside / max(1, n_out) > in_core / max(1, n_core))[colour]
    prune = inside & ~core & surroundings
    if not prune.any():
        return None
    labels = np.full(inside.shape, cv2.GC_BGD, np.uint8)
    labels[y0 - oy:y0 - oy + h, x0 - ox:x0 - ox + w] = cv2.GC_PR_BGD
    labels[inside & ~prune] = cv2.GC_PR_FGD
    out = np.zeros_like(mask)
    out[ys, xs] = _run_grabcut(np.ascontiguousarray(image_bgr[ys, xs]), labels, None, iterations,
                               cv2.GC_INIT_WITH_MASK)
    return _clean_mask(out, rect)
