"""CONDENSATION: conditional density propagation by sampling (AC §12.2, Fig 12.6; 000 Fig 2).

The state density ``p(X_k | Z_k)`` is carried by ``N`` weighted samples of the second-order
state ``(X_{k-1}; X_k)`` (AC eqs 9.16–9.18).  One time-step

1. *selects* ``n_out`` samples by weight — the papers' cumulative weights ``c^(n)`` and a
   binary search for the smallest ``j`` with ``c^(j) > r`` (``"multinomial"``), or the
   lower-variance ``"systematic"`` and ``"stratified"`` schemes;
2. *predicts* each with the AR(2) model and fresh noise (AC eq 9.15),
   ``X_k - X̄ = A2 (X_{k-2} - X̄) + A1 (X_{k-1} - X̄) + B0 w_k``, ``w_k ~ N(0, I)``;
3. *weights* each by the observation density, kept in the log domain (a contour likelihood
   is a product over normals and underflows in linear form).

Weights are stored as normalised log-weights.  Every function is pure: randomness comes
from the ``numpy.random.Generator`` passed in, and nothing is modified in place.  The frame
loop (decoding, the measurement model, reporting) lives elsewhere; ``step`` only needs a
callable ``loglik(X) -> log p(Z | X)`` for an ``(n, Nx)`` array of shapes.

A dynamics object is anything with numpy attributes ``A1``, ``A2`` of shape (Nx, Nx), ``B0``
of shape (Nx, Nw) and ``mean`` of shape (Nx,).

One module (over 600 lines): the sample set, the three selection schemes, prediction,
weighting, the step that composes them and the initial sets share one representation of a
weighted set (log-weights) and its checks.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from trackcli.dynamics.ar2 import dynamics_arrays, spectral_radius
from trackcli.dynamics.ar2 import predict_samples as predict  # the predict step of AC Fig 12.6
from trackcli.errors import ConfigError, DataError

__all__ = [
    "RESAMPLERS",
    "ParticleSet",
    "StepInfo",
    "best_sample",
    "effective_sample_size",
    "init_gaussian",
    "init_steady_state",
    "normalise_log_weights",
    "predict",
    "resample",
    "sample_size_schedule",
    "step",
    "weighted_histogram",
    "weighted_mean",
]


#: Largest number of samples handed to ``loglik`` at once by :func:`step`.
LOGLIK_BLOCK = 2048
#: with ``threads = 0`` (automatic), the sample count from which :func:`weigh` uses every core
#: (measured on the default observation model, whose kernel releases the GIL: at N = 500 two
#: threads took a step from 2.3 to 1.9 ms, at N = 100 they gained nothing)
PARALLEL_MIN = 300
#: the same for observation models written with numpy (``clutter``, ``truncated``): their many
#: short array passes hold the GIL in between, and two threads gained only from N = 2000 up
PARALLEL_MIN_NUMPY = 2000

# ---------------------------------------------------------------------------------------------
# Weights


def normalise_log_weights(log_w: np.ndarray) -> tuple[np.ndarray, bool]:
    """Turn log-weights into normalised weights without overflow, underflow or NaN.

    The largest log-weight is subtracted before exponentiating, so log-likelihoods of any
    magnitude (e.g. all near ``-1e6``) normalise correctly.  NaN counts as ``-inf``.

    Parameters
    ----------
    log_w : ndarray of shape (N,)
        Unnormalised log-weights.

    Returns
    -------
    weights : ndarray of shape (N,)
        Non-negative, summing to 1.
    degenerate : bool
        True when no log-weight is finite and above ``-inf`` (every sample has zero
        likelihood); the weights then fall back to uniform.  Where some log-weights are
        ``+inf``, those samples share the weight equally (``degenerate`` stays False).
    """
    lw = _as_log_weights(log_w)
    top = lw.max()
    if top == -np.inf:
        return np.full(lw.size, 1.0 / lw.size), True
    if top == np.inf:
        w = (lw == np.inf).astype(np.float64)
        return w / w.sum(), False
    w = np.exp(lw - top)
    return w / w.sum(), False


def _as_log_weights(log_w: np.ndarray) -> np.ndarray:
    lw = np.array(log_w, dtype=np.float64)
    if lw.ndim != 1 or lw.size == 0:
        raise DataError(f"log_w: expected a non-empty 1-D array, got shape {lw.shape}")
    lw[np.isnan(lw)] = -np.inf
    return lw


def _log_normalise(log_w: np.ndarray) -> tuple[np.ndarray, bool]:
    """Log of normalised weights, computed in the log domain; uniform if degenerate."""
    lw = _as_log_weights(log_w)
    top = lw.max()
    if top == -np.inf:
        return np.full(lw.size, -math.log(lw.size)), True
    if top == np.inf:
        w, _ = normalise_log_weights(lw)
        with np.errstate(divide="ignore"):
            return np.log(w), False
    shifted = lw - top
    return shifted - math.log(np.exp(shifted).sum()), False


def effective_sample_size(weights: np.ndarray) -> float:
    """Effective sample size ``(sum w)^2 / sum w^2`` of non-negative weights.

    Equals ``N`` for uniform weights and 1 when one sample carries all the weight.  The
    weights need not be normalised; for log-weights use ``ParticleSet.ess`` or normalise
    first with :func:`normalise_log_weights`.
    """
    w = _as_weights(weights)
    return float(w.sum() ** 2 / np.dot(w, w))


def _as_weights(weights: np.ndarray) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise DataError(f"weights: expected a non-empty 1-D array, got shape {w.shape}")
    if not (np.isfinite(w).all() and (w >= 0).all()):
        raise DataError("weights: expected finite, non-negative values")
    if not w.sum() > 0:
        raise DataError("weights: all weights are zero")
    return w


# ---------------------------------------------------------------------------------------------
# Resampling: each scheme maps weights (N,) to n_out parent indices, ascending.


def _cumulative(w: np.ndarray) -> np.ndarray:
    """Cumulative weights ``c^(1..N)``, normalised, with the last entry exactly 1."""
    c = np.cumsum(w)
    c /= c[-1]
    c[-1] = 1.0
    return c


def _select(c: np.ndarray, r: np.ndarray) -> np.ndarray:
    # The smallest j with c[j] > r, r in [0, 1): a zero-weight sample (c[j] == c[j-1]) is
    # never chosen, and c[-1] == 1 > r keeps every index in range.
    return np.searchsorted(c, r, side="right").astype(np.int64)


def _multinomial(w: np.ndarray, n_out: int, rng: np.random.Generator) -> np.ndarray:
    """Independent draws: ``n_out`` uniform numbers and a binary search each (AC Fig 12.6)."""
    return _select(_cumulative(w), np.sort(rng.random(n_out)))


def _systematic(w: np.ndarray, n_out: int, rng: np.random.Generator) -> np.ndarray:
    """One uniform offset and an evenly spaced comb ``(k + U) / n_out``.

    Sample ``j`` receives ``floor(n_out w_j)`` or ``ceil(n_out w_j)`` offspring.
    """
    return _select(_cumulative(w), (np.arange(n_out) + rng.random()) / n_out)


def _stratified(w: np.ndarray, n_out: int, rng: np.random.Generator) -> np.ndarray:
    """One uniform draw in each of ``n_out`` equal strata ``[k, k + 1) / n_out``."""
    return _select(_cumulative(w), (np.arange(n_out) + rng.random(n_out)) / n_out)


RESAMPLERS: dict[str, Callable[[np.ndarray, int, np.random.Generator], np.ndarray]] = {
    "multinomial": _multinomial,
    "systematic": _systematic,
    "stratified": _stratified,
}
"""Resampling schemes by name: ``f(weights (N,), n_out, rng) -> indices (n_out,)``."""


def resample(weights: np.ndarray, n_out: int, rng: np.random.Generator, scheme: str = "multinomial") -> np.ndarray:
    """Choose ``n_out`` parents with probability proportional to ``weights``.

    Parameters
    ----------
    weights : ndarray of shape (N,)
        Non-negative weights, not all zero (normalisation is done here).
    n_out : int
        Number of samples to draw (>= 1); may differ from ``N``.
    rng : numpy.random.Generator
        Source of randomness.
    scheme : {"multinomial", "systematic", "stratified"}
        Selection scheme, see :data:`RESAMPLERS`.  All are unbiased: the expected number of
        offspring of sample ``j`` is ``n_out w_j / sum(w)``.

    Returns
    -------
    ndarray of shape (n_out,), int64
        Indices of the chosen parents, in ascending order.
    """
    try:
        scheme_fn = RESAMPLERS[scheme]
    except (KeyError, TypeError):
        raise ConfigError(f"resampling scheme: unknown value {scheme!r}; valid choices are {', '.join(RESAMPLERS)}") from None
    return scheme_fn(_as_weights(weights), _check_count(n_out, "n_out"), rng)


def _check_count(n: Any, name: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ConfigError(f"{name}: expected an integer >= 1, got {n!r}")
    return int(n)


# ---------------------------------------------------------------------------------------------
# Sample sets


@dataclass(frozen=True)
class ParticleSet:
    """A weighted set of second-order states.

    Attributes
    ----------
    prev : ndarray of shape (N, Nx)
        ``X_{k-1}`` of every sample.
    cur : ndarray of shape (N, Nx)
        ``X_k`` of every sample.
    log_w : ndarray of shape (N,)
        Log-weights (normalised by :func:`step`; any offset is allowed).
    """

    prev: np.ndarray
    cur: np.ndarray
    log_w: np.ndarray

    def __post_init__(self) -> None:
        prev = np.asarray(self.prev, dtype=np.float64)
        cur = np.asarray(self.cur, dtype=np.float64)
        log_w = np.asarray(self.log_w, dtype=np.float64)
        if cur.ndim != 2 or cur.shape[0] == 0 or cur.shape[1] == 0:
            raise DataError(f"ParticleSet.cur: expected shape (N, Nx) with N, Nx >= 1, got {cur.shape}")
        if prev.shape != cur.shape:
            raise DataError(f"ParticleSet.prev: expected shape {cur.shape} like cur, got {prev.shape}")
        if log_w.shape != (cur.shape[0],):
            raise DataError(f"ParticleSet.log_w: expected shape ({cur.shape[0]},), got {log_w.shape}")
        object.__setattr__(self, "prev", prev)
        object.__setattr__(self, "cur", cur)
        object.__setattr__(self, "log_w", log_w)

    @property
    def n(self) -> int:
        """Number of samples N."""
        return self.cur.shape[0]

    @property
    def nx(self) -> int:
        """Shape-space dimension Nx."""
        return self.cur.shape[1]

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights, shape (N,) (uniform if every log-weight is ``-inf``)."""
        return normalise_log_weights(self.log_w)[0]

    @property
    def ess(self) -> float:
        """Effective sample size of the weights."""
        return effective_sample_size(self.weights)


class StepInfo(NamedTuple):
    """Diagnostics of one CONDENSATION step."""

    ess: float
    """Effective sample size of the new weights."""
    resampled: bool
    """Whether samples were selected by weight this step."""
    degenerate: bool
    """True when every new sample had zero likelihood (weights fell back to uniform)."""
    ess_before: float
    """Effective sample size of the incoming weights, on which the selection decision rests."""
    parent_shapes: np.ndarray | None = None
    """``X_{k-1}`` of each new sample's parent as selected, before ``propose`` moved any
    (for offline consumers that trace ancestry)."""
    loglik: np.ndarray | None = None
    """``log p(Z | X)`` of every new sample, as ``loglik`` returned it."""
    parents: np.ndarray | None = None
    """Index in the incoming set of each new sample's parent (``arange(N)`` without selection)."""


# ---------------------------------------------------------------------------------------------
# Dynamics


# ---------------------------------------------------------------------------------------------
# One time-step


def weigh(samples: np.ndarray, loglik: Callable[[np.ndarray], np.ndarray],
          base: np.ndarray | float = 0.0, *, threads: int = 1,
          parallel_min: int = PARALLEL_MIN, power: float = 1.0) -> tuple[np.ndarray, np.ndarray, bool]:
    """The weighting step of AC Fig 12.6: ``log π = base + log p(Z | X)``, normalised; with
    ``power`` < 1, ``log π = base + power log p(Z | X)`` (a tempered likelihood, see
    :class:`~trackcli.trackers.condensation_tracker.CondensationTracker`).

    ``loglik`` is called on blocks of at most :data:`LOGLIK_BLOCK` samples (bounded
    memory); ``base`` holds the log-weights the samples carry into the step (zeros after
    selection, plus any importance correction).  With ``threads`` > 1 the blocks are cut
    ``threads`` ways, one share scored by the calling thread and the others by a pool of
    ``threads - 1`` (``loglik`` must be a pure function of its samples; the compiled
    kernels, OpenCV and numpy release the GIL in the heavy parts); the result is the same
    array to the bit.  ``threads = 0`` means :func:`automatic_threads` for at least
    ``parallel_min`` samples and one thread below that.  Returns ``(log-likelihoods (n,), normalised log-weights (n,),
    degenerate)``; ``degenerate`` is True when every weight was zero and the weights were
    made uniform.
    """
    n = samples.shape[0]
    ll = np.empty(n)
    if threads == 0:
        threads = automatic_threads() if n >= parallel_min else 1
    if threads <= 1:
        size = LOGLIK_BLOCK
    else:  # a whole number of blocks per thread, so that the shares are equal
        per_thread = -(-n // (threads * LOGLIK_BLOCK))
        size = max(1, -(-n // (threads * per_thread)))
    starts = range(0, n, size)

    def score(b0: int) -> None:
        block = samples[b0 : b0 + size]
        part = np.asarray(loglik(block), dtype=np.float64)
        if part.shape != (block.shape[0],):
            raise DataError(f"loglik: expected an array of shape ({block.shape[0]},), got {part.shape}")
        ll[b0 : b0 + block.shape[0]] = part

    if threads > 1 and len(starts) > 1:
        # the blocks dealt out round-robin; the calling thread scores the first share itself
        # instead of waiting idle for the pool
        def share(first: int) -> None:
            for b0 in starts[first::threads]:
                score(b0)

        others = [thread_pool(threads - 1).submit(share, t) for t in range(1, min(threads, len(starts)))]
        try:
            share(0)
        finally:  # no block is still being scored when this returns or raises
            wait(others)
        for future in others:
            future.result()
    else:
        for b0 in starts:
            score(b0)
    if (ll == np.inf).any():
        raise DataError("loglik: returned +inf; a log-likelihood must be finite or -inf")
    log_w, degenerate = _log_normalise(base + (ll if power == 1.0 else power * ll))
    return ll, log_w, degenerate


_POOLS: dict[int, Any] = {}
#: The machine's cores, read once (``os.cpu_count`` reads a file each call: 40 µs a frame).
_CORES = os.cpu_count() or 1


def automatic_threads() -> int:
    """Threads for ``threads = 0``: OpenCV's thread count (the cores, or the share of them a
    ``batch`` worker was given), at most the cores."""
    import cv2

    return max(1, min(_CORES, cv2.getNumThreads()))


def thread_pool(threads: int) -> Any:
    """A process-wide pool of ``threads`` worker threads (made on first use, then reused)."""
    if threads not in _POOLS:
        _POOLS[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="trackcli-weigh")
    return _POOLS[threads]


def step(
    particles: ParticleSet,
    dynamics: Any,
    loglik: Callable[[np.ndarray], np.ndarray],
    rng: np.random.Generator,
    *,
    n_out: int | None = None,
    scheme: str = "multinomial",
    ess_threshold: float | None = None,
    propose: Callable[[np.ndarray, np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray, np.ndarray]]
    | None = None,
    threads: int = 1,
    parallel_min: int = PARALLEL_MIN,
    motion: Callable[[np.ndarray, np.ndarray, np.random.Generator, np.ndarray],
                     tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
    power: float = 1.0,
) -> tuple[ParticleSet, StepInfo]:
    """One CONDENSATION time-step: select, predict, weight (AC Fig 12.6).

    Parameters
    ----------
    particles : ParticleSet
        Sample set at time ``k-1`` (``N`` samples).
    dynamics
        AR(2) model with ``A1``, ``A2`` (Nx, Nx), ``B0`` (Nx, Nw), ``mean`` (Nx,).
    loglik : callable
        ``loglik(X)`` with ``X`` of shape (n, Nx) returns the log observation density
        ``log p(Z_k | X)`` of shape (n,); ``-inf`` marks an impossible sample.  It is called
        on consecutive blocks of at most :data:`LOGLIK_BLOCK` samples, so that the curves
        of a block and their measurement stay in the processor's cache.
    rng : numpy.random.Generator
        Source of randomness for selection and process noise.
    n_out : int, optional
        Size of the new set (default ``N``); see :func:`sample_size_schedule`.
    scheme : str
        Resampling scheme, a key of :data:`RESAMPLERS`.
    ess_threshold : float in (0, 1], optional
        When given, select by weight only if ``ESS / N < ess_threshold`` (or the set size
        changes); otherwise the samples keep their weights and are all propagated.  ``None``
        selects every step, as in the papers.
    propose : callable, optional
        A change to the predicted states before weighting: ``propose(prev, predicted, rng)``
        with ``prev`` the selected samples' ``X_{k-1}`` and ``predicted`` their new ``X_k``
        returns ``(prev, predicted, log_correction)``.  It may move some states (a jump of
        a mixture prior; a draw from another proposal, with its velocity, as in
        importance sampling, ICONDENSATION); ``log_correction`` (n,) is added to every
        log-weight, i.e. the log of prior density over proposal density that keeps the
        weighted set a fair sample of the posterior (zeros for a mixture prior sampled as it is).
    threads : int
        Threads that score the samples (:func:`weigh`); the result does not depend on it.
    parallel_min : int
        With ``threads = 0``, the sample count from which every core scores (:func:`weigh`).
    motion : callable, optional
        Replaces the AR(2) prediction: ``motion(prev, cur, rng, parents)`` with the selected
        samples' ``X_{k-2}, X_{k-1}`` and their parents' indices in ``particles`` returns
        ``(prev', X_k, log_correction)``, ``prev'`` being the ``X_{k-1}`` the new state carries
        (its velocity is ``X_k - prev'``; usually ``cur``) and ``log_correction`` (n,) added to
        the log-weights (``-inf``: a state the motion model cannot produce).  Used by mixed-state dynamics
        (:mod:`trackcli.dynamics.mixed`), whose samples carry a label beside the shape.
    power : float
        Exponent on the likelihood in the weights (:func:`weigh`); 1 as in the papers.
        ``StepInfo.loglik`` is ``log p(Z | X)`` itself.

    Returns
    -------
    ParticleSet
        The weighted set at time ``k``: ``prev`` holds the parents' ``X_{k-1}``, ``cur`` the
        predicted ``X_k``, ``log_w`` the normalised log-weights (uniform if degenerate).
    StepInfo
        Effective sample size, whether selection happened, whether the weights degenerated.
    """
    if not isinstance(particles, ParticleSet):
        raise DataError(f"particles: expected a ParticleSet, got {type(particles).__name__}")
    n_out = particles.n if n_out is None else _check_count(n_out, "n_out")
    if scheme not in RESAMPLERS:
        raise ConfigError(f"resampling scheme: unknown value {scheme!r}; valid choices are {', '.join(RESAMPLERS)}")
    if not 0 < power <= 1:
        raise ConfigError(f"power: expected an exponent in (0, 1], got {power!r}")
    if ess_threshold is not None and not (0 < ess_threshold <= 1):
        raise ConfigError(f"ess_threshold: expected a ratio in (0, 1] or None, got {ess_threshold!r}")

    log_w, _ = _log_normalise(particles.log_w)
    w = np.exp(log_w)
    ess_before = effective_sample_size(w)
    do_select = ess_threshold is None or n_out != particles.n or ess_before / particles.n < ess_threshold
    if do_select:
        parents = resample(w, n_out, rng, scheme)
        prev, cur = particles.prev[parents], particles.cur[parents]
        base = np.zeros(n_out)
    else:
        parents = np.arange(particles.n)
        prev, cur, base = particles.prev, particles.cur, log_w

    if motion is None:
        new = predict(prev, cur, dynamics, rng)
    else:
        cur, new, correction = motion(prev, cur, rng, parents)
        base = base + correction
    parents_cur = cur
    if propose is not None:
        cur, new, correction = propose(cur, new, rng)
        base = base + np.asarray(correction, dtype=np.float64)
    ll, out_log_w, degenerate = weigh(new, loglik, base, threads=threads, parallel_min=parallel_min, power=power)
    out = ParticleSet(prev=cur, cur=new, log_w=out_log_w)
    info = StepInfo(
        ess=effective_sample_size(np.exp(out_log_w)),
        resampled=bool(do_select),
        degenerate=degenerate,
        ess_before=ess_before,
        parent_shapes=parents_cur,
        loglik=ll,
        parents=parents,
    )
    return out, info


# ---------------------------------------------------------------------------------------------
# Estimates


def weighted_mean(particles: ParticleSet) -> np.ndarray:
    """Weighted mean ``E[X_k] = sum_n pi_n s_n`` of the current shapes: (Nx,)."""
    return particles.weights @ particles.cur


def best_sample(particles: ParticleSet) -> np.ndarray:
    """The current shape of the highest-weight sample: (Nx,)."""
    return particles.cur[int(np.argmax(particles.log_w))].copy()


def weighted_histogram(particles: ParticleSet, edges: np.ndarray, *, component: int = 0) -> np.ndarray:
    """Weighted histogram of one component of the current shapes (000 Fig 3, AC Fig 12.10).

    Parameters
    ----------
    particles : ParticleSet
        The sample set.
    edges : ndarray of shape (B + 1,)
        Increasing bin edges, fixed by the caller so frames can be compared.
    component : int
        Index into ``X`` (0 = horizontal translation in the usual shape-spaces).

    Returns
    -------
    ndarray of shape (B,)
        Probability mass per bin; mass outside ``[edges[0], edges[-1]]`` is dropped, so the
        sum is at most 1.
    """
    edges = np.asarray(edges, dtype=np.float64)
    if edges.ndim != 1 or edges.size < 2 or not (np.diff(edges) > 0).all():
        raise ConfigError("edges: expected at least two strictly increasing bin edges")
    if not -particles.nx <= component < particles.nx:
        raise ConfigError(f"component: expected an index in [0, {particles.nx}), got {component!r}")
    # np.histogram's binning, by one search of the edges (much faster for a few hundred samples):
    # bin b holds edges[b] <= x < edges[b + 1], the last bin also x == edges[-1]
    x = particles.cur[:, component]
    b = np.searchsorted(edges, x, side="right") - 1
    b[x == edges[-1]] = edges.size - 2
    inside = (b >= 0) & (b < edges.size - 1)
    return np.bincount(b[inside], weights=particles.weights[inside], minlength=edges.size - 1)


# ---------------------------------------------------------------------------------------------
# Initialisation


def init_gaussian(
    mean_x: np.ndarray,
    cov: np.ndarray,
    n: int,
    rng: np.random.Generator,
    *,
    velocity: np.ndarray | None = None,
) -> ParticleSet:
    """A sample set placed by hand: ``X_k ~ N(mean_x, cov)`` (000 §5.2, AC §12.4).

    Parameters
    ----------
    mean_x : ndarray of shape (Nx,)
        Mean shape.
    cov : ndarray of shape (Nx, Nx)
        Symmetric positive semi-definite covariance (zero variances are allowed).
    n : int
        Number of samples.
    rng : numpy.random.Generator
        Source of randomness.
    velocity : ndarray of shape (Nx,), optional
        Known initial velocity per frame: ``X_{k-1} = X_k - velocity``.  By default the
        samples start at rest, ``X_{k-1} = X_k``.

    Returns
    -------
    ParticleSet
        ``n`` equally weighted samples.
    """
    mean_x = np.asarray(mean_x, dtype=np.float64)
    cov = np.asarray(cov, dtype=np.float64)
    n = _check_count(n, "n")
    if mean_x.ndim != 1 or cov.shape != (mean_x.size, mean_x.size):
        raise DataError(f"init_gaussian: expected mean (Nx,) and cov (Nx, Nx), got {mean_x.shape} and {cov.shape}")
    root = _psd_root(cov, "cov")
    cur = mean_x + rng.standard_normal((n, mean_x.size)) @ root.T
    if velocity is None:
        prev = cur.copy()
    else:
        velocity = np.asarray(velocity, dtype=np.float64)
        if velocity.shape != mean_x.shape:
            raise DataError(f"velocity: expected shape {mean_x.shape}, got {velocity.shape}")
        prev = cur - velocity
    return ParticleSet(prev=prev, cur=cur, log_w=np.zeros(n))


def _psd_root(cov: np.ndarray, name: str) -> np.ndarray:
    """A matrix ``R`` with ``R R^T = cov`` for symmetric PSD ``cov``."""
    if not np.isfinite(cov).all() or not np.allclose(cov, cov.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(cov).max())):
        raise DataError(f"{name}: expected a finite symmetric matrix")
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    tol = 1e-10 * max(1.0, float(np.abs(vals).max()))
    if vals.min() < -tol:
        raise DataError(f"{name}: not positive semi-definite (smallest eigenvalue {vals.min():.3g})")
    return vecs * np.sqrt(np.clip(vals, 0.0, None))


def init_steady_state(
    dynamics: Any,
    n: int,
    rng: np.random.Generator,
    *,
    n_burn: int | None = None,
) -> ParticleSet:
    """A sample set from the open-loop steady state of the motion model (000 §5.1, AC §12.4).

    All samples start at rest at the mean ``X̄`` and the model is iterated ``n_burn`` times
    with no measurements, which draws them from the stationary density of the AR(2)
    process.

    Parameters
    ----------
    dynamics
        AR(2) model with ``A1``, ``A2`` (Nx, Nx), ``B0`` (Nx, Nw), ``mean`` (Nx,); it must be
        stable (no steady state exists for, e.g., constant-velocity models, AC §10.1).
    n : int
        Number of samples.
    rng : numpy.random.Generator
        Source of randomness.
    n_burn : int, optional
        Number of iterations.  By default enough for the slowest mode to decay to 0.1 %
        (``rho^n_burn <= 1e-3``, ``rho`` the spectral radius), at least 20 and at most
        100 000.

    Returns
    -------
    ParticleSet
        ``n`` equally weighted samples.
    """
    a1, a2, _, mean = dynamics_arrays(dynamics)
    n = _check_count(n, "n")
    rho = spectral_radius(a2, a1)
    if rho >= 1.0:
        raise DataError(
            f"dynamics: no steady state, the model is not stable (spectral radius {rho:.6g} >= 1); "
            "initialise with init_gaussian instead"
        )
    if n_burn is None:
        n_burn = 20 if rho == 0 else int(min(100_000, max(20, math.ceil(math.log(1e-3) / math.log(rho)))))
    else:
        n_burn = _check_count(n_burn, "n_burn")
    prev = np.tile(mean, (n, 1))
    cur = prev.copy()
    for _ in range(n_burn):
        prev, cur = cur, predict(prev, cur, dynamics, rng)
    return ParticleSet(prev=prev, cur=cur, log_w=np.zeros(n))


def sample_size_schedule(start: int = 1500, end: int = 500, frames: int = 4) -> Callable[[int], int]:
    """Sample-set size per frame, falling linearly from ``start`` to ``end`` (000 §5.3).

    Returns a function ``size(k)`` of the 0-based frame number: ``start`` at frame 0,
    ``end`` from frame ``frames`` on, rounded linear interpolation in between (defaults:
    1500, 1250, 1000, 750, 500, 500, ...).  A large first set sweeps out the prior well
    enough to find the object; the smaller one tracks it cheaply.
    """
    start = _check_count(start, "start")
    end = _check_count(end, "end")
    if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 0:
        raise ConfigError(f"frames: expected an integer >= 0, got {frames!r}")
    frames = int(frames)

    def size(k: int) -> int:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
            raise ConfigError(f"frame number: expected an integer >= 0, got {k!r}")
        if k >= frames:
            return end
        return int(round(start + (end - start) * k / frames))

    return size
