"""``draw --box`` asks the next frames which mask is the object (trackcli.run.confirm).

A synthetic scene (320 x 240): a blue oval moves right over a cluttered background, and on the
first frame it touches a panel of its own blue that stands still.  A mask that takes the panel
in cannot be told from the oval's own on that frame; on the frames after it the oval leaves
the panel behind.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from trackcli.io.video import Frame
from trackcli.run import confirm
from trackcli.run import drawing
from trackcli.segment import grabcut
from trackcli.segment.masks import mask_iou, mask_outline
from trackcli.shapes import draw

W, H = 320, 240
BLUE = (150, 70, 40)
CENTRE0 = (150.0, 125.0)
AXES = (34, 44)
PANEL = (70, 85, 118, 165)  # x0, y0, x1, y1: beside the oval's left side on the first frame


def scene(frames: int, speed: float) -> list[Frame]:
    rng = np.random.default_rng(3)
    bg = np.clip(np.full((H, W, 3), (110, 130, 115), float) + rng.normal(0, 5, (H, W, 3)), 0, 255).astype(np.uint8)
    for _ in range(80):
        x, y = (int(v) for v in rng.integers(0, [W, H]))
        a, n = rng.uniform(0, math.pi), rng.uniform(10, 40)
        shade = int(rng.choice([50, 200]))
        cv2.line(bg, (x, y), (int(x + n * math.cos(a)), int(y + n * math.sin(a))), (shade,) * 3, 1, cv2.LINE_AA)
    x0, y0, x1, y1 = PANEL
    cv2.rectangle(bg, (x0, y0), (x1, y1), BLUE, -1)
    for x in range(x0 + 3, x1, 8):  # dark stripes: the panel's own edges
        cv2.line(bg, (x, y0), (x, y1), (90, 40, 25), 2)
    out = []
    for k in range(frames):
        img = bg.copy()
        noise = rng.normal(0, 3, img.shape)
        c = (int(round(CENTRE0[0] + speed * k)), int(round(CENTRE0[1])))
        cv2.ellipse(img, c, AXES, 0, 0, 360, BLUE, -1, cv2.LINE_AA)
        out.append(Frame(k, k / 25.0, np.clip(img + noise, 0, 255).astype(np.uint8)))
    return out


def masks() -> list[np.ndarray]:
    oval = np.zeros((H, W), np.uint8)
    cv2.ellipse(oval, (int(CENTRE0[0]), int(CENTRE0[1])), AXES, 0, 0, 360, 255, -1)
    with_panel = oval.copy()
    x0, y0, x1, y1 = PANEL
    with_panel[y0 : y1 + 1, x0 : x1 + 1] = 255
    return [with_panel, oval]


def fit(mask: np.ndarray):
    return drawing.fit_template(mask_outline(mask), drawing.DEFAULT_CTRL, frame_size=(W, H), _quiet=True)


@pytest.fixture(scope="module")
def moving() -> list[Frame]:
    return scene(confirm.CONFIRM_FRAMES, 2.5)


def test_the_mask_without_the_still_panel_is_taken_when_the_object_moves(moving):
    best, trials = confirm.confirm(masks(), confirm.to_try(masks(), 0), fit, moving, 25.0)
    assert best == 1
    assert [t.index for t in trials] == [0, 1]
    assert trials[1].beats(trials[0])


def test_the_frames_choice_stands_when_it_is_the_object(moving):
    best, trials = confirm.confirm(masks(), confirm.to_try(masks(), 1), fit, moving, 25.0)
    assert best == 1
    assert not trials[1].beats(trials[0])


def test_a_still_object_leaves_the_frames_choice():
    still = scene(confirm.CONFIRM_FRAMES, 0.0)
    assert confirm.confirm(masks(), confirm.to_try(masks(), 0), fit, still, 25.0)[0] == 0


def test_the_choice_is_the_same_on_every_run(moving):
    a = confirm.confirm(masks(), confirm.to_try(masks(), 0), fit, moving, 25.0)[1]
    b = confirm.confirm(masks(), confirm.to_try(masks(), 0), fit, moving, 25.0)[1]
    assert a == b


def test_masks_alike_are_tried_once():
    m = masks()
    nearly = m[1].copy()
    nearly[int(CENTRE0[1]), int(CENTRE0[0]) + AXES[0]] = 0  # one pixel off the oval's
    assert confirm.to_try([m[0], nearly, m[1]], 0) == [0, 1]
    assert confirm.to_try([m[0], nearly, m[1]], 2) == [2, 0]


def test_the_rule_needs_all_three_gains():
    base = confirm.Trial(0, confidence=0.85, score=100.0, held=0.75)
    assert confirm.Trial(1, 0.90, 120.0, 0.90).beats(base)
    assert not confirm.Trial(1, 0.87, 120.0, 0.90).beats(base)  # confidence: +0.02
    assert not confirm.Trial(1, 0.90, 120.0, 0.80).beats(base)  # held: +0.05
    assert not confirm.Trial(1, 0.95, 105.0, 1.00).beats(base)  # score: +5 %, a weak template held
    # a first frame with nothing to keep (held NaN) is beaten only by one that keeps something
    assert confirm.Trial(1, 0.90, 120.0, 0.5).beats(confirm.Trial(0, 0.85, 100.0, math.nan))
    assert not confirm.Trial(1, 0.90, 120.0, math.nan).beats(base)
    assert not confirm.Trial(1, 0.90, 120.0, math.nan).beats(confirm.Trial(0, 0.85, 100.0, math.nan))


def write_clip(path, frames: list[Frame]):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (W, H))
    assert writer.isOpened()
    for f in frames:
        writer.write(f.image)
    writer.release()
    return path


BOX = "112,78,76,94"  # around the oval on the first frame, the panel's right part inside it


def draw_box(tmp_path, clip, *args):
    from click.testing import CliRunner

    from trackcli.cli import cli
    from trackcli.shapes.template import load_template

    out = tmp_path / "t.yaml"
    result = CliRunner().invoke(cli, ["draw", str(clip), "--box", BOX, "-o", str(out), *args])
    assert result.exit_code == 0, result.output
    return load_template(out)


def test_draw_keeps_the_mask_the_next_frames_hold(tmp_path, moving, monkeypatch):
    """``draw --box`` hands its candidates and the frames from the drawn one to ``confirm``
    and keeps the mask it returns, saying so in the template's source."""
    clip = write_clip(tmp_path / "moving.avi", scene(30, 2.5))
    seen = {}

    def segment(image, box, **kw):
        return grabcut.Segmentation(tuple(masks()), 0, "GrabCut")

    real = confirm.confirm

    def spy(ms, order, fit, frames, fps, **kw):
        seen.update(n=len(frames), first=frames[0].index, fps=fps)
        return real(ms, order, fit, frames, fps, **kw)

    monkeypatch.setattr(grabcut, "segment_candidates", segment)
    monkeypatch.setattr(confirm, "confirm", spy)
    t = draw_box(tmp_path, clip, "--frame", "3")
    assert seen == {"n": confirm.CONFIRM_FRAMES, "first": 3, "fps": 25.0}
    assert "held best" in t.source
    from trackcli.shapes.spline import dense_polygon

    drawn = draw.polygon_mask(dense_polygon(t.Q, t.basis(), 400), (W, H))
    assert mask_iou(masks()[1], drawn) > 0.9


@pytest.mark.parametrize("after", [confirm.CONFIRM_LEAST - 1, confirm.CONFIRM_LEAST])
def test_draw_asks_the_next_frames_only_when_there_are_enough(tmp_path, monkeypatch, after):
    """Fewer than CONFIRM_LEAST frames after the drawn one (near the clip's end): no trial,
    and the frame's choice stands; with CONFIRM_LEAST of them the masks are tried on them all."""
    n = 20
    clip = write_clip(tmp_path / "short.avi", scene(n, 2.5))
    monkeypatch.setattr(grabcut, "segment_candidates",
                        lambda image, box, **kw: grabcut.Segmentation(tuple(masks()), 0, "GrabCut"))
    seen = []
    real = confirm.trial

    def spy(template, frames, fps, index=0):
        if after < confirm.CONFIRM_LEAST:
            raise AssertionError("tried the masks without the frames to try them on")
        seen.append([f.index for f in frames])
        return real(template, frames, fps, index)

    monkeypatch.setattr(confirm, "trial", spy)
    t = draw_box(tmp_path, clip, "--frame", str(n - 1 - after))
    if after < confirm.CONFIRM_LEAST:
        assert "held best" not in t.source
    else:
        assert seen == [list(range(n - 1 - after, n))] * 2  # both masks, the drawn frame and the 8 after it


def test_a_trial_needs_a_frame_after_the_drawn_one(moving):
    with pytest.raises(ValueError):
        confirm.trial(fit(masks()[1]), moving[:1], 25.0)
