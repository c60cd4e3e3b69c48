"""Motion models over a shape-space: what they are, how they are set and learned.

- :mod:`.ar2` — the second-order auto-regressive model ``X_k - X̄ = A2 (X_{k-2} - X̄) +
  A1 (X_{k-1} - X̄) + B0 w_k`` (AC eq 9.15, :class:`.ar2.AR2`), its companion form,
  steady state, sampling (:func:`.ar2.sample_paths`), modes, and the hand-set models of
  AC §9.2 (damped oscillators, constant velocity) per subspace.
- :mod:`.learning` — maximum-likelihood learning of ``A1, A2, B0, X̄`` from tracked
  sequences (AC Fig 11.6 and eqs 11.4–11.6, pooled over several sequences).
- :mod:`.em` — expectation–maximisation learning from the Kalman smoother's output
  (AC §11.2 notes).
- :mod:`.model` — the model file (dynamics, shape-space, template), and placement of a
  learned model on a new template.
- :mod:`.simulate` — sample paths of a model drawn as curves.
"""
