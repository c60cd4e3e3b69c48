"""Compiled kernel of the default observation model (numba).

:func:`trackcli.observe.discriminant.per_normal` reads, for every normal of every sample
curve, 2 h + 4 bilinear samples of the feature image and a few pixels of the colour map, finds the
local maxima of the intensity difference along the profile and sums a Gaussian over them.
Written with numpy and OpenCV this is ``cv2.remap`` (which needs two coordinate maps the size
of its output) and a dozen short array passes per chunk of normals; the maps and profiles
stream through memory, and the interpreter holds the GIL between the passes, so that a
second thread gains little.  :func:`discriminant_normals` does the whole computation of one
normal in one pass, with the profile in a small buffer, and releases the GIL: the thread
pool of :func:`trackcli.trackers.condensation.weigh` then scores its blocks of samples on
separate cores.

The feature image is sampled as ``cv2.remap`` with ``INTER_LINEAR`` does (OpenCV 5
interpolates at the exact float position), border pixels replicated; features are located to
a fraction of a pixel, so the profile needs the interpolation.  The colour map is read at the
nearest pixel, 0 outside the frame: it is a log-ratio of histogram bins, constant over
regions of one colour, and is averaged over several places per normal; interpolating it cost
up to a tenth of the kernel's time.  Along normals whose whole segment lies inside the image
(nearly all) the profile is read without border tests, the coordinates first and the pixels
in a second loop.  The local maxima are found a word of 32 candidates at a time, as the bits
of an integer (a loop of fixed length the compiler vectorises), and only the set bits are
visited.  For the tracker's weights, :func:`discriminant_curves` sums each curve's terms in
the kernel and takes one logarithm of the product of its normals' factors instead of one per
normal.
The numpy version, :func:`trackcli.observe.discriminant.per_normal_reference`, is kept as the
reference the kernel is tested against.  The compiled code is cached next to this file
(``cache=True``): only the first run after installation compiles it (a few seconds).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uintp
from numba.cpython.unsafe.numbers import trailing_zeros

# Floating-point licence of the compiled loops: fused multiply-adds (an eighth of the kernel's
# time).  Sums are not reordered, so the results are the same on every processor with FMA
# instructions (most x86-64 processors since 2013, ARM64) and with any number of threads.
_FAST = {"contract"}


@njit(cache=True, nogil=True, inline="always", fastmath=_FAST)
def _bilinear_replicate(flat, w, h, x, y):  # pragma: no cover - compiled
    """The image (flattened, ``w`` x ``h``) at ``(x, y)``, border pixels replicated."""
    # beyond a pixel outside the image the value no longer changes; clamping first keeps the
    # integer conversion defined for any finite coordinate
    x = min(max(x, np.float32(-2.0)), np.float32(w + 1))
    y = min(max(y, np.float32(-2.0)), np.float32(h + 1))
    ix = np.int32(x + np.float32(3.0)) - np.int32(3)  # floor: the argument is positive
    iy = np.int32(y + np.float32(3.0)) - np.int32(3)
    ax = x - np.float32(ix)
    ay = y - np.float32(iy)
    x0 = min(max(ix, 0), w - 1)
    x1 = min(max(ix + 1, 0), w - 1)
    y0 = min(max(iy, 0), h - 1) * w
    y1 = min(max(iy + 1, 0), h - 1) * w
    one = np.float32(1.0)
    top = flat[y0 + x0] * (one - ax) + flat[y0 + x1] * ax
    bottom = flat[y1 + x0] * (one - ax) + flat[y1 + x1] * ax
    return top * (one - ay) + bottom * ay


@njit(cache=True, nogil=True, inline="always", fastmath=_FAST)
def _nearest_zero(flat, w, h, x, y):  # pragma: no cover - compiled
    """The pixel of the image (flattened, ``w`` x ``h``) nearest ``(x, y)``, 0 outside it."""
    x = min(max(x, np.float32(-2.0)), np.float32(w + 1))
    y = min(max(y, np.float32(-2.0)), np.float32(h + 1))
    ix = np.int32(x + np.float32(3.5)) - np.int32(3)  # floor(x + 1/2): the argument is positive
    iy = np.int32(y + np.float32(3.5)) - np.int32(3)
    if 0 <= ix < w and 0 <= iy < h:
        return flat[iy * w + ix]
    return np.float32(0.0)


@njit(cache=True, nogil=True, inline="always", fastmath=_FAST)
def _profile_inside(flat, w_img, px, py, nx, ny, u0, idx, ax, ay, prof):  # pragma: no cover - compiled
    """``prof[j]``, the image (flattened, ``w_img`` wide) at ``(px, py) + (j - u0) (nx, ny)``,
    bilinear, for a segment whose samples and their right and lower neighbours all lie inside
    the image: no border tests, the coordinates first (into ``idx``, ``ax``, ``ay``) and the
    pixels in a second loop, with unsigned indices."""
    n_prof = prof.shape[0]
    for j in range(n_prof):
        u = np.float32(j) - u0
        x = nx * u + px
        y = ny * u + py
        ix = np.int32(x)
        iy = np.int32(y)
        ax[j] = x - np.float32(ix)
        ay[j] = y - np.float32(iy)
        idx[j] = iy * np.int32(w_img) + ix
    wu = uintp(w_img)
    one = np.float32(1.0)
    for j in range(n_prof):
        r0 = uintp(idx[j])
        a = ax[j]
        b = ay[j]
        top = flat[r0] * (one - a) + flat[r0 + uintp(1)] * a
        bottom = flat[r0 + wu] * (one - a) + flat[r0 + wu + uintp(1)] * a
        prof[j] = top * (one - b) + bottom * b


_WORD = 32  # candidate maxima tested per pass (one bit each of an integer)

#: a curve's normals beyond the frame's edge count as the mean of those in view only while at
#: least this share of them is in view (the confidence's
#: :data:`trackcli.observe.discriminant.VISIBLE_NONE` is this share); with fewer, as missed boundaries
IN_VIEW_LEAST = 0.3


@njit(cache=True, nogil=True, fastmath=_FAST)
def _discriminant(fimg, cmap, pts, nrm, polarity, half, limit, threshold, scale, inv_in, inv_out, base,
                  log_ratio_in, miss, colour_u, colour_w, colour_weight, log_d, colour, out):  # pragma: no cover
    """The kernels below: per normal into ``log_d`` and ``colour`` (when they have K entries),
    summed per curve into ``out`` (when it has K / M).

    One compiled function with two Python entry points, not three compiled ones: compiled
    functions that call each other can get mismatched cache entries when two processes
    compile them at once (Numba issues 4807 and 10128), and a ``batch`` worker then crashed
    on a fresh installation."""
    h_img, w_img = fimg.shape
    flat = fimg.reshape(-1)
    cflat = cmap.reshape(-1)
    m = polarity.shape[0]
    per_normal = log_d.shape[0] > 0
    n_prof = 2 * half + 4
    n_diff = n_prof - 1
    n_cand = 2 * half + 1
    n_colour = colour_u.shape[0]
    u0 = np.float32(half + 1.5)
    c_lo = colour_u[0] if n_colour else np.float32(0.0)
    c_hi = colour_u[n_colour - 1] if n_colour else np.float32(0.0)
    idx = np.empty(n_prof, np.uint32)
    ax = np.empty(n_prof, np.float32)
    ay = np.empty(n_prof, np.float32)
    prof = np.empty(n_prof, np.float32)
    # differences, padded to whole words of candidates
    d = np.zeros(-(-n_cand // _WORD) * _WORD + 2, np.float32)
    s = np.zeros(d.shape[0], np.float32)
    two = np.float32(2.0)
    zero = np.float32(0.0)
    x_max = np.float32(w_img - 1)
    y_max = np.float32(h_img - 1)
    log_miss = math.log(miss)
    for c in range(pts.shape[0] // m):
        linear = 0.0  # the curve's sum of h (lambda - lambda_in) + n_in log(lambda_in / lambda) ...
        product = 1.0  # ... and the product of q + sum_n g(nu_n) / (sqrt(2 pi) sigma lambda) ...
        col = 0.0  # ... and of c_i, over its normals in view
        n_out = 0  # normals whose base point lies beyond the frame's edge ...
        missed = 0.0  # ... and their terms as missed boundaries (used when few are in view)
        for i in range(m):
            k = c * m + i
            px = pts[k, 0]
            py = pts[k, 1]
            nx = nrm[k, 0]
            ny = nrm[k, 1]
            if not per_normal and not (px >= zero and px <= x_max and py >= zero and py <= y_max):
                n_out += 1
                missed += base[i] + log_miss
                continue
            # the profile at u = -u0, ..., u0 (step 1); when the segment's ends, and so all its
            # samples and their right and lower neighbours, are inside the image, without border
            # tests: coordinates first, then the pixels (float products and sums are monotone)
            xa = px - nx * u0
            xb = px + nx * u0
            ya = py - ny * u0
            yb = py + ny * u0
            if min(xa, xb) >= zero and max(xa, xb) < x_max and min(ya, yb) >= zero and max(ya, yb) < y_max:
                _profile_inside(flat, w_img, px, py, nx, ny, u0, idx, ax, ay, prof)
            else:
                for j in range(n_prof):
                    u = np.float32(j) - u0
                    prof[j] = _bilinear_replicate(flat, w_img, h_img, nx * u + px, ny * u + py)
            for j in range(n_diff):  # D at u = -(half + 1) .. half + 1
                d[j] = prof[j + 1] - prof[j]
            for j in range(n_diff):
                s[j] = abs(d[j])
            # local maxima of |D| above the threshold, of the normal's polarity (sgn = 0: either):
            # a word of candidates tested in a loop of fixed length that the compiler vectorises,
            # into the bits of an integer, whose set bits (maxima are rare) are then scored; a
            # longer profile is shifted down a word at a time
            sgn = np.float32(polarity[i])
            anyp = sgn == zero
            total = 0.0
            n_in = 0
            c0 = 0
            while c0 < n_cand:
                left = n_cand - c0
                bits = np.uint64(0)
                for j in range(_WORD):
                    a1 = s[j + 1]
                    hit = ((a1 >= threshold) & (a1 > s[j]) & (a1 >= s[j + 2]) & (anyp | (sgn * d[j + 1] > zero))
                           & (j < left))
                    bits |= np.uint64(hit) << np.uint64(j)
                while bits:
                    j = trailing_zeros(bits)
                    bits &= bits - np.uint64(1)
                    a0 = s[j]
                    a1 = s[j + 1]
                    a2 = s[j + 2]
                    # parabola through the three values; a1 > a0 and a1 >= a2: curvature < 0
                    off = np.float32(0.5) * (a0 - a2) / (a0 - two * a1 + a2)
                    nu = np.float32(c0 + j - half) + off
                    x = px + nu * nx
                    y = py + nu * ny
                    # only features within the search segment and inside the image count
                    if abs(nu) <= limit and x >= zero and x <= x_max and y >= zero and y <= y_max:
                        g = math.exp(nu * nu * scale)
                        if nu < zero:
                            total += g * inv_in[i]
                            n_in += 1
                        else:
                            total += g * inv_out[i]
                c0 += _WORD
                if c0 < n_cand:
                    for j in range(n_cand - c0 + 2):
                        d[j] = d[j + _WORD]
                        s[j] = s[j + _WORD]
            acc = zero
            xa = px + nx * c_lo
            xb = px + nx * c_hi
            ya = py + ny * c_lo
            yb = py + ny * c_hi
            if min(xa, xb) >= zero and max(xa, xb) < x_max and min(ya, yb) >= zero and max(ya, yb) < y_max:
                for j in range(n_colour):
                    u = colour_u[j]
                    x = nx * u + px
                    y = ny * u + py
                    ix = np.int32(x + np.float32(0.5))
                    iy = np.int32(y + np.float32(0.5))
                    acc += cflat[uintp(iy * np.int32(w_img) + ix)] * colour_w[j]
            else:
                for j in range(n_colour):
                    u = colour_u[j]
                    acc += _nearest_zero(cflat, w_img, h_img, nx * u + px, ny * u + py) * colour_w[j]
            if per_normal:
                log_d[k] = base[i] + n_in * log_ratio_in[i] + math.log(miss + total)
                colour[k] = acc
            else:
                linear += base[i] + n_in * log_ratio_in[i]
                product *= miss + total
                if product > 1e150:  # each factor is at least q > 0: only overflow can come
                    linear += math.log(product)
                    product = 1.0
                col += acc
        if not per_normal:
            curve = linear + math.log(product) + colour_weight * col
            if 0 < n_out and m - n_out >= IN_VIEW_LEAST * m:
                # beyond the frame's edge there are no data: those normals count as the mean of
                # the normals in view when that is negative, and as nothing otherwise (a curve
                # gains nothing by leaving the frame, and loses nothing for what it cannot see)
                curve += n_out * min(curve / (m - n_out), 0.0)
            elif n_out > 0:
                # mostly beyond the edge: as missed boundaries (a few normals in view on clutter
                # would otherwise stand for the whole curve)
                curve += missed
            out[c] = curve


def discriminant_normals(fimg, cmap, pts, nrm, polarity, half, limit, threshold, scale, inv_in, inv_out,
                         base, log_ratio_in, miss, colour_u, colour_w, log_d, colour) -> None:
    """``log D_i`` and the colour term ``c_i`` of K normals, written into ``log_d`` and ``colour`` (K,).

    Parameters (arrays C-contiguous)
    ----------
    fimg, cmap : float32 (H, W)
        Feature image and colour log-ratio map.
    pts, nrm : float32 (K, 2)
        Base points and unit outward normals, finite; whole curves of M normals each.
    polarity : int8 (M,)
        Accepted sign of the intensity difference per normal of the curve (0 = either).
    half : int
        ``ceil(limit)``; the profile is read at ``u = -(half + 1.5), ..., half + 1.5``.
    limit, threshold, scale : float32
        Search half-width h (features with ``|nu| <= h``), contrast threshold, ``-1 / (2 sigma^2)``.
    inv_in, inv_out : float32 (M,)
        ``(1 - q) / (sqrt(2 pi) sigma lambda)`` inside and outside, per normal of the curve.
    base, log_ratio_in : float64 (M,)
        ``h (lambda - lambda_in)`` and ``log(lambda_in / lambda)`` per normal of the curve.
    miss : float64
        The miss probability q, > 0.
    colour_u, colour_w : float32 (C,)
        Offsets of the colour samples along the normal (ascending) and their weights:
        ``c_i`` is the weighted sum of the colour map's pixels nearest them (0 outside the frame).
    """
    _discriminant(fimg, cmap, pts, nrm, polarity, half, limit, threshold, scale, inv_in, inv_out, base,
                  log_ratio_in, miss, colour_u, colour_w, 0.0, log_d, colour, np.empty(0))


def discriminant_curves(fimg, cmap, pts, nrm, polarity, half, limit, threshold, scale, inv_in, inv_out,
                        base, log_ratio_in, miss, colour_u, colour_w, colour_weight, out) -> None:
    """``Σ_i log D_i + w_c c_i`` of each curve of M normals, written into ``out`` (K / M,).

    The arguments are those of :func:`discriminant_normals`, with the colour term's weight
    ``colour_weight``.  A curve's logarithms are taken of the product of its normals'
    ``q + Σ_n ...`` (rescaled before it overflows): one ``log`` per curve, not per normal.
    Normals whose base point lies beyond the image are not read: each counts as the mean
    ``log D_i + w_c c_i`` of the curve's normals in view when that is negative, and as 0
    otherwise, while at least :data:`IN_VIEW_LEAST` of the normals are in view; with fewer,
    each counts as a missed boundary, ``h (λ - λ_in) + log q``.  (An object growing past the
    frame's edge was otherwise followed by a smaller outline inside the frame, whose normals
    find clutter where the larger one's have nothing to read; and a lost outline, with a few
    normals in view on clutter, would leave the frame.)
    """
    _discriminant(fimg, cmap, pts, nrm, polarity, half, limit, threshold, scale, inv_in, inv_out, base,
                  log_ratio_in, miss, colour_u, colour_w, colour_weight, np.empty(0), np.empty(0, np.float32), out)


@njit(cache=True, nogil=True)
def count_line_features(img, y0, y1, x0, x1, stride, threshold):  # pragma: no cover - compiled
    """Features on every ``stride``-th row and column of ``img[y0:y1, x0:x1]``: ``(count, candidates)``.

    A feature is a local maximum of ``|D|`` (``D`` the difference of neighbouring pixels
    along the line) at least ``threshold``; ``candidates`` is the number of places tested
    (two fewer than the differences of each line).  The columns are scanned together, a row
    at a time, so that the image is read in memory order.
    """
    count = 0
    length = 0
    if x1 - x0 >= 4:  # rows: at least 3 differences, one candidate
        for y in range(y0, y1, stride):
            prev = abs(img[y, x0 + 1] - img[y, x0])
            cur = abs(img[y, x0 + 2] - img[y, x0 + 1])
            for x in range(x0 + 2, x1 - 1):
                nxt = abs(img[y, x + 1] - img[y, x])
                if cur > prev and cur >= nxt and cur >= threshold:
                    count += 1
                prev = cur
                cur = nxt
            length += x1 - x0 - 3
    if y1 - y0 >= 4:  # columns, each with its two last differences
        n_col = (x1 - x0 + stride - 1) // stride
        prev = np.empty(n_col, img.dtype)
        cur = np.empty(n_col, img.dtype)
        for c in range(n_col):
            x = x0 + c * stride
            prev[c] = abs(img[y0 + 1, x] - img[y0, x])
            cur[c] = abs(img[y0 + 2, x] - img[y0 + 1, x])
        for y in range(y0 + 2, y1 - 1):
            for c in range(n_col):
                x = x0 + c * stride
                nxt = abs(img[y + 1, x] - img[y, x])
                if cur[c] > prev[c] and cur[c] >= nxt and cur[c] >= threshold:
                    count += 1
                prev[c] = cur[c]
                cur[c] = nxt
        length += n_col * (y1 - y0 - 3)
    return count, length


@njit(cache=True, nogil=True)
def colour_lookup(hsv, shares, lut, out):  # pragma: no cover - compiled
    """``out[y, x] = lut[shares[h, 0] + shares[s, 1] + shares[v, 2]]`` for the HSV pixel ``(h, s, v)``.

    ``shares`` (256, 3) uint8 holds each channel's part of the flat histogram bin; ``lut`` (256,)
    float32 the colour log-ratio of every bin.  One pass over the frame instead of three
    OpenCV calls (two table look-ups and a channel sum) with two intermediate images.
    """
    h_img, w_img = out.shape
    for y in range(h_img):
        for x in range(w_img):
            b = int(shares[hsv[y, x, 0], 0]) + int(shares[hsv[y, x, 1], 1]) + int(shares[hsv[y, x, 2], 2])
            out[y, x] = lut[b]


@njit(cache=True, nogil=True)
def bgr_bin_lookup(image, lut, out):  # pragma: no cover - compiled
    """``out[y, x] = lut[(b >> 4) << 8 | (g >> 4) << 4 | r >> 4]`` for the BGR pixel ``(b, g, r)``:
    the region's colour log-ratio (:mod:`trackcli.observe.region`, 16 bins a channel) in one pass
    over the image instead of five array passes and a gather."""
    h_img, w_img = out.shape
    for y in range(h_img):
        for x in range(w_img):
            out[y, x] = lut[((image[y, x, 0] >> 4) << 8) | ((image[y, x, 1] >> 4) << 4) | (image[y, x, 2] >> 4)]


@njit(cache=True, nogil=True)
def bgr_bin_lookup_masked(image, mask, lut, out):  # pragma: no cover - compiled
    """The values of :func:`bgr_bin_lookup` at the pixels where ``mask`` is set, in row order
    (as ``L[mask]`` of the whole image's); returns how many (the first entries of ``out``)."""
    h_img, w_img = mask.shape
    n = 0
    for y in range(h_img):
        for x in range(w_img):
            if mask[y, x]:
                out[n] = lut[((image[y, x, 0] >> 4) << 8) | ((image[y, x, 1] >> 4) << 4) | (image[y, x, 2] >> 4)]
                n += 1
    return n
