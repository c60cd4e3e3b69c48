"""Maximum likelihood against EM on noisy shapes of a known AR(2) model.

The true model is a two-dimensional coherent oscillation (every component a damped
oscillator of AC §9.6: frequency ``f``, damping ``β``, steady-state RMS ``ρ``; 25 frames/s).
Each trial draws training sequences from it (stationary start), adds independent Gaussian
noise of standard deviation ``σ`` to every shape component, and learns:

- **MLE** (AC Fig 11.6, ``trackcli.dynamics.learning.fit_ar2``) from the noisy shapes as if exact;
- **EM** (``trackcli.dynamics.em.fit_ar2_em``) from the same shapes with their noise ``σ``.

Printed per trial: frequency and damping of the learned modes (the two nearest the truth
first), the driving-noise gain ``B0`` (mean of its diagonal) and, for EM, its iterations.
Then the mean absolute errors over the trials.

Usage::

    python bench/em_vs_mle.py [--trials 5] [--frames 250] [--sequences 2] [--sigma 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.em import InformationSequence, fit_ar2_em
from trackcli.dynamics.handset import oscillator_coefficients
from trackcli.dynamics.learning import fit_ar2

TAU = 0.04


def _modes(model: AR2) -> tuple[float, float]:
    """Frequency and damping of the learned mode nearest the true oscillation (worst of the pair)."""
    modes = sorted(model.modes(), key=lambda m: abs(m.frequency - ARGS.f) + abs(m.beta - ARGS.beta))
    worst = max(modes[:2], key=lambda m: abs(m.frequency - ARGS.f) + abs(m.beta - ARGS.beta))
    return worst.frequency, worst.beta


def main() -> None:
    a1, a2, b0 = oscillator_coefficients(ARGS.f, ARGS.beta, ARGS.rho, TAU)
    truth = AR2(a2 * np.eye(2), a1 * np.eye(2), b0 * np.eye(2), np.array([120.0, 80.0]), TAU)
    print(f"truth: f = {ARGS.f} Hz, beta = {ARGS.beta} /s, rho = {ARGS.rho} px, B0 = {b0:.3f}; "
          f"noise sigma = {ARGS.sigma} px; {ARGS.sequences} sequence(s) of {ARGS.frames} frames per trial")
    print(f"{'trial':>5}  {'method':6} {'f (Hz)':>8} {'beta (/s)':>10} {'B0':>7} {'iter':>5} {'s':>6}")
    errors = {"MLE": [], "EM": []}
    for trial in range(ARGS.trials):
        rng = np.random.default_rng(trial)
        clean = [truth.simulate(ARGS.frames, rng, burn_in=200) for _ in range(ARGS.sequences)]
        noisy = [X + ARGS.sigma * rng.standard_normal(X.shape) for X in clean]
        t0 = time.perf_counter()
        mle, _ = fit_ar2(noisy, TAU)
        t_mle = time.perf_counter() - t0
        t0 = time.perf_counter()
        seqs = [InformationSequence.from_shapes(Y, np.full(Y.shape, ARGS.sigma)) for Y in noisy]
        em, _, info = fit_ar2_em(seqs, TAU)
        t_em = time.perf_counter() - t0
        for name, model, it, secs in (("MLE", mle, "", t_mle), ("EM", em, info.iterations, t_em)):
            f, beta = _modes(model)
            b = float(np.mean(np.diag(model.B0)))
            errors[name].append((abs(f - ARGS.f), abs(beta - ARGS.beta), abs(b - b0)))
            print(f"{trial:>5}  {name:6} {f:8.3f} {beta:10.3f} {b:7.3f} {it!s:>5} {secs:6.2f}")
    print(f"{'':5}  {'truth':6} {ARGS.f:8.3f} {ARGS.beta:10.3f} {b0:7.3f}")
    print("mean absolute error over the trials:")
    for name, errs in errors.items():
        e = np.mean(errs, axis=0)
        print(f"  {name:4} f {e[0]:.3f} Hz, beta {e[1]:.3f} /s, B0 {e[2]:.3f}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--frames", type=int, default=250)
    parser.add_argument("--sequences", type=int, default=2)
    parser.add_argument("--sigma", type=float, default=2.0, help="measurement noise, px")
    parser.add_argument("--f", type=float, default=1.0, help="true frequency, Hz")
    parser.add_argument("--beta", type=float, default=0.5, help="true damping, 1/s")
    parser.add_argument("--rho", type=float, default=10.0, help="true steady-state RMS displacement, px")
    ARGS = parser.parse_args()
    main()
