"""A command's options: the settings they make, and the error for options that do not go together.

:func:`settings_from` is the configuration file (or preset) overridden by the options
given; :class:`OptionError` is what the library raises when the options it was called with
conflict or one is missing (the command line reports it as a usage error, exit code 2).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from trackcli.errors import TrackcliError

if TYPE_CHECKING:
    from trackcli.settings import Settings


class OptionError(TrackcliError, ValueError):
    """Options that do not go together, or one that is missing (``trackcli``: exit code 2)."""

    exit_code = 2


def settings_from(config: str | None, overrides: dict[str, Any]) -> Settings:
    """The defaults, overridden by ``config`` (a file or preset name) and then by ``overrides``
    (dotted keys; a ``None`` value is an option not given)."""
    from trackcli.settings import load_settings

    return load_settings(config, given(overrides))


def given(overrides: dict[str, Any]) -> dict[str, Any]:
    """The ``overrides`` whose option was given (not ``None``)."""
    return {k: v for k, v in overrides.items() if v is not None}


def explicit_keys(config: str | None, overrides: dict[str, Any]) -> set[str]:
    """Dotted keys the user set: every key of the configuration file, and the options given."""
    from trackcli.settings import read_yaml

    keys = set(given(overrides))

    def walk(node: dict[str, Any], prefix: str) -> None:
        for k, v in node.items():
            key = f"{prefix}{k}"
            if isinstance(v, dict) and v:
                walk(v, key + ".")
            else:
                keys.add(key)

    if config is not None:
        walk(read_yaml(config), "")
    return keys
