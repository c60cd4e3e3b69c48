"""Motion models over a shape-space: what they are, how they are set and learned.

- :mod:`.ar2` — the second-order auto-regressive model ``X_k - X̄ = A2 (X_{k-2} - X̄) +
  A1 (X_{k-1} - X̄) + B0 w_k`` (AC eq 9.15, :class:`.ar2.AR2`), its state-space form (AC eq
  9.18, :func:`.ar2.state_matrices`), steady state (AC eq 9.23,
  :func:`.ar2.stationary_covariance`), prediction of many samples
  (:func:`.ar2.predict_samples`), sample paths, modes (AC eqs 11.10–11.13), damped
  oscillators per subspace (AC eqs 9.25–9.26).
- :mod:`.handset` — the hand-set dynamics a template gets before learning (AC §9.6).
- :mod:`.learning` — maximum-likelihood learning of ``A1, A2, B0, X̄`` from tracked
  sequences (AC Fig 11.6), pooled over several sequences.
- :mod:`.em` — expectation–maximisation learning from the Kalman smoother's output.
- :mod:`.model` — the model file (dynamics, shape-space, template), and placement of a
  learned model on a new template.
- :mod:`.simulate` — sample paths of a model drawn as curves.
"""
