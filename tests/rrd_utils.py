"""Read ``.rrd`` recordings back in tests (rerun-sdk 0.41, ``rerun.chunk.RrdReader``).

Entity paths are given and returned without the leading slash (``"video/estimate"``), as
they are logged.  Components are named ``"Archetype:field"`` (``"LineStrips2D:strips"``,
``"Scalars:scalars"``) or, for ``AnyValues``, by their key.  One entity may be spread over
several chunks; the helpers gather them and order rows by a timeline (static rows first),
then by logging order.  A cell is a Python list of the instances logged in that row.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pyarrow as pa
from rerun.chunk import RrdReader

ROW_ID = "rerun.controls.RowId"


def _abs(entity: str) -> str:
    return "/" + entity.strip("/")


def _chunks(path: str | os.PathLike[str], entity: str | None = None,
            component: str | None = None) -> list[Any]:
    stream = RrdReader(Path(path)).store().stream()
    if entity is not None or component is not None:
        stream = stream.filter(content=_abs(entity) if entity is not None else None,
                               components=component)
    return list(stream.to_chunks())


def _index_values(column: pa.ChunkedArray | pa.Array) -> list[int]:
    """Timeline values as integers (sequence numbers, or nanoseconds for times)."""
    if pa.types.is_duration(column.type) or pa.types.is_timestamp(column.type):
        column = column.cast(pa.int64())
    return column.to_pylist()


def entity_paths(path: str | os.PathLike[str]) -> set[str]:
    """All entities holding data (the recording's ``__properties`` left out)."""
    paths = {str(c.entity_path).lstrip("/") for c in _chunks(path)}
    return {p for p in paths if not p.startswith("__properties")}


def read_rows(path: str | os.PathLike[str], entity: str, component: str, *,
              timeline: str = "frame") -> list[tuple[int | None, list[Any]]]:
    """``(index, cell)`` for every non-null cell of ``entity``'s ``component``.

    ``index`` is the row's value on ``timeline`` (nanoseconds for time timelines), None
    for static rows and rows without that timeline.  Sorted by index, then logging order.
    """
    rows: list[tuple[tuple[int, int, bytes], int | None, list[Any]]] = []
    for chunk in _chunks(path, entity, component):
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if component not in names:
            continue
        cells = batch.column(names.index(component)).to_pylist()
        ids = batch.column(names.index(ROW_ID)).to_pylist()
        index = (_index_values(batch.column(names.index(timeline)))
                 if timeline in names else [None] * len(cells))
        for cell, row_id, ix in zip(cells, ids, index, strict=True):
            if cell is None:
                continue
            key = (0, 0, row_id) if ix is None else (1, ix, row_id)
            rows.append((key, ix, cell))
    rows.sort(key=lambda r: r[0])
    return [(ix, cell) for _, ix, cell in rows]


def read_column(path: str | os.PathLike[str], entity: str, component: str, *,
                timeline: str = "frame") -> list[list[Any]]:
    """The non-null cells of one component, in timeline order (see :func:`read_rows`)."""
    return [cell for _, cell in read_rows(path, entity, component, timeline=timeline)]


def read_index(path: str | os.PathLike[str], entity: str, component: str,
               timeline: str = "frame") -> list[int | None]:
    """The ``timeline`` value of each non-null cell, in the order of :func:`read_column`."""
    return [ix for ix, _ in read_rows(path, entity, component, timeline=timeline)]


def count_rows(path: str | os.PathLike[str], entity: str, component: str | None = None) -> int:
    """Number of rows logged to ``entity`` (with a non-null ``component``, if given)."""
    if component is not None:
        return len(read_rows(path, entity, component))
    return sum(c.num_rows for c in _chunks(path, entity))


def is_static(path: str | os.PathLike[str], entity: str, component: str) -> bool:
    """Whether every chunk holding ``component`` for ``entity`` is static."""
    chunks = [c for c in _chunks(path, entity, component)
              if component in c.to_record_batch().schema.names]
    return bool(chunks) and all(c.is_static for c in chunks)


def application_id(path: str | os.PathLike[str]) -> str:
    """The application id of the (first) recording in the file."""
    return RrdReader(Path(path)).recordings()[0].application_id


def blueprint_count(path: str | os.PathLike[str]) -> int:
    """How many blueprint stores the file carries."""
    return len(RrdReader(Path(path)).blueprints())


def rerun_executable() -> Path:
    """The ``rerun`` command-line tool installed next to the running Python."""
    exe = Path(sys.executable).with_name("rerun.exe" if os.name == "nt" else "rerun")
    if not exe.exists():
        raise FileNotFoundError(f"no rerun executable next to {sys.executable}")
    return exe


def rrd_cli(*args: str | os.PathLike[str], timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """Run ``rerun rrd ARGS`` headless with analytics off (``CI=true``)."""
    env = dict(os.environ, CI="true")
    return subprocess.run([str(rerun_executable()), "rrd", *map(str, args)], env=env,
                          capture_output=True, text=True, timeout=timeout, check=False)


def verify(path: str | os.PathLike[str]) -> subprocess.CompletedProcess[str]:
    """``rerun rrd verify PATH``; check ``returncode == 0``."""
    return rrd_cli("verify", path)
