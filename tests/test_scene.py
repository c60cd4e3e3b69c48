"""The still-scene test: a curve on pixels that kept the first frame's colour lies on the scene."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trackcli.observe.appearance import in_first_light
from trackcli.observe.scene import StillScene


def textured(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Colour texture (smoothed noise) with structure at a few pixels, (h, w, 3) in 0..255."""
    img = rng.uniform(0, 255, (*shape, 3)).astype(np.float32)
    return np.clip((cv2.GaussianBlur(img, (0, 0), 2.0) - 128.0) * 4.0 + 128.0, 0, 255)


def circle(cx: float, cy: float, r: float, m: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """``m`` points on a circle and their outward unit normals, each (m, 2)."""
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    nrm = np.stack([np.cos(t), np.sin(t)], axis=1)
    return np.array([cx, cy]) + r * nrm, nrm


def disc(img: np.ndarray, cx: float, cy: float, r: float, colour) -> np.ndarray:
    out = img.copy()
    cv2.circle(out, (int(cx), int(cy)), int(r), colour, -1)
    return out


def own_place(shape, cx=60, cy=60, r=20) -> np.ndarray:
    own = np.zeros(shape[:2], np.uint8)
    cv2.circle(own, (cx, cy), r, 1, -1)
    return own


@pytest.fixture(scope="module")
def scene():
    """A textured first frame with the object (a flat disc) about (60, 60) and a look-alike
    (the same disc) standing at (200, 150)."""
    rng = np.random.default_rng(0)
    first = disc(disc(textured(rng, (240, 320)), 60, 60, 20, (40, 160, 60)), 200, 150, 20, (40, 160, 60))
    return rng, first, StillScene(first, own_place(first.shape), size=36.0)


def later(rng, img, gain=1.0, offset=0.0, noise=3.0) -> np.ndarray:
    return np.clip(img * gain + offset + rng.normal(0, noise, img.shape), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("gain,offset", [(1.0, 0.0), (1.2, -10.0), (0.8, 15.0)])
def test_a_look_alike_standing_where_it_stood_is_still_whatever_the_exposure(scene, gain, offset):
    rng, first, still = scene
    smap = still.compare(later(rng, first, gain, offset))
    assert still.stillness(smap, *circle(200, 150, 20)) == 1.0
    assert still.stillness(smap, *circle(130, 200, 25)) == 1.0  # the scene itself


def test_the_object_where_it_was_not_is_not_still(scene):
    rng, first, still = scene
    frame = disc(first, 120, 180, 20, (40, 160, 60))  # the object moved on the textured scene
    smap = still.compare(later(rng, frame, 1.1, -5.0))
    assert still.stillness(smap, *circle(120, 180, 20)) == 0.0
    assert still.stillness(smap, *circle(200, 150, 20)) == 1.0


def test_the_objects_own_place_is_never_judged(scene):
    rng, first, still = scene
    smap = still.compare(later(rng, first))  # the object stands still where it started
    assert still.stillness(smap, *circle(60, 60, 20)) == 0.0
    kept, usable = still.kept_share(smap, *circle(60, 60, 20))
    assert usable == 0.0


def test_a_moving_camera_leaves_nothing_still(scene):
    rng, first, still = scene
    smap = still.compare(np.roll(later(rng, first), 9, axis=1))
    pts, nrm = zip(*(circle(x, y, 20) for x in (120, 200, 260) for y in (60, 150, 200)))
    got = still.stillness(smap, np.stack(pts), np.stack(nrm))
    assert got.shape == (9,)
    assert got.max() < 0.2


def test_many_curves_at_once_and_a_frame_of_another_size(scene):
    rng, first, still = scene
    smap = still.compare(later(rng, first))
    curves = [circle(200, 150, 20), circle(60, 60, 20), circle(-100, -100, 10)]
    pts = np.stack([c[0] for c in curves])[None]
    nrm = np.stack([c[1] for c in curves])[None]
    got = still.stillness(smap, pts, nrm)
    assert got.shape == (1, 3)
    assert got[0].tolist() == [1.0, 0.0, 0.0]  # off the frame: nothing to judge
    smap = still.compare(np.zeros((100, 100, 3), np.uint8))
    assert np.all(still.stillness(smap, pts, nrm) == 0.0)


def test_grey_frames_and_large_objects_on_reduced_frames():
    rng = np.random.default_rng(3)
    small = textured(rng, (180, 320))[:, :, 1]
    first = cv2.resize(small, (1280, 720), interpolation=cv2.INTER_LINEAR)
    still = StillScene(first, own_place(first.shape, 200, 200, 80), size=160.0)
    assert still.k == 4
    moved = first.copy()
    cv2.circle(moved, (800, 400), 80, 30.0, -1)
    smap = still.compare(later(rng, moved, 1.1, -5.0))
    assert still.stillness(smap, *circle(800, 400, 80)) == 0.0
    assert still.stillness(smap, *circle(500, 500, 80)) == 1.0


def test_letterbox_bars_are_never_judged():
    rng = np.random.default_rng(5)
    first = textured(rng, (240, 320))
    first[:30] = 0
    first[210:] = 0
    still = StillScene(first, own_place(first.shape), size=36.0, area=(0, 30, 320, 210))
    smap = still.compare(later(rng, first))
    kept, usable = still.kept_share(smap, *circle(200, 10, 20))  # mostly on the top bar
    assert usable < 0.4 and still.stillness(smap, *circle(200, 10, 20)) == 0.0
    assert still.stillness(smap, *circle(200, 120, 20)) == 1.0


@pytest.mark.parametrize("gain,offset", [(1.0, 0.0), (1.25, -10.0), (0.8, 15.0)])
def test_a_change_of_the_light_over_the_scene_is_measured_and_undone(scene, gain, offset):
    rng, first, still = scene
    frame = disc(first, 120, 180, 20, (40, 160, 60))  # the object moved, and the light changed
    smap, exposure = still.measure(later(rng, frame, gain, offset, noise=1.0))
    assert exposure is not None
    np.testing.assert_allclose(exposure[0], gain, atol=0.03)
    np.testing.assert_allclose(exposure[1], offset, atol=4.0)
    assert still.stillness(smap, *circle(200, 150, 20)) == 1.0  # the map as compare makes it
    back = in_first_light(np.clip(frame * gain + offset, 0, 255).astype(np.uint8), exposure)
    assert np.abs(back.astype(float) - frame).mean() < 3.0  # the frame as the first light showed it


def test_no_exposure_is_taken_from_a_moving_camera_or_another_size(scene):
    rng, first, still = scene
    for shift in (9, 40):
        smap, exposure = still.measure(np.roll(later(rng, first, 1.2, 0.0), shift, axis=1))
        assert exposure is None
    assert still.measure(np.zeros((100, 100, 3), np.uint8)) == (None, None)
    image = later(rng, first)
    assert in_first_light(image, None) is image
    assert in_first_light(image, (np.ones(3), np.zeros(3))) is image
    grey = image[:, :, 1]
    np.testing.assert_allclose(in_first_light(grey, (np.array([2.0]), np.array([0.0]))), np.round(grey / 2.0), atol=1)


def test_grey_frames_are_told_and_never_brought_back():
    # one channel agreeing is weak evidence of a still camera: grey frames keep their exposure
    rng = np.random.default_rng(5)
    colour = textured(rng, (120, 160)).astype(np.uint8)
    still = StillScene(colour, own_place(colour.shape), size=36.0)
    assert not still.grey
    assert still.measure(later(rng, colour, 1.2, 0.0, noise=1.0))[1] is not None
    grey = cv2.cvtColor(cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)  # read as BGR
    for first in (grey, grey[:, :, 0]):
        still = StillScene(first, own_place(first.shape), size=36.0)
        assert still.grey
        smap, exposure = still.measure(later(rng, first, 1.2, 0.0, noise=1.0))
        assert exposure is None
        assert still.stillness(smap, *circle(130, 60, 20)) == 1.0  # the still scene works as before
