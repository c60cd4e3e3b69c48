"""Exceptions raised by trackcli.

Every error a user can cause derives from :class:`TrackcliError`.  Each subclass also
inherits the matching builtin (``ValueError``, ``OSError``), so library callers may catch
either.  The command line maps each class to an exit code (``exit_code``) and prints
``str(error)`` as one line, without a traceback.

Exit codes (documented in the README):

=====  ============================================================
0      success
1      a run failed (e.g. some clips in a batch failed)
2      bad command-line usage (missing or unknown option or argument,
       conflicting options)
3      invalid configuration file or option value (Click's range and
       choice checks included), or an output that would replace an input
4      input missing, unreadable or malformed (video, template, model,
       CSV, manifest), or an output that cannot be written
5      the data cannot support the computation (too few frames,
       singular system, frames too small to draw on)
130    interrupted (Ctrl-C)
=====  ============================================================
"""

from __future__ import annotations


class TrackcliError(Exception):
    """Root of all trackcli errors."""

    exit_code = 1


class ConfigError(TrackcliError, ValueError):
    """A configuration value is unknown, of the wrong type or out of range."""

    exit_code = 3


class InputError(TrackcliError, OSError):
    """An input file is missing, unreadable or malformed."""

    exit_code = 4


class VideoError(InputError):
    """A video file or image folder cannot be opened or decoded."""


class TemplateError(InputError):
    """A template file is malformed."""


class ModelError(InputError):
    """A model file is malformed."""


class DataError(TrackcliError, ValueError):
    """The data are insufficient or degenerate for the requested computation."""

    exit_code = 5


def short_repr(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, for one-line messages.

    Large or deeply nested values (from a hostile input file) are abbreviated without
    being formatted in full.
    """
    import reprlib

    r = reprlib.Repr()
    r.maxlevel, r.maxlist, r.maxtuple, r.maxdict, r.maxset = 2, 4, 4, 4, 4
    r.maxstring = r.maxother = r.maxlong = limit
    text = r.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
