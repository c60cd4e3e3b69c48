"""The command line: one module per command, each thin (parse options, call :mod:`trackcli.run`,
print or write); the group, its global options and the exit codes are in :mod:`.main`, the
options several commands share in :mod:`.options`."""

from trackcli.cli.main import cli, main

__all__ = ["cli", "main"]
