"""A motion cue for CONDENSATION: where the dense optical flow says the object moved.

The AR(2) prior predicts smooth motion; an object that starts, stops or swings faster than the
prior's noise allows (a kick, a dancer's turn, a bird taking off) leaves it behind, and the
jumps of the motion prior (:func:`trackcli.trackers.condensation_tracker.translation_jumps`)
cover such a move only thinly.  The optical flow between the last frame and this one measures
the move: :meth:`trackcli.observe.region.FlowPrior.shift` is the median flow over the last
estimate's region, and :func:`flow_proposal` draws a share of the samples about the last
estimate moved by it.

This is Isard & Blake's ICONDENSATION (1998): the samples come from a mixture of the prior
``f`` (the dynamics' prediction with its jumps) and an importance function ``g`` (here the
flow's prediction), and each carries the weight ``f / ((1 - q) f + q g)`` (``q`` the share
drawn from ``g``), so that the weighted set stays a fair sample of the prior and, once weighted
by the likelihood, of the posterior.  The flow changes where the samples are looked for, not
what the posterior is: a flow that is wrong wastes a share of the samples, and the likelihood
decides between the flow's place and the prior's.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["FLOW_SPREAD", "mixture_log_correction", "prior_log_density", "flow_proposal"]

#: standard deviation (per axis) of the flow proposal about its prediction, in object sizes
#: (at least :data:`MIN_SPREAD` px): the median flow is good to about a pixel, the estimate it
#: is added to less so
FLOW_SPREAD = 0.05
MIN_SPREAD = 1.0
#: smallest standard deviation (px per axis) of the Gaussian core fitted to the prior's samples:
#: a set that has collapsed onto one place still has a density
MIN_CORE = 0.5


def _log_gauss2_diag(d: np.ndarray, var: np.ndarray) -> np.ndarray:
    """Log density of a 2-D Gaussian with diagonal covariance ``var`` (2,) at offsets ``d`` (n, 2)."""
    return -0.5 * (d * d / var).sum(axis=1) - 0.5 * float(np.log(var).sum()) - math.log(2 * math.pi)


def prior_log_density(t: np.ndarray, samples: np.ndarray, jump_share: float = 0.0, jump_rms: float = 0.0):
    """An approximation of the density the prior's samples ``samples`` (n, 2) of translation were
    drawn from, evaluated at ``t`` (m, 2).

    The motion prior is the AR(2) prediction with, for a share ``jump_share`` of the samples, an
    isotropic jump of ``jump_rms`` px per axis (the motion prior's jumps, settings ``jumps``):
    ``f = (1 - J) N(m, C) + J N(m, C + s^2 I)``, ``m`` the samples' median and ``C`` the diagonal
    covariance of their median absolute deviations (robust to the jumped samples among them;
    at least :data:`MIN_CORE` px per axis).  The jumps give ``f`` the heavy tails the weights
    of samples drawn far from the prediction need.
    """
    s = np.asarray(samples, dtype=np.float64)
    m = np.median(s, axis=0)
    mad = np.median(np.abs(s - m), axis=0) * 1.4826
    var = np.maximum(mad, MIN_CORE) ** 2
    d = np.asarray(t, dtype=np.float64) - m
    core = _log_gauss2_diag(d, var)
    if jump_share <= 0 or jump_rms <= 0:
        return core
    wide = _log_gauss2_diag(d, var + jump_rms**2)
    if jump_share >= 1:
        return wide
    return np.logaddexp(math.log1p(-jump_share) + core, math.log(jump_share) + wide)


def mixture_log_correction(log_f: np.ndarray, log_g: np.ndarray, share: float) -> np.ndarray:
    """The log importance weight ``log f - log((1 - q) f + q g)`` of samples drawn from the
    mixture of ``f`` (share ``1 - q``) and ``g`` (share ``q``): the weighted set is a fair sample
    of ``f``.  With ``g = f`` every correction is 0; with ``q = 0``, too."""
    log_f = np.asarray(log_f, dtype=np.float64)
    if share <= 0:
        return np.zeros_like(log_f)
    log_mix = np.logaddexp(math.log1p(-share) + log_f if share < 1 else -np.inf, math.log(share) + np.asarray(log_g))
    with np.errstate(invalid="ignore"):
        out = log_f - log_mix
    return np.where(np.isneginf(log_f), -np.inf, out)


def flow_proposal(centre: np.ndarray, spread: float, fraction: float, *, jump_share: float = 0.0,
                  jump_rms: float = 0.0):
    """An importance-sampling step for CONDENSATION from the flow's prediction (module docstring).

    A share ``fraction`` of the predicted samples (chosen at random) has its translation redrawn
    from ``g = N(centre, spread^2 I)`` (``centre`` (2,): the last estimate's translation moved
    by the flow, in the units of ``X[:2]``); their other components are kept, and their previous
    state stays their parent's, so that the move is also their velocity, which the AR(2) model
    carries on.  Every sample then carries the correction :func:`mixture_log_correction` with
    ``f`` from :func:`prior_log_density` of the predicted translations (``jump_share`` and
    ``jump_rms``: the motion prior's jumps, which the predicted samples already carry).

    Returns ``propose(prev, predicted, rng) -> (prev, shapes, log_correction)`` for
    :func:`trackcli.trackers.condensation.step`.
    """
    centre = np.asarray(centre, dtype=np.float64)[:2]
    var = np.full(2, float(spread) ** 2)

    def propose(prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = new.shape[0]
        k = int(round(fraction * n))
        if k == 0:
            return prev, new, np.zeros(n)
        t_prior = new[:, :2]
        out = new.copy()
        idx = rng.choice(n, size=k, replace=False)
        out[idx, :2] = centre + float(spread) * rng.standard_normal((k, 2))
        t = out[:, :2]
        log_f = prior_log_density(t, t_prior, jump_share, jump_rms)
        log_g = _log_gauss2_diag(t - centre, var)
        return prev, out, mixture_log_correction(log_f, log_g, k / n)

    return propose
