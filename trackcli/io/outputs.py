"""Writing output files so that they are never half-written.

Every file trackcli writes goes first to a temporary name in the same folder and is renamed
into place only when complete (``os.replace`` is atomic on one file system).  An interrupted
run therefore leaves either the old file or none, never a truncated one.

Existing outputs are replaced; an output that names one of the command's own inputs is
refused (:func:`refuse_overwriting_inputs`).  Output folders a failed run created are
removed again if they stayed empty (:func:`output_dir`).  YAML inputs (configurations,
templates, models, manifests) are read with limits on size, nesting and alias expansion
(:func:`load_yaml_text`), so a hostile file is refused quickly with one line.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any, Iterator, Mapping

from trackcli.errors import ConfigError, InputError, TrackcliError

#: Largest YAML file read (bytes): trackcli's own files are a few kilobytes.
MAX_YAML_BYTES = 2 * 1024 * 1024
#: Largest number of YAML nodes after expanding aliases (a "billion laughs" file has 10**9).
MAX_YAML_NODES = 200_000
#: Deepest nesting of YAML collections.
MAX_YAML_DEPTH = 64


def partial_name(path: Path, *, keep_suffix: bool = False) -> Path:
    """The temporary name used while ``path`` is being written.

    With ``keep_suffix`` it ends like ``path`` (a video writer picks its container from the
    extension).
    """
    if keep_suffix:
        return path.with_name(f".{path.stem}.part{path.suffix}")
    return path.with_name(f".{path.name}.part")


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; rename it to ``path`` if the block succeeds.

    On any exception (including KeyboardInterrupt) the temporary file is removed.
    A file system error while writing (no permission, no space, a name too long) becomes an
    :class:`~trackcli.errors.InputError` naming ``path``.
    """
    path = Path(path)
    ensure_dir(path.parent)
    tmp = partial_name(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and not isinstance(exc, InputError):
            raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
        raise


@contextlib.contextmanager
def atomic_paths(*paths: str | Path) -> Iterator[list[Path]]:
    """Temporary paths (ending like each of ``paths``) for outputs that are written all or
    none: each is renamed into place only once the block has written every one.

    If the block fails, the temporary files are removed and the outputs of an earlier run
    stay as they were (a failure while writing the last of them does not take away the
    first).  A file system error becomes an :class:`~trackcli.errors.InputError`, as for
    :func:`atomic_path`.
    """
    finals = [Path(p) for p in paths]
    for p in finals:
        ensure_dir(p.parent)
        if p.is_dir():
            raise InputError(f"{p}: is a folder; give a file name")
    tmps = [partial_name(p, keep_suffix=True) for p in finals]
    try:
        yield tmps
        for tmp, path in zip(tmps, finals):
            os.replace(tmp, path)
    except BaseException as exc:
        for tmp in tmps:
            with contextlib.suppress(OSError):
                tmp.unlink()
        if isinstance(exc, OSError) and not isinstance(exc, InputError):
            raise InputError(f"{finals[0]}: cannot write ({exc.strerror or exc})") from None
        if isinstance(exc, TrackcliError) and len(exc.args) == 1:
            message = str(exc)  # name the output, not its temporary name
            for tmp, path in zip(tmps, finals):
                message = message.replace(str(tmp), str(path))
            if message != str(exc):
                raise type(exc)(message) from None
        raise


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8", newline="\n")
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


@contextlib.contextmanager
def output_dir(path: str | Path) -> Iterator[Path]:
    """Create the folder ``path`` (and parents) for the outputs of a block.

    If the block fails, the folders this call created are removed again when they are still
    empty, so a run that stops on bad input leaves nothing behind.
    """
    path = Path(path)
    missing = []
    p = path.absolute()
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    ensure_dir(path)
    try:
        yield path
    except BaseException:
        for folder in missing:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def check_output_folders(*paths: str | Path | None) -> None:
    """Fail early, with one line, when an output's folder cannot be made or written: before a
    command spends seconds on work it could not save."""
    for p in paths:
        if p is None:
            continue
        folder = Path(p).parent
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if not folder.is_dir():
            raise InputError(f"{p}: cannot create the output folder ({folder} is a file)")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"{p}: cannot write in {folder} (permission denied)")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): compare the resolved names
        try:
            return a.resolve() == b.resolve()
        except (OSError, RuntimeError):
            return False


def refuse_overwriting_inputs(outputs: Mapping[str, Any], inputs: Mapping[str, Any]) -> None:
    """Raise ConfigError if an output would write over an input or over another output.

    ``outputs`` and ``inputs`` map a label (the option or argument, for the message) to a
    path or None.  Files are the same when they are the same inode (hard links, symbolic
    links) or, for a file not yet written, when their resolved paths are equal.
    """
    outs = [(k, Path(v)) for k, v in outputs.items() if v is not None]
    ins = [(k, Path(v)) for k, v in inputs.items() if v is not None]
    for i, (label, out) in enumerate(outs):
        for what, src in ins:
            if _same_file(out, src):
                raise ConfigError(f"{out}: {label} would overwrite the input {src} ({what}); "
                                  "choose another output name")
        for other, out2 in outs[i + 1:]:
            if _same_file(out, out2):
                raise ConfigError(f"{out}: {label} and {other} name the same file; choose distinct names")


def load_yaml_text(text: str, where: str, error: type[Exception]) -> Any:
    """Parse YAML ``text`` safely, refusing documents that nest or expand too much.

    Aliases are counted as the nodes they stand for, so a file of nested aliases (the
    "billion laughs") is refused before anything is built from it.  ``where`` starts the
    one-line messages (``where line N: not valid YAML (problem)``).
    """
    import yaml

    loader = yaml.SafeLoader(text)
    try:
        try:
            node = loader.get_single_node()
        except RecursionError:
            raise error(f"{where}: not valid YAML (nested more than {MAX_YAML_DEPTH} levels deep)") from None
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = f" line {mark.line + 1}" if mark is not None else ""
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise error(f"{where}{line}: not valid YAML ({problem})") from None
        if node is None:
            return None
        _check_yaml_size(node, where, error)
        try:
            return loader.construct_document(node)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = f" line {mark.line + 1}" if mark is not None else ""
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise error(f"{where}{line}: not valid YAML ({problem})") from None
    finally:
        loader.dispose()


def _check_yaml_size(root: Any, where: str, error: type[Exception]) -> None:
    """Count the nodes of a composed YAML graph with aliases expanded, and its depth."""
    import yaml

    sizes: dict[int, tuple[int, int]] = {}  # id(node) -> (expanded nodes, depth)
    stack: list[tuple[Any, bool]] = [(root, False)]
    on_path: set[int] = set()
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            on_path.discard(key)
            if isinstance(node, yaml.MappingNode):
                children = [c for pair in node.value for c in pair]
            else:
                children = node.value
            n = 1 + sum(sizes[id(c)][0] for c in children)
            depth = 1 + max((sizes[id(c)][1] for c in children), default=0)
            if n > MAX_YAML_NODES:
                raise error(f"{where}: too large once its aliases are expanded (more than {MAX_YAML_NODES} "
                            "values); refusing to read it")
            if depth > MAX_YAML_DEPTH:
                raise error(f"{where}: not valid YAML (nested more than {MAX_YAML_DEPTH} levels deep)")
            sizes[key] = (n, depth)
            continue
        if key in sizes:
            continue
        if not isinstance(node, (yaml.SequenceNode, yaml.MappingNode)):
            sizes[key] = (1, 0)
            continue
        if key in on_path:
            raise error(f"{where}: a YAML alias refers to itself; refusing to read it")
        on_path.add(key)
        stack.append((node, True))
        children = [c for pair in node.value for c in pair] if isinstance(node, yaml.MappingNode) else node.value
        for c in children:
            if id(c) not in sizes:
                stack.append((c, False))


def other_kind(data: Any, expected: str | None = None) -> str | None:
    """``"a model file (kind: trackcli-model)"`` when ``data`` (a parsed YAML file) is a trackcli
    file of another kind than ``expected``, for the message that names a file given in the
    wrong place (a model as a template, a template as a configuration); else None."""
    kind = data.get("kind") if isinstance(data, dict) else None
    if isinstance(kind, str) and kind.startswith("trackcli-") and kind != expected:
        return f"a {kind[len('trackcli-'):]} file (kind: {kind})"
    return None


def read_yaml_file(path: str | Path, what: str, error: type[Exception], invalid: type[Exception] | None = None):
    """Parse the YAML file ``path`` (a ``what`` file, for messages), raising ``error`` with one line.

    Missing file: ``PATH: no such WHAT file``; bad YAML: ``PATH line N: not valid YAML (problem)``;
    unreadable: ``PATH: cannot read WHAT file (reason)``; larger than :data:`MAX_YAML_BYTES`,
    nested deeper than :data:`MAX_YAML_DEPTH` or expanding to more than
    :data:`MAX_YAML_NODES` values: refused, see :func:`load_yaml_text`.  ``invalid`` (default
    ``error``) is raised for a file that reads but is not acceptable YAML.
    """
    p = Path(path)
    if not p.is_file():
        raise error(f"{p}: no such {what} file")
    try:
        size = p.stat().st_size
        if size > MAX_YAML_BYTES:
            raise (invalid or error)(f"{p}: too large for a {what} file ({size / 2**20:.1f} MiB; at most "
                        f"{MAX_YAML_BYTES // 2**20} MiB)")
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise error(f"{p}: cannot read {what} file (not a text file: {what} files are UTF-8 YAML)") from None
    except OSError as exc:
        if isinstance(exc, TrackcliError):
            raise
        raise error(f"{p}: cannot read {what} file ({exc.strerror or exc})") from None
    return load_yaml_text(text, str(p), invalid or error)
