"""What every command prints with: progress bars on stderr, JSON lines on stdout, ``-q``.

Progress bars are the command line's business: the library takes a ``progress(label, n)``
factory (see :func:`trackcli.run.clips.track_clip`) and :func:`bars` makes one that draws
Click's bars, hidden with ``-q`` or when stderr is not a terminal (``TRACKCLI_PROGRESS=1``
shows them anyway).
"""

from __future__ import annotations

import math
import os
import sys
from typing import Any, Callable, ContextManager

import click


def is_quiet(ctx: click.Context | None = None) -> bool:
    """Whether ``trackcli -q`` was given."""
    root = (ctx or click.get_current_context()).find_root().obj
    return bool(root and root.get("quiet"))


def progress(ctx: click.Context, length: int, label: str) -> ContextManager[Any]:
    """A progress bar of ``length`` steps on stderr (its value has ``update(k)``)."""
    hidden = is_quiet(ctx) or not sys.stderr.isatty() and os.environ.get("TRACKCLI_PROGRESS") != "1"
    return click.progressbar(length=length, label=label, file=sys.stderr, show_pos=True, width=30, hidden=hidden)


def bars(ctx: click.Context | None = None) -> Callable[[str, int], ContextManager[Any]]:
    """The ``progress(label, n)`` factory the library's long runs take."""
    ctx = ctx or click.get_current_context()
    return lambda label, n: progress(ctx, n, label)


def echo_json(obj: Any, digits: int | None = None) -> None:
    """``obj`` as one line of JSON on stdout: NaN and infinities as null, numpy values as numbers;
    with ``digits``, floats keep that many significant digits."""
    import json

    click.echo(json.dumps(clean_json(obj, digits), allow_nan=False, default=_json_default))


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def clean_json(d: Any, digits: int | None = None) -> Any:
    """NaN and infinities become None; with ``digits``, floats keep that many significant digits."""
    if isinstance(d, dict):
        return {k: clean_json(v, digits) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [clean_json(v, digits) for v in d]
    if isinstance(d, float) and not math.isfinite(d):
        return None
    if isinstance(d, float) and digits is not None:
        return float(f"{d:.{digits}g}")
    return d
