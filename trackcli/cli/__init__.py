"""The command line: one module per command, each thin (parse options, call :mod:`trackcli.run`,
print or write); the group, its global options and the exit codes are in :mod:`.main`, the
options several commands share in :mod:`.options`."""

import os

# numpy's BLAS in one thread, unless the user says otherwise (read when numpy is first imported):
# the command's matrices are small (a sample set times the shape-space), and BLAS's own thread
# pool only spun between them, 3 ms of processor time a frame at 854x480 beside the threads
# that track, decode, refine and record (the results are the same)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from trackcli.cli.main import cli, main  # noqa: E402

__all__ = ["cli", "main"]
