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

How large a share ``q`` to draw from ``g`` is learned as the frames go (:class:`AdaptiveShare`):
the adaptive mixture importance sampling of population Monte Carlo (Douc, Guillin, Marin & Robert
2007) sets each component's share of the next draw to the posterior mass it is responsible for,
``q' = sum_i w_i q g(x_i) / ((1 - q) f(x_i) + q g(x_i))`` (``w_i`` the normalised posterior
weights), i.e. one EM step toward the mixture nearest the posterior.  Where the flow's place is
where the likelihood puts the object and the prior's is not (a dash, a turn) the share grows; where
the flow is unreliable (a small fast ball, a region whose flow is the background's) it shrinks,
and fewer samples are spent on it.  The proposal's spread is learned the same way (the EM update
of its variance: the posterior's mean squared offset from its centre, weighted by the
responsibilities), so that a flow that is off by some pixels, as it is on an object smaller than
its patches or against the background's parallax, spreads its samples as far.  The weights are
right for any ``q`` and spread, so both may follow the past frames.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["FLOW_SPREAD", "AdaptiveShare", "FlowProposal", "mixture_log_correction", "prior_log_density",
           "flow_proposal"]

#: standard deviation (per axis) of the flow proposal about its prediction, in object sizes
#: (at least :data:`MIN_SPREAD` px): the median flow is good to about a pixel, the estimate it
#: is added to less so
FLOW_SPREAD = 0.05
MIN_SPREAD = 1.0
#: how far the flow proposal's share moves toward the posterior weight its samples earned, each
#: frame (:class:`AdaptiveShare`): one frame whose flow misled halves the share, not more
SHARE_RATE = 0.5
#: smallest standard deviation (px per axis) of the Gaussian core fitted to the prior's samples:
#: a set that has collapsed onto one place still has a density
MIN_CORE = 0.5
#: most kernels of the prior's density estimate (:func:`prior_log_density`)
KERNELS = 400


def _log_gauss2_diag(d: np.ndarray, var: np.ndarray) -> np.ndarray:
    """Log density of a 2-D Gaussian with diagonal covariance ``var`` (2,) at offsets ``d`` (n, 2)."""
    return -0.5 * (d * d / var).sum(axis=1) - 0.5 * float(np.log(var).sum()) - math.log(2 * math.pi)


def prior_log_density(t: np.ndarray, samples: np.ndarray, jump_share: float = 0.0, jump_rms: float = 0.0,
                      rng: np.random.Generator | None = None):
    """An approximation of the density the prior's samples ``samples`` (n, 2) of translation were
    drawn from, evaluated at ``t`` (m, 2).

    The motion prior is the AR(2) prediction with, for a share ``jump_share`` of the samples, an
    isotropic jump of ``jump_rms`` px per axis (the motion prior's jumps, settings ``jumps``):
    ``f = (1 - J) K + J N(m, C + s^2 I)``.  ``K`` is a kernel density estimate over the samples
    (Gaussian kernels, Silverman's width ``sd n^(-1/6)`` per axis from the samples' median absolute
    deviations, at least :data:`MIN_CORE` px; at most :data:`KERNELS` of the samples, drawn with
    ``rng``, as centres), which keeps the modes of a prior with more than one (a ball that may
    fly on or bounce); ``m`` is the samples' median and ``C`` the diagonal covariance of their
    median absolute deviations.  The jumps give ``f`` the heavy tails the weights of samples
    drawn far from the prediction need.
    """
    s = np.asarray(samples, dtype=np.float64)
    n = len(s)
    m = np.median(s, axis=0)
    sd = np.maximum(np.median(np.abs(s - m), axis=0) * 1.4826, MIN_CORE)
    d = np.asarray(t, dtype=np.float64) - m
    centres = s
    if n > KERNELS:
        pick = (rng or np.random.default_rng(0)).choice(n, size=KERNELS, replace=False)
        centres = s[pick]
    h2 = np.maximum(sd * len(centres) ** (-1.0 / 6.0), MIN_CORE) ** 2
    h = np.sqrt(h2)
    tt = np.asarray(t, dtype=np.float64) / h
    cc = centres / h
    c2 = 0.5 * (cc * cc).sum(axis=1)
    core = np.empty(len(tt))
    for a in range(0, len(tt), 1024):  # (block, kernels) at a time
        tb = tt[a:a + 1024]
        e = tb @ cc.T - c2  # -|t - c|^2 / 2 less -|t|^2 / 2, added below
        top = e.max(axis=1)
        np.subtract(e, top[:, None], out=e)
        np.exp(e, out=e)
        core[a:a + 1024] = top + np.log(e.sum(axis=1)) - 0.5 * (tb * tb).sum(axis=1)
    core += -math.log(len(centres)) - 0.5 * float(np.log(h2).sum()) - math.log(2 * math.pi)
    if jump_share <= 0 or jump_rms <= 0:
        return core
    wide = _log_gauss2_diag(d, sd**2 + jump_rms**2)
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


class FlowProposal:
    """An importance-sampling step for CONDENSATION from the flow's prediction (module docstring).

    A share ``fraction`` of the predicted samples (chosen at random) has its translation redrawn
    from ``g = N(centre, diag(spread^2))`` (``centre`` (2,): the last estimate's translation moved
    by the flow, in the units of ``X[:2]``; ``spread`` px, one or per axis); their other components are kept, and their previous
    state stays their parent's, so that the move is also their velocity, which the AR(2) model
    carries on.  Every sample then carries the correction :func:`mixture_log_correction` with
    ``f`` from :func:`prior_log_density` of the predicted translations (``jump_share`` and
    ``jump_rms``: the motion prior's jumps, which the predicted samples already carry).

    Called as ``propose(prev, predicted, rng) -> (prev, shapes, log_correction)`` for
    :func:`trackcli.trackers.condensation.step`; afterwards :attr:`responsibility` (n,) holds
    each sample's ``r g / ((1 - r) f + r g)`` with ``r`` the share ``reference`` (``fraction``
    unless given): the probability that a mixture with that share drew it from ``g`` (None
    before a call or when no sample was drawn from ``g``).  With ``groups`` (a call that returns
    each predicted sample's label, as mixed-state dynamics give them, or None), the prior's
    density is taken within each label: a sample the proposal moves keeps its label.
    """

    def __init__(self, centre: np.ndarray, spread: float | np.ndarray, fraction: float, *, jump_share: float = 0.0,
                 jump_rms: float = 0.0, reference: float | None = None,
                 groups: Callable[[], np.ndarray | None] | None = None) -> None:
        self.groups = groups
        self.reference = float(fraction if reference is None else reference)
        self.centre = np.asarray(centre, dtype=np.float64)[:2]
        self.spread = np.broadcast_to(np.asarray(spread, dtype=np.float64), (2,)).copy()
        self.fraction = float(fraction)
        self.jump_share, self.jump_rms = jump_share, jump_rms
        self.responsibility: np.ndarray | None = None

    def __call__(self, prev: np.ndarray, new: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = new.shape[0]
        k = int(round(self.fraction * n))
        self.responsibility = None
        if k == 0:
            return prev, new, np.zeros(n)
        t_prior = new[:, :2]
        out = new.copy()
        idx = rng.choice(n, size=k, replace=False)
        out[idx, :2] = self.centre + self.spread * rng.standard_normal((k, 2))
        t = out[:, :2]
        q = k / n
        labels = self.groups() if self.groups is not None else None
        if labels is None or len(labels) != n:
            log_f = prior_log_density(t, t_prior, self.jump_share, self.jump_rms, rng)
        else:  # a sample keeps its label: the prior's density of its place given that label
            log_f = np.empty(n)
            for label in np.unique(labels):
                g = labels == label
                log_f[g] = prior_log_density(t[g], t_prior[g], self.jump_share, self.jump_rms, rng)
        log_g = _log_gauss2_diag(t - self.centre, self.spread**2)
        log_c = mixture_log_correction(log_f, log_g, q)
        r = min(max(self.reference, 1e-12), 1.0)
        log_rg = math.log(r) + log_g
        log_mix = np.logaddexp(math.log1p(-r) + log_f if r < 1 else -np.inf, log_rg)
        self.responsibility = np.exp(np.minimum(log_rg - log_mix, 0.0))
        return prev, out, log_c


def flow_proposal(centre: np.ndarray, spread: float, fraction: float, *, jump_share: float = 0.0,
                  jump_rms: float = 0.0, reference: float | None = None,
                  groups: Callable[[], np.ndarray | None] | None = None) -> FlowProposal:
    """The flow's importance-sampling step (:class:`FlowProposal`)."""
    return FlowProposal(centre, spread, fraction, jump_share=jump_share, jump_rms=jump_rms, reference=reference,
                        groups=groups)


class AdaptiveShare:
    """The share of the samples the flow proposal draws, learned from the posterior (module
    docstring): starts at ``largest``; after each frame whose samples it drew, the posterior
    mass the proposal is responsible for, clipped to ``[least, largest]``.  With ``least >=
    largest`` the share is fixed."""

    def __init__(self, largest: float, least: float) -> None:
        self.largest = float(largest)
        self.least = min(float(least), self.largest)
        self.share = self.largest
        #: how far (px per axis, rms) the posterior's samples the proposal is responsible for lie
        #: from its centre, followed as the share is (None before the first frame)
        self.error: np.ndarray | None = None

    def update_error(self, weights: np.ndarray, responsibility: np.ndarray | None, offsets: np.ndarray) -> None:
        """Follow :attr:`error` from this frame's posterior ``weights`` (n,), the proposal's
        :attr:`FlowProposal.responsibility` and the samples' ``offsets`` (n, 2) from its centre:
        the EM update of the proposal's variance, ``sum w r d^2 / sum w r``."""
        if responsibility is None:
            return
        w = np.asarray(weights, dtype=np.float64) * responsibility
        total = float(w.sum())
        if not np.isfinite(total) or total <= 1e-12:
            return
        e2 = (w @ (np.asarray(offsets, dtype=np.float64) ** 2)) / total
        if not np.all(np.isfinite(e2)):
            return
        old = e2 if self.error is None else self.error**2
        self.error = np.sqrt(old + SHARE_RATE * (e2 - old))

    def update(self, weights: np.ndarray, responsibility: np.ndarray | None) -> float:
        """The share for the next frame from this frame's normalised posterior ``weights`` (n,)
        and :attr:`FlowProposal.responsibility` (unchanged when it is None or the weights are not
        a distribution)."""
        if responsibility is not None:
            w = np.asarray(weights, dtype=np.float64)
            total = float(w.sum())
            if np.isfinite(total) and total > 0 and responsibility.shape == w.shape:
                earned = float(w @ responsibility) / total
                self.share = float(np.clip(self.share + SHARE_RATE * (earned - self.share), self.least, self.largest))
        return self.share
