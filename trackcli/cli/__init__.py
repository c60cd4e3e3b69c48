"""The command line: Click commands only; the work is done in :mod:`trackcli.run`."""

from trackcli.cli.commands import cli, main

__all__ = ["cli", "main"]
