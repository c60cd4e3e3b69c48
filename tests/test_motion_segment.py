"""``draw --box`` on a clip: what moves unlike the scene tells the object (trackcli.segment.motion).

A synthetic scene (320 x 240) seen by a panning camera: a cluttered background with a panel
of the object's own blue painted on it moves left with the pan, and a blue oval, on the first
frame touching the panel, moves right.  In one frame the panel's colour is the oval's; in the
next frames the panel goes with the scene and the oval does not.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from trackcli.segment import grabcut, motion
from trackcli.segment.masks import mask_iou

W, H = 320, 240
BLUE = (150, 70, 40)
CENTRE0 = (160.0, 125.0)
AXES = (34, 44)
PAN = 2.0      # the scene moves left this many pixels a frame
SPEED = 3.0    # the oval moves right this many pixels a frame
BOX = (100, 78, 96, 94)  # the oval on the first frame and the panel's right part


def background(rng: np.random.Generator) -> np.ndarray:
    """The scene, wider than the frame by the pan: clutter and a panel of the oval's blue."""
    wide = W + 40
    bg = np.clip(np.full((H, wide, 3), (110, 130, 115), float) + rng.normal(0, 8, (H, wide, 3)), 0, 255)
    bg = bg.astype(np.uint8)
    for _ in range(160):
        x, y = (int(v) for v in rng.integers(0, [wide, H]))
        a, n = rng.uniform(0, math.pi), rng.uniform(10, 40)
        shade = int(rng.choice([50, 200]))
        cv2.line(bg, (x, y), (int(x + n * math.cos(a)), int(y + n * math.sin(a))), (shade,) * 3, 2, cv2.LINE_AA)
    cv2.rectangle(bg, (80, 85), (128, 165), BLUE, -1)  # in the scene's coordinates; frame 0 shows x >= 0
    return bg


def frames(n: int, pan: float = PAN, speed: float = SPEED) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    bg = background(rng)
    out = []
    for k in range(n):
        shift = np.float32([[1, 0, -pan * k], [0, 1, 0]])
        img = cv2.warpAffine(bg, shift, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        c = (int(round(CENTRE0[0] + speed * k)), int(round(CENTRE0[1])))
        cv2.ellipse(img, c, AXES, 0, 0, 360, BLUE, -1, cv2.LINE_AA)
        out.append(np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8))
    return out


def oval() -> np.ndarray:
    m = np.zeros((H, W), np.uint8)
    cv2.ellipse(m, (int(CENTRE0[0]), int(CENTRE0[1])), AXES, 0, 0, 360, 255, -1)
    return m > 0


RECT = BOX  # whole pixels already


def test_the_oval_moves_unlike_the_panning_scene():
    f = frames(1 + motion.MOTION_FRAMES)
    residual = motion.motion_residual(f[0], f[1:], BOX)
    assert residual is not None and residual.shape == (H, W)
    moves = motion.moving(residual, RECT)
    assert moves is not None
    inside = np.zeros((H, W), bool)
    inside[BOX[1]:BOX[1] + BOX[3], BOX[0]:BOX[0] + BOX[2]] = True
    panel = inside & ~oval()
    # the oval moves against the scene; the panel, painted on it, moves with it
    assert np.median(residual[oval()]) > 3 * np.median(residual[panel])
    assert mask_iou(moves, oval()) > 0.7
    assert motion.agreement(oval().astype(np.uint8) * 255, moves, RECT) > 0.6
    assert motion.agreement(inside.astype(np.uint8) * 255, moves, RECT) == 0.0  # the whole box: nothing to tell


def test_a_still_scene_shows_no_moving_object():
    f = frames(1 + motion.MOTION_FRAMES, pan=0.0, speed=0.0)
    residual = motion.motion_residual(f[0], f[1:], BOX)
    assert residual is not None
    assert motion.moving(residual, RECT) is None
    seg = grabcut.segment_candidates(f[0], BOX, later=f[1:])
    assert seg.agreement is None
    plain = grabcut.segment_candidates(f[0], BOX)
    assert len(seg.masks) == len(plain.masks) and seg.chosen == plain.chosen
    assert all(np.array_equal(a, b) for a, b in zip(seg.masks, plain.masks))


def test_without_later_frames_there_is_no_motion_cue():
    f = frames(1)
    assert motion.motion_residual(f[0], [], BOX) is None


def test_the_motion_cue_takes_the_oval_without_the_panel():
    f = frames(1 + motion.MOTION_FRAMES)
    plain = grabcut.segment_candidates(f[0], BOX)
    seg = grabcut.segment_candidates(f[0], BOX, later=f[1:])
    assert seg.agreement is not None and len(seg.agreement) == len(seg.masks)
    # on the frame alone the panel's part in the box cannot be told from the oval ...
    assert mask_iou(plain.mask > 0, oval()) < 0.85
    # ... the next frames tell it
    assert mask_iou(seg.mask > 0, oval()) > 0.9
    assert seg.agreement[seg.chosen] == max(seg.agreement)


def test_the_motion_cue_is_the_same_on_every_run():
    f = frames(1 + motion.MOTION_FRAMES)
    a = grabcut.segment_candidates(f[0], BOX, later=f[1:])
    b = grabcut.segment_candidates(f[0], BOX, later=f[1:])
    assert a.chosen == b.chosen and a.agreement == b.agreement
    assert all(np.array_equal(x, y) for x, y in zip(a.masks, b.masks))


def test_later_frames_of_another_size_give_no_cue():
    f = frames(2)
    assert motion.motion_residual(f[0], [cv2.resize(f[1], (W // 2, H // 2))], BOX) is None


def test_a_box_covering_the_frame_gives_no_cue():
    f = frames(2)
    assert motion.motion_residual(f[0], f[1:], (0, 0, W, H)) is None


@pytest.mark.parametrize("agreement, tried", [((0.6, 0.58), [0, 1]), ((0.6, 0.1), [0])])
def test_draw_tries_only_the_masks_as_much_what_moves_as_the_choice(monkeypatch, agreement, tried):
    """The trial over the next frames (trackcli.run.confirm) comes after the motion: a still
    region is easily held, so masks much less what moves than the choice are not tried."""
    from trackcli.io.video import Frame
    from trackcli.run import confirm, drawing
    from trackcli.run.clips import no_progress

    a, b = oval().astype(np.uint8) * 255, np.zeros((H, W), np.uint8)
    b[90:170, 100:200] = 255
    seg = grabcut.Segmentation((a, b), 0, "GrabCut", agreement)
    seen = []

    def spy(masks, order, fit, frames, fps, **kw):
        seen.extend(order)
        return order[0], []

    monkeypatch.setattr(confirm, "confirm", spy)

    after = [Frame(i, i / 25.0, np.zeros((H, W, 3), np.uint8)) for i in range(1, 20)]
    mask, note = drawing.confirm_mask(seg, Frame(0, 0.0, np.zeros((H, W, 3), np.uint8)), after, 25.0,
                                      lambda m: None, lambda label, n: no_progress())
    assert np.array_equal(mask, a) and note == ""
    assert seen == (tried if len(tried) > 1 else [])


def test_draw_box_on_the_clip_outlines_the_oval_without_the_panel(tmp_path):
    """As a user runs it: ``draw --box`` on the clip (a folder of lossless frames) gives the
    oval's outline.  (With JPEG frames GrabCut takes the panel back in: its colour is the
    oval's exactly, and the motion only seeds GrabCut's colour models; docs/drawing.md.)"""
    from click.testing import CliRunner

    from trackcli.cli import cli
    from trackcli.shapes import draw
    from trackcli.shapes.spline import dense_polygon
    from trackcli.shapes.template import load_template

    clip = tmp_path / "pan"
    clip.mkdir()
    for k, img in enumerate(frames(20)):
        assert cv2.imwrite(str(clip / f"{k:04d}.png"), img)
    out = tmp_path / "t.yaml"
    result = CliRunner().invoke(cli, ["draw", str(clip), "--box", ",".join(map(str, BOX)), "-o", str(out)])
    assert result.exit_code == 0, result.output
    t = load_template(out)
    drawn = draw.polygon_mask(dense_polygon(t.Q, t.basis(), 400), (W, H))
    assert mask_iou(drawn > 0, oval()) > 0.85
