"""Everything read from or written to disk.

- :mod:`.video` — decoding of video files and image folders.
- :mod:`.recording` — the Rerun ``.rrd`` recording of a run.
- :mod:`.tracks` — the track CSV: writing rows, reading tracks, outlines and uncertainty.
- :mod:`.truth` — what ``eval`` compares: a track's boxes and centres, and ground truth
  (truth CSVs, benchmark box files, folders).
- :mod:`.outputs` — atomic writes, output folders, refusal to write over inputs.
- :mod:`.viewer` — opening recordings in the Rerun viewer.
"""
