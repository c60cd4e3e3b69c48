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


def read_yaml_file(path: str | Path, what: str, error: type[Exception]):
    """Parse the YAML file ``path`` (a ``what`` file, for messages), raising ``error`` with one line.

    Missing file: ``PATH: no such WHAT file``; bad YAML: ``PATH line N: not valid YAML (problem)``;
    unreadable: ``PATH: cannot read WHAT file (reason)``.
    """
    import yaml

    p = Path(path)
    if not p.is_file():
        raise error(f"{p}: no such {what} file")
    try:
        return yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{p}{where}: not valid YAML ({problem})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{p}: cannot read {what} file ({exc})") from None
