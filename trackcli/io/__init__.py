"""Everything read from or written to disk.

The file formats sit low in the package (``tests/test_layering.py``): they import only
:mod:`trackcli.errors`, :mod:`trackcli.settings` and :mod:`.outputs`, and know nothing of
curves, models or trackers.  What a format needs of those is handed to it: the track
writer's outline columns (:class:`.tracks.OutlineSource`, computed by
:mod:`trackcli.run.outline_columns`), the placing of a sample clip's true outlines
(``load_truth(outlines=...)``, passed by :mod:`trackcli.run.truth`).

- :mod:`.video` — decoding of video files and image folders.
- :mod:`.recording` — the Rerun ``.rrd`` recording of a run.
- :mod:`.encode` — H.264 video files and AV1 frames for recordings, through PyAV.
- :mod:`.tracks` — the track CSV: writing rows, reading tracks, outlines and uncertainty.
- :mod:`.truth` — what ``eval`` compares: a track's boxes and centres, and ground truth
  (truth CSVs, benchmark box files, folders).
- :mod:`.outputs` — atomic writes, output folders, refusal to write over inputs; below the
  settings, which read their file with it.
- :mod:`.viewer` — opening recordings in the Rerun viewer.
"""
