"""Motion models over a shape-space: what they are, how they are set and learned, and the
Kalman filter and smoother over them.

The package sits below the observation models and the trackers (``tests/test_layering.py``):
learning (:mod:`.em`) and the trackers both use its filter and smoother.

- :mod:`.ar2` — the second-order auto-regressive model ``X_k - X̄ = A2 (X_{k-2} - X̄) +
  A1 (X_{k-1} - X̄) + B0 w_k`` (AC eq 9.15, :class:`.ar2.AR2`), its state-space form (AC eq
  9.18, :func:`.ar2.state_matrices`), steady state (AC eq 9.23,
  :func:`.ar2.stationary_covariance`), prediction of many samples
  (:func:`.ar2.predict_samples`), sample paths, modes (AC eqs 11.10–11.13).
- :mod:`.handset` — hand-set dynamics (AC §9.6): damped oscillators (AC eqs 9.25–9.28,
  :func:`.handset.oscillator_coefficients`), the partitioned model over H-orthogonal
  subspaces (AC eq 9.30, :func:`.handset.partitioned`), and the model a template gets from
  the ``dynamics`` settings before learning (:func:`.handset.handset_dynamics`).
- :mod:`.kalman` — the Kalman filter for AR(2) dynamics: predict and assimilate (AC Fig
  10.3, :func:`.kalman.predict`, :func:`.kalman.assimilate`), initial states, validation
  gates.
- :mod:`.rts` — the Rauch–Tung–Striebel smoother, and the forward pass over information
  pairs with the log-likelihood of a sequence (:func:`.rts.filter_information`), which EM
  runs at every iteration.
- :mod:`.learning` — maximum-likelihood learning of ``A1, A2, B0, X̄`` from tracked
  sequences (AC Fig 11.6), pooled over several sequences.
- :mod:`.em` — expectation–maximisation learning from noisy measurements, with the
  smoother of :mod:`.rts` as its E-step.
- :mod:`.model` — the model file (dynamics, shape-space, template), and placement of a
  learned model on a new template.
- :mod:`.mixed` — mixed-state models (001 §8): labels, transition matrix, the model file,
  learning from labelled frame ranges.
- :mod:`.mixed_dynamics` — a mixed-state model on one shape-space: the prediction step of
  mixed-state CONDENSATION and the bounce event.
- :mod:`.simulate` — sample paths of a model drawn as curves.
"""
