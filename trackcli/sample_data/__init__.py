"""Synthetic clips with exact ground truth, for the demo and for tests that pin accuracy.

Four clips, each 480×360 at 25 fps, are rendered from a seed:

``train``
    One head-and-shoulders silhouette moving gently over a clean background (smooth
    gradient, light fixed-pattern noise).  Each pose parameter ``tx, ty, angle, scale`` is an
    independent second-order auto-regressive process -- a damped oscillator driven by white
    noise, AC eqs 9.24–9.25 -- rescaled to a few pixels per frame, ±8° and ±8 %, so AR(2)
    dynamics learned from the clip have a known answer (recorded in the outline file).
``test``
    The same object moving agilely (velocity switching every few frames, sudden reversals,
    peak speeds of 12–15 px/frame) over heavy clutter: lines at many angles, text-like
    strokes, texture and static look-alike silhouettes, some only partly drawn (none where
    the object stands in the first frame, on which a template is drawn); a pole passes in
    front of the object for about ten frames.
``three_heads``
    Three similar heads (paper 000 §5.1), of nearly the same size (scales 0.95, 0.97, 1):
    two stand roughly still, the third walks from the right to the left in front of them
    (drawn on top).  The person on the left stands against a plain wall, the one in the
    middle in front of a door frame; a picture and book shelves hang above head height on
    the right, so that the three outlines are about equally visible when apart.
``bouncing_ball``
    A ball in parabolic flight over a floor, losing energy at each bounce, where its
    vertical velocity reverses within one frame (paper 001 §8).

Ground truth
------------
Every clip has a *base outline*: a dense closed polygon ``(P, 2)`` in object coordinates,
centred on its area centroid, ordered counter-clockwise as seen on the screen (``y``
down), so its shoelace signed area in ``(x, y)`` is negative.  In frame ``k`` object ``j``
is exactly the region bounded by the base outline mapped by the similarity

    ``p_image = scale · R(angle) · p + (tx, ty)``,  ``R(a) = [[cos a, −sin a], [sin a, cos a]]``,

with ``angle`` in radians from ``+x`` towards ``+y`` (clockwise on the screen), as in
:mod:`trackcli.shapes.shape_space`.  Frames are rendered from that polygon with 8×8 supersampled
coverage, so the rendered edge lies within a few hundredths of a pixel of the truth.

``<clip>.truth.csv`` has one row per frame and object:

=========================  =================================================================
``frame``                  frame index, from 0
``time``                   ``frame / fps`` in seconds
``object``                 object index, from 0 (see the outline file for which is which)
``cx, cy``                 area centroid of the true outline (pixels)
``bbox_x … bbox_h``        tight box ``(x, y, w, h)`` of the true outline; it may extend
                           outside the image
``tx, ty, angle, scale``   the similarity above
``visible``                fraction of the object's area that is inside the image and not
                           hidden by anything drawn in front of it (0 to 1)
=========================  =================================================================

``<clip>.outline.json`` holds the base outline (``points``), ``format: 1``, the clip's frame
rate, size, frame count and seed, which object is which, and the parameters of the motion.
:func:`true_outline` places it for one row of the truth, :func:`place_outlines` for every row
(as ``trackcli eval`` does, through :mod:`trackcli.run.truth`).

Determinism: the truth and outline files depend only on the seed and the frame count and
are byte-identical between runs; each clip draws from its own stream
``numpy.random.SeedSequence([seed, clip_key])``.  A clip shortened with ``n_frames`` is the
first ``n_frames`` frames of the full clip.  Videos are written with OpenCV's VP9 encoder
(``vp09`` in ``.mp4``); where that encoder is missing, Motion-JPEG in ``.avi`` is used instead.
"""

from __future__ import annotations

from trackcli.sample_data.common import N_OUTLINE_POINTS, CLIP_NAMES, DEFAULT_SEED, FPS, FRAME_SIZE, TRUTH_COLUMNS
from trackcli.sample_data.geometry import circle_outline, head_and_shoulders, place_outlines, polygon_area, polygon_centroid, similarity, true_outline
from trackcli.sample_data.truth import Outline, Truth, load_outline, load_truth
from trackcli.sample_data.write import clip_truth, default_n_frames, generate, make_bouncing_ball, make_test, make_three_heads, make_train, render_frames, write_clip

__all__ = [
    "CLIP_NAMES",
    "N_OUTLINE_POINTS",
    "DEFAULT_SEED",
    "FPS",
    "FRAME_SIZE",
    "TRUTH_COLUMNS",
    "Outline",
    "Truth",
    "circle_outline",
    "clip_truth",
    "default_n_frames",
    "generate",
    "head_and_shoulders",
    "load_outline",
    "load_truth",
    "make_bouncing_ball",
    "make_test",
    "make_three_heads",
    "make_train",
    "place_outlines",
    "polygon_area",
    "polygon_centroid",
    "render_frames",
    "similarity",
    "true_outline",
    "write_clip",
]
