"""Compiled kernel of the default observation model (numba).

:func:`trackcli.observe.discriminant.per_normal` reads, for every normal of every sample
curve, about 2 h + 4 bilinear samples of the feature image and a few of the colour map
(``cv2.remap``, vectorised, the GIL released), then finds the local maxima of the intensity
difference along each profile and sums a Gaussian over them.  Written with numpy that second
part is a dozen short array passes per chunk of normals, each holding the GIL in between, so
that the interpreter and memory traffic, not the arithmetic, set the pace and a second thread
gains little.  :func:`discriminant_profiles` does it in one pass per normal, in registers,
with the GIL released; the thread pool of :func:`trackcli.trackers.condensation.weigh` then
scores its blocks of samples on separate cores.

The kernel computes what the numpy version computes, in the same float32 operations (sums
in float64); :func:`trackcli.observe.discriminant.per_normal_reference` is kept as the
reference it is tested against.  The compiled code is cached next to this file
(``cache=True``): only the first run after installation compiles it (a few seconds).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def discriminant_profiles(prof, cprof, pts, nrm, first, polarity, half, limit, threshold, scale, inv_in, inv_out,
                          base, log_ratio_in, miss, colour_w, x_max, y_max, log_d, colour):  # pragma: no cover
    """``log D_i`` and the colour term ``c_i`` of K normals from their profiles, into ``log_d``, ``colour`` (K,).

    Parameters
    ----------
    prof : float32 (K, 2 half + 4)
        The feature image along each normal at ``u = -(half + 1.5), ..., half + 1.5``.
    cprof : float32 (K, C)
        The colour log-ratio map at the colour offsets; ``c_i`` is its product with ``colour_w``.
    pts, nrm : float32 (K, 2)
        Base points and unit outward normals (for the test that a feature lies in the image).
    first : int
        Normal ``k`` is normal ``(first + k) % M`` of its curve.
    polarity : int8 (M,)
        Accepted sign of the intensity difference per normal of the curve (0 = either).
    half : int
        ``ceil(limit)``.
    limit, threshold, scale : float32
        Search half-width h (features with ``|nu| <= h``), contrast threshold, ``-1 / (2 sigma^2)``.
    inv_in, inv_out : float32 (M,)
        ``(1 - q) / (sqrt(2 pi) sigma lambda)`` inside and outside, per normal of the curve.
    base, log_ratio_in : float64 (M,)
        ``h (lambda - lambda_in)`` and ``log(lambda_in / lambda)`` per normal of the curve.
    miss : float64
        The miss probability q.
    x_max, y_max : float32
        The image's last column and row.
    """
    k_total = prof.shape[0]
    m = polarity.shape[0]
    n_diff = prof.shape[1] - 1
    n_colour = cprof.shape[1]
    n_cand = 2 * half + 1
    d = np.empty(n_diff, np.float32)
    s = np.empty(n_diff, np.float32)
    peaks = np.empty(n_cand, np.int64)
    two = np.float32(2.0)
    zero = np.float32(0.0)
    i = first % m
    for k in range(k_total):
        row = prof[k]
        for j in range(n_diff):  # D at u = -(half + 1) .. half + 1
            d[j] = row[j + 1] - row[j]
        for j in range(n_diff):
            s[j] = abs(d[j])
        # local maxima of |D| above the threshold, of the normal's polarity (sgn = 0: either);
        # collected without branches (a maximum is rare and unpredictable), then scored
        sgn = np.float32(polarity[i])
        c = 0
        for j in range(n_cand):
            a1 = s[j + 1]
            peaks[c] = j
            c += (a1 >= threshold) & (a1 > s[j]) & (a1 >= s[j + 2]) & ((sgn == zero) | (sgn * d[j + 1] > zero))
        px = pts[k, 0]
        py = pts[k, 1]
        nx = nrm[k, 0]
        ny = nrm[k, 1]
        total = 0.0
        n_in = 0
        for t in range(c):
            j = peaks[t]
            a0 = s[j]
            a1 = s[j + 1]
            a2 = s[j + 2]
            # parabola through the three values; a1 > a0 and a1 >= a2, so the curvature is < 0
            off = np.float32(0.5) * (a0 - a2) / (a0 - two * a1 + a2)
            nu = np.float32(j - half) + off
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
        log_d[k] = base[i] + n_in * log_ratio_in[i] + math.log(miss + total)
        acc = zero
        crow = cprof[k]
        for j in range(n_colour):
            acc += crow[j] * colour_w[j]
        colour[k] = acc
        i += 1
        if i == m:
            i = 0
