"""Orchestration of the commands: what runs a clip, a batch, a training cycle, a score.

- :mod:`.clips` — set-up of a tracking run and the run over one clip (CSV, recording, summary).
- :mod:`.background` — decoding ahead and writing the recording in background threads.
- :mod:`.batch` — manifests of clips run in worker processes or on a Dask cluster.
- :mod:`.train` — the track → learn cycle on training clips.
- :mod:`.drawing` — the B-spline fit of a drawn outline, its preview and recording (``draw``).
- :mod:`.confirm` — ``draw --box``'s masks tried on the frames that follow.
- :mod:`.evaluate` — scores against ground truth (centre error, IoU, precision, success).
- :mod:`.render` — overlays drawn on frames, videos and contact sheets.
- :mod:`.plots` — plots of scores.
"""
