"""The entry point of installations made before the commands had a module each: it now lives
in :mod:`trackcli.cli.main` (``pip install -e .`` again points ``trackcli`` there)."""

from trackcli.cli.main import cli, main

__all__ = ["cli", "main"]
