"""Making templates without a mouse: from points, an ellipse, a box or a mask.

Every route ends the same way: an ordered outline polygon ``(P, 2)`` in image ``(x, y)``
pixels, to which a B-spline with a chosen number of control points is fitted by least
squares (:func:`trackcli.shapes.spline.fit`).

- ``--points``: the polygon is given.
- ``--ellipse cx,cy,a,b[,angle]``: the polygon is sampled from the ellipse (angle in degrees,
  clockwise on screen since ``y`` points down).
- ``--box x,y,w,h``: the object inside the box is segmented with GrabCut (OpenCV), seeded by
  the box (outside = background; on a grey frame with its local texture too), and the outline
  of the largest region is traced.
- ``--mask FILE``: a binary image (non-zero = object); the outline of its largest region.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from trackcli.errors import ConfigError, DataError, InputError, short_repr

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------------------------
# Parsing user input


def parse_numbers(text: str, count: int | tuple[int, int], what: str,
                  error: type[Exception] = ConfigError) -> list[float]:
    """Parse ``"a,b,c"`` into floats, checking how many there are.

    Raises ``error``: ConfigError (an invalid option value) by default, InputError for a
    line of an input file.
    """
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise error(f"{what}: expected comma-separated numbers, got {short_repr(text)}") from None
    lo, hi = (count, count) if isinstance(count, int) else count
    if not lo <= len(values) <= hi:
        n = str(lo) if lo == hi else f"{lo} to {hi}"
        raise error(f"{what}: expected {n} numbers, got {len(values)} in {short_repr(text)}")
    if not all(np.isfinite(values)):
        raise error(f"{what}: numbers must be finite, got {short_repr(text)}")
    return values


def parse_points(spec: str) -> np.ndarray:
    """Ordered points from ``"x1,y1 x2,y2 ..."`` (or ``x1,y1,x2,y2,...``) or from a file of them.

    A file holds one ``x,y`` (or ``x y``) pair per line; blank lines and lines starting with
    ``#`` are ignored.  Returns an array of shape ``(P, 2)``.
    """
    path = Path(spec)
    looks_numeric = re.fullmatch(r"[\d.,\s+\-eE]+", spec) is not None
    if not looks_numeric:
        if not path.is_file():
            raise ConfigError(f"--points: {short_repr(spec)} is neither x,y pairs nor an existing points file")
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise InputError(f"{path}: cannot read points file ({exc.strerror or exc})") from None
        rows = []
        for k, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if line and not line.startswith("#"):
                rows.append(parse_numbers(line, 2, f"{spec} line {k}", InputError))
        pts = np.asarray(rows, dtype=float).reshape(-1, 2)
        if len(pts) < 3:
            raise InputError(f"{spec}: need at least 3 points, got {len(pts)}")
    else:
        values = parse_numbers(spec, (0, 10**6), "--points")
        if len(values) % 2:
            raise ConfigError(f"--points: expected x,y pairs, got an odd count of numbers ({len(values)})")
        pts = np.asarray(values, dtype=float).reshape(-1, 2)
    if len(pts) < 3:
        raise ConfigError(f"--points: need at least 3 points, got {len(pts)}")
    return pts


# ---------------------------------------------------------------------------------------------
# Outlines

#: Smallest width and height (px) of the part of an outline inside the frame, and of a frame.
MIN_OUTLINE_SIDE = 8
#: a closed outline's least mean width, px (area over half its perimeter)
MIN_OUTLINE_WIDTH = 1.0


def check_frame_size(frame_size: tuple[int, int], clip: str) -> None:
    """Raise DataError if frames of ``frame_size = (w, h)`` are too small to draw on."""
    w, h = frame_size
    if w < MIN_OUTLINE_SIDE or h < MIN_OUTLINE_SIDE:
        raise DataError(f"{clip}: frames are {w}x{h} px, too small to draw a template on "
                        f"(at least {MIN_OUTLINE_SIDE}x{MIN_OUTLINE_SIDE})")


def check_outline_in_frame(outline: np.ndarray, frame_size: tuple[int, int], what: str, *,
                           closed: bool = True) -> None:
    """Raise ConfigError if the outline ``(P, 2)`` is tiny or lies (almost) outside the frame.

    The rule is the one ``--box`` follows: the outline's bounding box, cut to the frame
    ``(w, h)``, must be at least :data:`MIN_OUTLINE_SIDE` px wide and high (an open curve:
    wide or high).  A closed outline must also enclose an area: its mean width (area over
    half the perimeter) at least :data:`MIN_OUTLINE_WIDTH` px, which points on a line, or a
    path that doubles back on itself, do not have.
    """
    w, h = frame_size
    pts = np.asarray(outline, dtype=float)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = hi - lo
    if (size.min() if closed else size.max()) < MIN_OUTLINE_SIDE:
        raise ConfigError(f"{what}: the outline spans only {size[0]:.3g}x{size[1]:.3g} px (at least "
                          f"{MIN_OUTLINE_SIDE} px {'each way' if closed else 'one way'})")
    if closed:
        from trackcli.shapes.spline import polygon_area_centroid

        area = abs(float(polygon_area_centroid(pts)[0]))
        half_perimeter = 0.5 * float(np.hypot(*(np.roll(pts, -1, axis=0) - pts).T).sum())
        if area < MIN_OUTLINE_WIDTH * half_perimeter:
            raise ConfigError(f"{what}: the outline encloses almost no area ({area:.1f} px²; its points lie on "
                              "a line, or the path doubles back on itself): give points in order around the object")
    inside = np.minimum(hi, [w - 1.0, h - 1.0]) - np.maximum(lo, 0.0)
    if inside.min() < 0 or (inside.min() if closed else inside.max()) < MIN_OUTLINE_SIDE:
        raise ConfigError(f"{what}: the outline lies (almost) outside the {w}x{h} frame "
                          f"(at least {MIN_OUTLINE_SIDE}x{MIN_OUTLINE_SIDE} px of it must be inside)")


def ellipse_outline(cx: float, cy: float, a: float, b: float, angle_deg: float = 0.0, n: int = 256) -> np.ndarray:
    """Points ``(n, 2)`` on an ellipse with semi-axes ``a`` (along x before rotation) and ``b``."""
    if a <= 0 or b <= 0:
        raise ConfigError(f"--ellipse: semi-axes must be positive, got a={a:g}, b={b:g}")
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    x, y = a * np.cos(t), b * np.sin(t)
    return np.column_stack([cx + c * x - s * y, cy + s * x + c * y])


def mask_outline(mask: np.ndarray) -> np.ndarray:
    """Outline ``(P, 2)`` of the largest region of a binary mask, as an ordered polygon."""
    import cv2

    m = (np.asarray(mask) > 0).astype(np.uint8)
    if m.ndim != 2:
        raise InputError(f"mask must be a 2-D image, got shape {m.shape}")
    contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise DataError("the mask contains no object (no non-zero pixels)")
    c = max(contours, key=cv2.contourArea)
    if cv2.contourArea(c) < 9:
        raise DataError("the mask's largest region is too small to outline (under 9 px)")
    return c[:, 0, :].astype(float)


def load_mask(path: str | Path, frame_size: tuple[int, int] | None = None) -> np.ndarray:
    """Read a binary mask image (non-zero = object); check its size against the frame."""
    import cv2

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such mask file")
    m = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise InputError(f"{p}: not an image OpenCV can read")
    if frame_size is not None and (m.shape[1], m.shape[0]) != tuple(frame_size):
        raise InputError(f"{p}: mask is {m.shape[1]}x{m.shape[0]} but the frame is {frame_size[0]}x{frame_size[1]}")
    return m


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
#: a fit that strayed from the outline is replaced by a fit without folds when that covers the
#: object (IoU with the outline) by at least this much more than the convex hull does; else
#: the hull is taken
REFIT_GAIN = 0.1
#: control points of ``draw`` when none are asked for; an outline with detail that many cannot
#: follow (an open hand's fingers) is fitted with DETAIL_CTRL before the convex hull is taken
DEFAULT_CTRL = 12
DETAIL_CTRL = 24


def segment_runs(image_bgr: np.ndarray) -> int:
    """The GrabCut runs :func:`segment_box` makes at most on this frame (its ``progress`` steps):
    the whole frame and the box's surroundings, each possibly again without a leak (4); on a
    colour frame each of these masks possibly again pruned by colour and by regions (12), on a
    grey frame all of it again on its texture image (8)."""
    from trackcli.observe.discriminant import is_grey

    return 8 if is_grey(image_bgr) else 12


@dataclasses.dataclass(frozen=True, eq=False)
class Segmentation:
    """The masks :func:`segment_candidates` found for a box and the one it chose.

    ``masks`` are uint8 masks of the frame's size (0 or 255), the candidates among which the
    choice of :func:`segment_box` is made (those spanning the box, see there); ``chosen`` is
    the index of that choice and ``method`` how it was found (``"GrabCut"``, or
    :data:`FALLBACK_METHOD`, whose only mask is the ellipse inscribed in the box).
    """

    masks: tuple[np.ndarray, ...]
    chosen: int
    method: str

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
                       progress: Callable[[int], None] | None = None) -> Segmentation:
    """The candidate masks of :func:`segment_box` for ``box`` and its choice among them (see
    there), for a caller that can judge them further (``draw --box`` tracks them over the
    frames that follow, :mod:`trackcli.run.confirm`)."""
    import cv2

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
        masks, chosen, method = _segment(big, (seg[0] + p, seg[1] + p, seg[2], seg[3]),
                                         (x0 + p, y0 + p, x1 - x0, y1 - y0), iterations, progress)
        masks = [np.ascontiguousarray(m[p:-p, p:-p]) for m in masks]
    else:
        masks, chosen, method = _segment(image_bgr, box, (x0, y0, x1 - x0, y1 - y0), iterations, progress)
    if method == FALLBACK_METHOD:
        log.warning("--box %g,%g,%g,%g: automatic segmentation found no clear object; using the ellipse "
                    "inscribed in the box", x, y, w, h)
    return Segmentation(tuple(masks), chosen, method)


#: the method :func:`segment_box` names when GrabCut found no object
FALLBACK_METHOD = "inscribed ellipse"


def _segment(image_bgr: np.ndarray, box: tuple[float, float, float, float], rect: tuple[int, int, int, int],
             iterations: int, progress: Callable[[int], None] | None = None) -> tuple[list[np.ndarray], int, str]:
    """:func:`segment_candidates` of a checked box, ``rect`` its whole-pixel part inside the
    frame: ``(masks, chosen, method)``."""
    import cv2

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
    candidates = [c for c in candidates if c is not None]
    if not candidates:
        # GrabCut finds nothing convincing (small or low-contrast objects): the ellipse
        # inscribed in the box is the honest fallback, and the user is told (segment_box)
        fallback = np.zeros((h_img, w_img), np.uint8)
        box_rr = (((x0 + x1) / 2.0, (y0 + y1) / 2.0), (float(x1 - x0), float(y1 - y0)), 0.0)
        cv2.ellipse(fallback, box_rr, 255, -1)
        return [fallback], 0, FALLBACK_METHOD
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
    if any(sp >= BOX_SPAN for sp in spans):
        candidates, spans = map(list, zip(*[(c, sp) for c, sp in zip(candidates, spans) if sp >= BOX_SPAN]))
    # the first (the whole-frame mask, the older default) stays unless another one is clearly better
    separation = [colour_separation(image_bgr, c, box) if texture is None else texture_separation(texture, c, box)
                  for c in candidates]
    score = [_choice_score(sep, sp) for sep, sp in zip(separation, spans)]
    best = int(np.argmax(score))
    # SEPARATION_MARGIN of 1 - BC about the whole-frame mask's BC, on the distance -ln BC
    margin = SEPARATION_MARGIN / max(1.0 - separation[0], 1e-6)
    return candidates, (best if score[best] > score[0] + margin else 0), "GrabCut"


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


def polygon_mask(points: np.ndarray, frame_size: tuple[int, int]) -> np.ndarray:
    """Rasterise a closed polygon ``(P, 2)`` into a uint8 mask of ``frame_size = (w, h)``."""
    import cv2

    w, h = frame_size
    m = np.zeros((h, w), np.uint8)
    pts = np.round(np.asarray(points) * 16).astype(np.int32).reshape(-1, 1, 2)
    cv2.fillPoly(m, [pts], 255, lineType=cv2.LINE_8, shift=4)
    return m


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two binary masks."""
    a, b = np.asarray(a) > 0, np.asarray(b) > 0
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 0.0


# ---------------------------------------------------------------------------------------------
# Templates and previews


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
    from trackcli.shapes.fit import fit
    from trackcli.shapes.template import Template

    outline = np.asarray(outline, dtype=float)
    if closed:
        outline = canonical_start(outline)
    if len(outline) < n_ctrl:
        # too few points to pin every control point: resample the polygon densely first
        outline = _resample_polygon(outline, max(4 * n_ctrl, 64), closed)
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
        t = make(fit(_resample_polygon(pts, max(16 * n_ctrl, 192), True), n_ctrl, degree=degree, closed=True,
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
    hull = _resample_polygon(canonical_start(hull), max(8 * n_ctrl, 128), True)
    # strict: without it the refinement folded the curve back along the hull's straight sides
    # (crossing's pedestrian, 30 runs: P@20 0.80 with the folded template, 0.97)
    warn("the outline has detail %d control points cannot follow (fit %.0f px off it); "
         "using its convex hull (more control points: --n-ctrl)", n_ctrl, err)
    return make(fit(hull, n_ctrl, degree=degree, closed=True, strict=True), " (convex hull)")


def fit_error(template, outline: np.ndarray) -> float:
    """Largest distance (px) from the template's curve to the closed polygon ``outline``."""
    import cv2

    from trackcli.shapes.spline import dense_polygon

    poly = dense_polygon(template.Q, template.basis())
    contour = np.asarray(outline, dtype=np.float32).reshape(-1, 1, 2)
    return max(abs(cv2.pointPolygonTest(contour, (float(x), float(y)), True)) for x, y in poly)


def canonical_start(outline: np.ndarray) -> np.ndarray:
    """Order a closed outline clockwise on screen, starting at its topmost point.

    Templates of the same object drawn on different frames then have control points in
    correspondence (control point 0 at the top), which models placed on a new clip rely on.
    """
    x, y = outline[:, 0], outline[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    if area2 < 0:  # counter-clockwise on screen (y down): reverse
        outline = outline[::-1]
    top = outline[:, 1].min()
    near_top = np.flatnonzero(outline[:, 1] <= top + 0.5)
    # among the topmost points take the middle one, so flat tops start at their centre
    cx = outline[near_top, 0].mean()
    start = near_top[np.argmin(np.abs(outline[near_top, 0] - cx))]
    return np.roll(outline, -int(start), axis=0)


def _resample_polygon(points: np.ndarray, n: int, closed: bool) -> np.ndarray:
    pts = np.vstack([points, points[:1]]) if closed else points
    seg = np.hypot(*np.diff(pts, axis=0).T)
    t = np.concatenate([[0.0], np.cumsum(seg)])
    u = np.linspace(0.0, t[-1], n, endpoint=not closed)
    return np.column_stack([np.interp(u, t, pts[:, 0]), np.interp(u, t, pts[:, 1])])


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
