"""Orchestration of the commands: what runs a clip, a batch, a training cycle, a score.

- :mod:`.clips` — set-up of a tracking run and the run over one clip (CSV, recording, summary).
- :mod:`.background` — decoding ahead and writing the recording in background threads.
- :mod:`.batch` — a batch of clips and its results; :mod:`.manifest` its manifest, :mod:`.jobs`
  one job (a clip and its outputs), :mod:`.executors` the worker processes and Dask cluster.
- :mod:`.train` — the track → learn cycle on training clips.
- :mod:`.drawing` — the B-spline fit of a drawn outline, its preview and recording (``draw``).
- :mod:`.confirm` — ``draw --box``'s masks tried on the frames that follow.
- :mod:`.evaluate` — scores against ground truth (centre error, IoU, precision, success).
- :mod:`.truth` — ground truth as ``eval`` reads it, with the true outlines of sample clips.
- :mod:`.outline_columns` — the outline points of each row of a track CSV.
- :mod:`.masks` — masks and the DAVIS scores J and F; :mod:`.mask_eval` — J and F of a mask
  folder or a track against true masks; :mod:`.export` — mask PNGs and VOT region lines.
- :mod:`.checks` — inputs that do not belong together, and collapsed sample sets.
- :mod:`.render` — overlays drawn on frames, videos and contact sheets.
- :mod:`.plots` — plots of scores.

What each command does, for its module under :mod:`trackcli.cli` to call:

- :mod:`.drawing` (``draw``), :mod:`.tracking` (``track``), :mod:`.learn` (``learn``),
  :mod:`.model_report` (``inspect``), :mod:`.simulation` (``simulate``), :mod:`.scoring`
  (``eval``), :mod:`.rendering` (``render``);
- :mod:`.options` — settings from a command's options, and :class:`.options.OptionError`
  for options that do not go together.
"""
