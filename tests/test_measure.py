"""Tests of features along normals, the Kalman measurement and the clutter likelihood."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from trackcli.observe import likelihoods, measure
from trackcli.errors import ConfigError, DataError

BRIGHT, DARK = 200.0, 40.0


# ---------------------------------------------------------------------------------------------
# Synthetic images with known edges


def coverage_image(shape: tuple[int, int], inside, samples: int = 8) -> np.ndarray:
    """Fraction of each pixel covered by a region, by supersampling: (H, W) in [0, 1].

    ``inside(x, y)`` takes arrays of image coordinates (pixel centres at integers).
    """
    h, w = shape
    sub = (np.arange(samples) + 0.5) / samples - 0.5
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    total = np.zeros(shape)
    for dy in sub:
        for dx in sub:
            total += inside(xs + dx, ys + dy)
    return total / samples**2


def region_frame(shape, inside) -> np.ndarray:
    """A bright region on a dark background, as a BGR uint8-range float frame."""
    cover = coverage_image(shape, inside)
    grey = DARK + (BRIGHT - DARK) * cover
    return np.repeat(grey[:, :, None], 3, axis=2)


def half_plane(theta: float, centre=(100.0, 100.0)):
    """Bright where ``n . (p - c) < 0`` with ``n = (cos theta, sin theta)``; returns (inside, n)."""
    n = np.array([math.cos(theta), math.sin(theta)])

    def inside(x, y):
        return (n[0] * (x - centre[0]) + n[1] * (y - centre[1])) < 0

    return inside, n


def ellipse(centre=(160.0, 120.0), radii=(70.0, 45.0)):
    """Inside test, and points with outward unit normals of the ellipse boundary, M = 30."""

    def inside(x, y):
        return ((x - centre[0]) / radii[0]) ** 2 + ((y - centre[1]) / radii[1]) ** 2 < 1

    t = 2 * np.pi * (np.arange(30) + 0.25) / 30
    pts = np.stack([centre[0] + radii[0] * np.cos(t), centre[1] + radii[1] * np.sin(t)], axis=-1)
    nrm = np.stack([radii[1] * np.cos(t), radii[0] * np.sin(t)], axis=-1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return inside, pts, nrm


@pytest.fixture(scope="module")
def ellipse_scene():
    inside, pts, nrm = ellipse()
    fimg = measure.feature_image(region_frame((240, 320), inside))
    return fimg, pts, nrm


# ---------------------------------------------------------------------------------------------
# Feature image


def test_feature_image_grey_and_channels():
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (40, 50, 3)).astype(np.uint8)
    grey = measure.feature_image(frame, sigma=0, edge_sigma=0)
    expected = cv2.cvtColor(frame.astype(np.float32), cv2.COLOR_BGR2GRAY)
    np.testing.assert_allclose(grey, expected, atol=1e-4)
    assert grey.dtype == np.float32 and grey.shape == (40, 50)
    for i, ch in enumerate("bgr"):
        np.testing.assert_array_equal(measure.feature_image(frame, channel=ch, sigma=0, edge_sigma=0), frame[:, :, i])
    # Both smoothings are applied as one Gaussian of width hypot(sigma, edge_sigma).
    smooth = measure.feature_image(frame, sigma=1.2, edge_sigma=1.6)
    ref = cv2.GaussianBlur(expected, (0, 0), 2.0, borderType=cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(smooth, ref, atol=1e-3)


def test_feature_image_skin_map():
    frame = np.zeros((10, 30, 3), np.uint8)
    frame[:, :10] = (120, 150, 210)  # BGR of a pinkish skin tone: (r, g) = (0.44, 0.31)
    frame[:, 10:20] = (200, 80, 40)  # blue
    frame[:, 20:] = (6, 8, 12)  # skin hue but nearly black
    skin = measure.feature_image(frame, channel="skin", sigma=0, edge_sigma=0)
    assert skin[:, :10].min() > 240
    assert skin[:, 10:20].max() < 1
    assert skin[:, 20:].max() < 1
    assert skin.min() >= 0 and skin.max() <= 255


def test_feature_image_rejects_bad_input():
    frame = np.zeros((8, 8, 3), np.uint8)
    with pytest.raises(ConfigError, match="grey, b, g, r, skin"):
        measure.feature_image(frame, channel="hue")
    with pytest.raises(ConfigError, match="sigma"):
        measure.feature_image(frame, sigma=-1)
    with pytest.raises(DataError, match="colour"):
        measure.feature_image(np.zeros((8, 8)), channel="skin")
    with pytest.raises(DataError, match="shape"):
        measure.feature_image(np.zeros((8, 8, 4)))


# ---------------------------------------------------------------------------------------------
# Sampling


def bilinear_replicate(img: np.ndarray, x: float, y: float) -> float:
    """Plain bilinear interpolation with the border replicated (reference)."""
    h, w = img.shape
    x = min(max(x, 0.0), w - 1.0)
    y = min(max(y, 0.0), h - 1.0)
    x0, y0 = int(math.floor(x)), int(math.floor(y))
    x1, y1 = min(x0 + 1, w - 1), min(y0 + 1, h - 1)
    fx, fy = x - x0, y - y0
    top = (1 - fx) * img[y0, x0] + fx * img[y0, x1]
    bottom = (1 - fx) * img[y1, x0] + fx * img[y1, x1]
    return float((1 - fy) * top + fy * bottom)


def test_sampling_is_bilinear_with_replicated_border():
    rng = np.random.default_rng(1)
    img = (rng.random((30, 40)) * 255).astype(np.float32)
    pts = rng.uniform([-5, -5], [45, 35], size=(6, 5, 2))
    ang = rng.uniform(0, 2 * np.pi, size=(6, 5))
    nrm = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    u = np.linspace(-7.5, 7.5, 11)
    got = measure.sample_along_normals(img, pts, nrm, u)
    assert got.shape == (6, 5, 11)
    for idx in np.ndindex(6, 5):
        p, n = pts[idx], nrm[idx]
        ref = [bilinear_replicate(img, p[0] + t * n[0], p[1] + t * n[1]) for t in u]
        np.testing.assert_allclose(got[idx], ref, atol=2e-3)


def test_sampling_handles_more_rows_than_the_remap_limit():
    rng = np.random.default_rng(2)
    img = (rng.random((50, 60)) * 255).astype(np.float32)
    k = measure.REMAP_MAX_SIDE + 1234
    pts = rng.uniform(0, 50, size=(k, 2))
    nrm = np.tile([0.6, 0.8], (k, 1))
    u = np.arange(-3.0, 4.0)
    whole = measure.sample_along_normals(img, pts, nrm, u)
    pieces = np.concatenate(
        [measure.sample_along_normals(img, pts[i : i + 1000], nrm[i : i + 1000], u) for i in range(0, k, 1000)]
    )
    np.testing.assert_array_equal(whole, pieces)


# ---------------------------------------------------------------------------------------------
# Features: position, polarity, threshold, gates


@pytest.mark.parametrize("theta_deg", [0.0, 17.0, 45.0, 100.0, 233.0])
def test_feature_at_subpixel_offset_of_blurred_step(theta_deg):
    inside, n = half_plane(math.radians(theta_deg))
    fimg = measure.feature_image(region_frame((200, 200), inside))
    tangent = np.array([-n[1], n[0]])
    deltas = np.array([-4.3, -0.5, 0.0, 0.25, 3.7, 6.6])
    along = np.linspace(-30, 30, 7)
    # Points displaced by delta along the normal see the edge at nu = -delta.
    pts = np.array([[100, 100] + t * tangent + d * n for d in deltas for t in along])
    nrm = np.tile(n, (len(pts), 1))
    feats = measure.find_features(fimg, pts, nrm, 10.0, threshold=5.0)
    assert np.array_equal(feats.counts(), np.ones(len(pts), dtype=int))
    error = feats.offset - np.repeat(-deltas, len(along))
    # Exact for axis-aligned normals; bilinear interpolation costs up to ~0.1 px on diagonals.
    assert np.abs(error).max() < 0.15
    assert np.abs(error).mean() < 0.06
    # The reported position lies on the true edge line.
    assert np.abs((feats.xy - [100, 100]) @ n).max() < 0.15


def test_strength_is_contrast_per_pixel_of_the_blurred_step():
    inside, n = half_plane(0.3)
    fimg = measure.feature_image(region_frame((200, 200), inside), sigma=1.0, edge_sigma=1.5)
    feats = measure.find_features(fimg, [[100.0, 100.0]], [n], 8.0, threshold=1.0)
    # A unit-spaced difference across a step of height C blurred to width s: C erf(1 / (2 sqrt 2 s)),
    # with s^2 = 1.0^2 + 1.5^2 + 1/12 + 1/6 (blur, pixel area, bilinear interpolation).
    s = math.sqrt(1.0 + 2.25 + 1 / 12 + 1 / 6)
    expected = (BRIGHT - DARK) * math.erf(1 / (2 * math.sqrt(2) * s))
    assert feats.strength[0] == pytest.approx(expected, rel=0.03)
    strength = feats.strength[0]
    assert len(measure.find_features(fimg, [[100.0, 100.0]], [n], 8.0, threshold=strength * 1.01)) == 0
    assert len(measure.find_features(fimg, [[100.0, 100.0]], [n], 8.0, threshold=strength * 0.99)) == 1


def test_polarity_is_relative_to_the_normal_direction(ellipse_scene):
    fimg, pts, nrm = ellipse_scene
    # Outward normals cross a bright object's outline from light to dark.
    out_ld = measure.find_features(fimg, pts, nrm, 8.0, threshold=5.0, polarity="light_to_dark")
    out_dl = measure.find_features(fimg, pts, nrm, 8.0, threshold=5.0, polarity="dark_to_light")
    assert np.array_equal(out_ld.counts(), np.ones(30, dtype=int))
    assert len(out_dl) == 0
    # Turning the normals inwards swaps the polarities, and nu changes sign with the normal.
    in_dl = measure.find_features(fimg, pts, -nrm, 8.0, threshold=5.0, polarity="dark_to_light")
    assert len(measure.find_features(fimg, pts, -nrm, 8.0, threshold=5.0, polarity="light_to_dark")) == 0
    np.testing.assert_allclose(in_dl.offset, -out_ld.offset, atol=0.02)
    anyp = measure.find_features(fimg, pts, nrm, 8.0, threshold=5.0)
    np.testing.assert_allclose(anyp.offset, out_ld.offset)


def test_ellipse_outline_found_at_known_offsets(ellipse_scene):
    fimg, pts, nrm = ellipse_scene
    for delta in (-5.0, -1.5, 0.0, 2.25, 6.0):
        k = measure.kalman_features(fimg, pts + delta * nrm, nrm, 9.0, threshold=5.0)
        assert k.found.all()
        assert np.abs(k.nu + delta).max() < 0.2


def test_gate_segments_are_respected(ellipse_scene):
    fimg, pts, nrm = ellipse_scene
    shifted = pts - 5.0 * nrm  # the outline is at nu = +5 on every normal
    assert not measure.kalman_features(fimg, shifted, nrm, 4.8, threshold=5.0).found.any()
    assert measure.kalman_features(fimg, shifted, nrm, 5.2, threshold=5.0).found.all()
    gates = np.where(np.arange(30) % 3 == 0, 5.2, 4.8)
    k = measure.kalman_features(fimg, shifted, nrm, gates, threshold=5.0)
    np.testing.assert_array_equal(k.found, gates > 5)
    assert np.all(k.nu[~k.found] == 0) and np.all(k.strength[~k.found] == 0)
    # The cap on the gate applies to every normal.
    capped = measure.kalman_features(fimg, shifted, nrm, 20.0, threshold=5.0, max_half_width=4.8)
    assert not capped.found.any()
    # find_features takes per-normal segments too.
    np.testing.assert_array_equal(measure.find_features(fimg, shifted, nrm, gates, threshold=5.0).counts(), gates > 5)


def two_step_profile() -> np.ndarray:
    """Vertical edges at x = 99.5 (contrast 50) and x = 105.5 (contrast 70), rising to the right."""
    img = np.full((60, 200), 20.0, np.float32)
    img[:, 100:] = 70.0
    img[:, 106:] = 140.0
    return measure.feature_image(img, sigma=0.0, edge_sigma=1.2)


def test_kalman_choice_biased_towards_zero_innovation():
    fimg = two_step_profile()
    pts, nrm = np.array([[99.5, 30.0]]), np.array([[1.0, 0.0]])
    everything = measure.find_features(fimg, pts, nrm, 6.5, threshold=5.0)
    np.testing.assert_allclose(everything.offset, [0.0, 6.0], atol=0.05)
    strong = measure.kalman_features(fimg, pts, nrm, 6.5, threshold=5.0, bias=0.0)
    assert strong.nu[0] == pytest.approx(6.0, abs=0.05)  # the strongest contrast
    near = measure.kalman_features(fimg, pts, nrm, 6.5, threshold=5.0, bias=1.0)
    assert near.nu[0] == pytest.approx(0.0, abs=0.05)  # 70 exp(-36 / 84.5) = 45.7 < 50
    wide = measure.kalman_features(fimg, pts, nrm, 12.0, threshold=5.0, bias=1.0)
    assert wide.nu[0] == pytest.approx(6.0, abs=0.05)  # 70 exp(-36 / 288) = 61.8 > 50
    assert near.strength[0] == pytest.approx(everything.strength[0])


def test_nothing_is_found_outside_the_image():
    img = np.zeros((40, 40), np.float32)
    img[:, 20:] = 100.0  # a vertical edge that reaches the top border
    fimg = measure.feature_image(img)
    # A normal parallel to the top border, 5 px above it, would see the border row replicated.
    assert len(measure.find_features(fimg, [[20.0, -5.0]], [[1.0, 0.0]], 10.0, threshold=1.0)) == 0
    assert len(measure.find_features(fimg, [[20.0, 3.0]], [[1.0, 0.0]], 10.0, threshold=1.0)) == 1
    far = np.full((3, 4, 2), 1e12)
    ll = likelihoods.log_likelihood(fimg, far, np.tile([1.0, 0.0], (3, 4, 1)), h=10, sigma=2, alpha=0.01, threshold=1.0)
    np.testing.assert_array_equal(ll, 0.0)


def test_rejects_bad_arguments(ellipse_scene):
    fimg, pts, nrm = ellipse_scene
    with pytest.raises(ConfigError, match="any, light_to_dark, dark_to_light"):
        measure.find_features(fimg, pts, nrm, 5.0, threshold=5.0, polarity="up")
    with pytest.raises(ConfigError, match="threshold"):
        measure.find_features(fimg, pts, nrm, 5.0, threshold=-1.0)
    with pytest.raises(DataError, match="normals"):
        measure.find_features(fimg, pts, nrm[:5], 5.0, threshold=5.0)
    bad = pts.copy()
    bad[3, 0] = np.nan
    with pytest.raises(DataError, match="finite"):
        measure.kalman_features(fimg, bad, nrm, 5.0, threshold=5.0)
    with pytest.raises(ConfigError, match="half_widths"):
        measure.kalman_features(fimg, pts, nrm, -1.0, threshold=5.0)
    with pytest.raises(DataError, match="broadcast"):
        measure.kalman_features(fimg, pts, nrm, np.ones(7), threshold=5.0)
    with pytest.raises(ConfigError, match="alpha"):
        likelihoods.log_likelihood(fimg, pts[None], nrm[None], h=5, sigma=2, alpha=0, threshold=5)


# ---------------------------------------------------------------------------------------------
# Kalman aggregation


def test_aggregate_sums_found_normals_only():
    rng = np.random.default_rng(3)
    m, nx = 12, 6
    h = rng.normal(size=(m, nx))
    nu = rng.normal(size=m) * 3
    found = rng.random(m) < 0.6
    sigma = rng.uniform(1, 4, size=m)
    z, s = measure.aggregate(h, nu, found, sigma)
    z_ref, s_ref = np.zeros(nx), np.zeros((nx, nx))
    for i in range(m):
        if found[i]:
            z_ref += h[i] * nu[i] / sigma[i] ** 2
            s_ref += np.outer(h[i], h[i]) / sigma[i] ** 2
    np.testing.assert_allclose(z, z_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(s, s_ref, rtol=1e-12, atol=1e-12)
    # A scalar sigma is the same for every normal; NaN innovations of missing normals are ignored.
    nu_nan = np.where(found, nu, np.nan)
    z2, s2 = measure.aggregate(h, nu_nan, found, 2.0)
    np.testing.assert_allclose(s2, (h[found].T @ h[found]) / 4.0, atol=1e-12)
    np.testing.assert_allclose(z2, h[found].T @ nu[found] / 4.0, atol=1e-12)
    z0, s0 = measure.aggregate(h, nu, np.zeros(m, bool), 2.0)
    assert not z0.any() and not s0.any()


def test_aggregate_rejects_bad_shapes():
    with pytest.raises(DataError):
        measure.aggregate(np.ones((4, 2)), np.ones(3), np.ones(4, bool), 1.0)
    with pytest.raises(DataError, match="boolean"):
        measure.aggregate(np.ones((4, 2)), np.ones(4), np.ones(4), 1.0)
    with pytest.raises(ConfigError, match="sigma"):
        measure.aggregate(np.ones((4, 2)), np.ones(4), np.ones(4, bool), 0.0)


# ---------------------------------------------------------------------------------------------
# CONDENSATION likelihood


def reference_log_likelihood(img, pts, nrm, *, h, sigma, alpha, threshold, polarity):
    """AC eq 12.2 with plain loops: sample, difference, find maxima, interpolate, sum."""
    half = math.ceil(h)
    sign = {"any": 0, "light_to_dark": -1, "dark_to_light": 1}[polarity]
    c = 1 / (math.sqrt(2 * math.pi) * sigma * alpha)
    hgt, wid = img.shape
    out = np.zeros(pts.shape[:-2])
    for idx in np.ndindex(*pts.shape[:-2]):
        total = 0.0
        for p, n in zip(pts[idx], nrm[idx]):
            u = [j - (half + 1.5) for j in range(2 * half + 4)]
            prof = [bilinear_replicate(img, p[0] + t * n[0], p[1] + t * n[1]) for t in u]
            d = [prof[j + 1] - prof[j] for j in range(len(prof) - 1)]
            s = [abs(v) if sign == 0 else sign * v for v in d]
            acc = 0.0
            for j in range(1, len(s) - 1):
                if s[j] >= threshold and s[j] > s[j - 1] and s[j] >= s[j + 1]:
                    off = 0.5 * (s[j - 1] - s[j + 1]) / (s[j - 1] - 2 * s[j] + s[j + 1])
                    nu = (j - half - 1) + off
                    x, y = p[0] + nu * n[0], p[1] + nu * n[1]
                    if abs(nu) <= h and 0 <= x <= wid - 1 and 0 <= y <= hgt - 1:
                        acc += math.exp(-nu * nu / (2 * sigma**2))
            total += math.log(1 + c * acc)
        out[idx] = total
    return out


@pytest.mark.parametrize("polarity", ["any", "light_to_dark", "dark_to_light"])
def test_log_likelihood_equals_plain_loop_reference(polarity):
    rng = np.random.default_rng(4)
    noise = rng.normal(0, 60, (60, 80)).astype(np.float32)
    img = cv2.GaussianBlur(noise, (0, 0), 2.0) + 100
    pts = rng.uniform([-4, -4], [84, 64], size=(3, 9, 2))  # some normals leave the image
    ang = rng.uniform(0, 2 * np.pi, size=(3, 9))
    nrm = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    kw = dict(h=6.5, sigma=2.0, alpha=0.02, threshold=1.5, polarity=polarity)
    got = likelihoods.log_likelihood(img, pts, nrm, **kw)
    ref = reference_log_likelihood(img, pts, nrm, **kw)
    assert got.shape == (3,)
    assert ref.max() > 1  # the case is not trivial
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-4)


def test_log_likelihood_is_largest_at_the_true_curve():
    inside, pts, nrm = ellipse()
    frame = region_frame((240, 320), inside)
    rng = np.random.default_rng(5)
    for _ in range(40):  # clutter away from the object
        x, y = int(rng.integers(0, 300)), int(rng.choice([rng.integers(0, 50), rng.integers(190, 240)]))
        corner = (x + int(rng.integers(5, 30)), y + int(rng.integers(5, 30)))
        cv2.rectangle(frame, (x, y), corner, [float(rng.integers(0, 255))] * 3, -1)
    frame += rng.normal(0, 3, frame.shape)
    fimg = measure.feature_image(frame)
    shifts = np.array([(dx, dy) for dx in range(-8, 9, 2) for dy in range(-8, 9, 2)], dtype=float)
    hyp_pts = pts[None] + shifts[:, None, :]
    hyp_nrm = np.broadcast_to(nrm, hyp_pts.shape)
    ll = likelihoods.log_likelihood(fimg, hyp_pts, hyp_nrm, h=15, sigma=3, alpha=0.02, threshold=8)
    assert ll.shape == (len(shifts),)
    assert tuple(shifts[np.argmax(ll)]) == (0.0, 0.0)
    # Every normal sees the outline at nu = 0, so the truth scores M log(1 + c).
    c = 1 / (math.sqrt(2 * math.pi) * 3 * 0.02)
    assert ll.max() == pytest.approx(30 * math.log1p(c), rel=0.01)


def test_log_likelihood_chunks_give_the_same_answer_beyond_the_remap_limit(ellipse_scene):
    fimg, pts, nrm = ellipse_scene
    rng = np.random.default_rng(6)
    n = 1200  # N M = 36 000 > 32 767 normals
    hyp_pts = pts[None] + rng.normal(0, 6, size=(n, 1, 2))
    hyp_nrm = np.broadcast_to(nrm, hyp_pts.shape)
    kw = dict(h=15, sigma=3, alpha=0.02, threshold=8)
    whole = likelihoods.log_likelihood(fimg, hyp_pts, hyp_nrm, **kw)
    pieces = np.concatenate([likelihoods.log_likelihood(fimg, hyp_pts[i : i + 7], hyp_nrm[i : i + 7], **kw) for i in range(0, n, 7)])
    np.testing.assert_allclose(whole, pieces, rtol=1e-12)
    assert np.ptp(whole) > 10


def test_find_features_lists_positions_for_display(ellipse_scene):
    fimg, pts, nrm = ellipse_scene
    feats = measure.find_features(fimg, pts + 2 * nrm, nrm, 6.0, threshold=5.0)
    assert feats.shape == (30,) and len(feats) == 30
    np.testing.assert_array_equal(feats.normal, np.arange(30))
    np.testing.assert_allclose(feats.xy, pts, atol=0.25)
    assert (feats.strength > 5).all()
