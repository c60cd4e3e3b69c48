"""Writing output files so that they are never half-written.

Every file trackcli writes goes first to a temporary name in the same folder and is renamed
into place only when complete (``os.replace`` is atomic on one file system).  An interrupted
run therefore leaves either the old file or none, never a truncated one.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator

from .errors import InputError


def partial_name(path: Path) -> Path:
    """The temporary name used while ``path`` is being written."""
    return path.with_name(f".{path.name}.part")


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; rename it to ``path`` if the block succeeds.

    On any exception (including KeyboardInterrupt) the temporary file is removed.
    """
    path = Path(path)
    ensure_dir(path.parent)
    tmp = partial_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def ensure_dir(path: str | Path) -> Path:
    """Create the folder ``path`` (and parents) or raise a one-line error."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{path}: cannot create output folder ({exc.strerror or exc})") from None
    if not path.is_dir():
        raise InputError(f"{path}: exists and is not a folder")
    return path
