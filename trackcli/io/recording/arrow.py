"""Arrow conversions and validators of a recording's data (pyarrow comes with rerun-sdk).

Rerun's own Python conversions build one object per item; the particle contours of a frame
and the bar charts sent as columns are built here as Arrow arrays in one pass.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from trackcli.errors import ConfigError, DataError

#: Environment variable: ``0`` makes :class:`Recording` let pyarrow's check for pandas fail
#: at once (:func:`skip_pandas_check`).  pyarrow checks once per process whether pandas is
#: installed, by importing it, when it first converts data for Rerun: about 0.25 s, a sixth
#: of a short ``track`` run, and trackcli never hands pandas objects to pyarrow.  The
#: ``trackcli`` command sets it to 0 for itself and the processes it starts (batch workers)
#: unless it is set; code that imports trackcli as a library keeps pyarrow's behaviour.
PANDAS_CHECK_ENV = "TRACKCLI_PANDAS_CHECK"
_pandas_check_done = False


def skip_pandas_check() -> None:
    """Let pyarrow's one-time check for pandas find none, unless pandas is already imported.

    pyarrow remembers the answer for the process: its pandas conversions (``from_pandas``,
    ``to_pandas``) are then unavailable in this process.  pandas itself still imports.
    Only the first call in a process does anything.
    """
    global _pandas_check_done
    if _pandas_check_done or "pandas" in sys.modules:
        return
    _pandas_check_done = True

    class _NoPandas:
        def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
            if name == "pandas" or name.startswith("pandas."):
                raise ModuleNotFoundError(f"{name} is not imported in this process", name=name)
            return None

    import pyarrow as pa

    blocker = _NoPandas()
    sys.meta_path.insert(0, blocker)
    try:
        pa.array([0.0])  # the first conversion makes the check
    finally:
        sys.meta_path.remove(blocker)


def _points(value: Any, name: str, *, leading: int | None = None) -> np.ndarray:
    """Validate an array of 2-D points of shape (..., 2) and return it as float32."""
    a = np.asarray(value, dtype=np.float32)
    if a.ndim < 1 or a.shape[-1] != 2:
        raise DataError(f"{name} must have shape (..., 2) in (x, y) order, got shape {a.shape}")
    if leading is not None and a.ndim != leading + 1:
        raise DataError(
            f"{name} must have {leading + 1} dimensions ending in 2, got shape {a.shape}"
        )
    return a


def _nbytes(value: Any) -> int:
    """The size of a held component's data, roughly (arrays and byte strings exactly)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, (bytes, str)):
        return len(value)
    if isinstance(value, (list, tuple)):
        return sum(_nbytes(v) for v in value)
    return 8


def _strips_arrow(blocks: Sequence[np.ndarray]) -> Any:
    """Line strips as the Arrow array of Rerun's ``LineStrip2D`` batch.

    ``blocks`` are float32 arrays of shape (K, n, 2): K strips of n points each (the K
    particle contours of a frame, say), in order.  Built from one buffer of points and the
    strips' offsets; Rerun's own conversion takes each strip separately, twenty times slower
    for the particle contours of a frame.
    """
    import pyarrow as pa
    from rerun.components import LineStrip2DBatch

    kind = LineStrip2DBatch._ARROW_DATATYPE
    lengths = (np.concatenate([np.full(b.shape[0], b.shape[1], np.int32) for b in blocks]) if len(blocks)
               else np.zeros(0, np.int32))
    offsets = np.zeros(lengths.size + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    flat = (np.concatenate([np.asarray(b, dtype=np.float32).reshape(-1) for b in blocks]) if len(blocks)
            else np.zeros(0, np.float32))
    points = pa.FixedSizeListArray.from_arrays(pa.array(flat, type=pa.float32()), type=kind.value_type)
    return pa.ListArray.from_arrays(pa.array(offsets), points, type=kind)


def _tensors_arrow(rows: Sequence[np.ndarray]) -> Any:
    """1-D tensors (one per row, as float64) as the Arrow array of Rerun's ``TensorData`` batch.

    Rerun's Python side converts one tensor per call only; bar charts sent as columns need
    the batch, built here from the same Arrow type (shape, no names, an ``F64`` buffer).
    """
    import pyarrow as pa
    from rerun.components import TensorDataBatch

    kind = TensorDataBatch._ARROW_DATATYPE
    union = kind.field("buffer").type
    n = len(rows)
    values = [np.asarray(r, dtype=np.float64).reshape(-1) for r in rows]
    lengths = np.fromiter((v.size for v in values), dtype=np.int64, count=n)
    shape = pa.ListArray.from_arrays(pa.array(np.arange(n + 1, dtype=np.int32)),
                                     pa.array(lengths.astype(np.uint64), type=pa.uint64()),
                                     type=kind.field("shape").type)
    offsets = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    flat = np.concatenate(values) if n else np.zeros(0)
    children, code = [], None
    for i in range(union.num_fields):
        field = union.field(i)
        if field.name == "F64":
            children.append(pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, type=pa.float64()),
                                                     type=field.type))
            code = union.type_codes[i]
        else:
            children.append(pa.array([], type=field.type))
    buffer = pa.Array.from_buffers(union, n, [None, pa.py_buffer(np.full(n, code, np.int8)),
                                              pa.py_buffer(np.arange(n, dtype=np.int32))], children=children)
    return pa.StructArray.from_arrays([shape, pa.nulls(n, type=kind.field("names").type), buffer],
                                      fields=[kind.field(i) for i in range(kind.num_fields)])


def _color(value: Any, name: str = "color") -> np.ndarray:
    """Validate one RGB or RGBA colour given as integers 0–255."""
    c = np.asarray(value)
    if c.shape not in ((3,), (4,)) or np.any(c < 0) or np.any(c > 255):
        raise DataError(f"{name} must be 3 or 4 integers in 0..255 (RGB or RGBA), got {value!r}")
    return c.astype(np.uint8)


def _flatten(params: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested mappings to dotted keys with values Rerun's AnyValues accepts."""
    flat: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{name}."))
        elif value is None:
            continue
        elif isinstance(value, int) and not isinstance(value, bool) and not -2**63 <= value < 2**63:
            flat[name] = str(value)  # beyond int64 (e.g. a seed of 2**70): kept exactly, as text
        elif isinstance(value, (bool, int, float, str)):
            flat[name] = value
        elif isinstance(value, np.generic):
            flat[name] = value.item()
        elif isinstance(value, (np.ndarray, list, tuple)):
            arr = np.asarray(value)
            items = arr.ravel()
            flat[name] = items.tolist() if arr.dtype.kind in "biuf" else [str(v) for v in items]
        else:
            flat[name] = str(value)
    return flat


def _plain(value: Any) -> Any:
    """Convert numpy values and paths to plain Python for YAML output."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return str(value)



def _check_quality(quality: int) -> int:
    if isinstance(quality, bool) or int(quality) != quality or not 1 <= quality <= 100:
        raise ConfigError(f"JPEG quality must be an integer 1..100, got {quality!r}")
    return int(quality)


def _half_width(width: float) -> float:
    if not np.isfinite(width) or width <= 0:
        raise DataError(f"line width must be a positive number of pixels, got {width!r}")
    return 0.5 * float(width)


def _edges(x_edges: Any, bins: int) -> np.ndarray:
    e = np.asarray(x_edges, dtype=float)
    if e.shape != (bins + 1,):
        raise DataError(f"x_edges must have shape ({bins + 1},) for {bins} bins, got {e.shape}")
    if not np.all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
        raise DataError("x_edges must be finite and strictly increasing")
    return e

