"""Classes listed by name and imported when first used (the trackers, the observation terms).

A registry is a mapping of names to ``"module:class"`` strings: listing a class costs no import,
and a new one is one line (:data:`trackcli.trackers.TRACKERS`, :data:`trackcli.observe.terms.TERMS`).
"""

from __future__ import annotations

import importlib
from typing import Any, Mapping

from trackcli.errors import ConfigError


def load(ref: str) -> Any:
    """The object ``ref`` names, ``"module:name"``."""
    module, _, name = ref.partition(":")
    return getattr(importlib.import_module(module), name)


def lookup(registry: Mapping[str, str], name: str, what: str) -> Any:
    """The class registered as ``name``; a ConfigError naming ``what`` and the valid names if none is."""
    if name not in registry:
        raise ConfigError(f"{what}: expected one of {', '.join(registry)}, got {name!r}")
    return load(registry[name])
