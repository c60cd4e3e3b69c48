"""The package's layers: which part of trackcli may import which.

Every module's imports of trackcli are read from its source (``ast``, imports inside functions
included) and checked against :data:`LAYERS`: a module may import its own part of the package
and any part of a lower layer, nothing above it and nothing beside it (parts of one layer are
independent of each other).  Reading from low to high:

- the root (``trackcli`` with its version, ``trackcli.errors``);
- ``trackcli.io.outputs``: atomic writes and the YAML reader, which the settings need;
- ``trackcli.settings``: every setting, read by every layer above;
- ``trackcli.io``: the file formats (video, track and truth CSVs, the Rerun recording, the
  viewer).  They know nothing of curves, models or trackers: a format that needs such a thing
  is given it by its caller (``io.truth.load_truth(outlines=...)``, ``io.tracks.OutlineSource``);
- ``trackcli.shapes``: splines, shape-spaces, templates;
- ``trackcli.dynamics`` (AR(2) models, their Kalman filter and smoother, learning) and
  ``trackcli.sample_data`` (the synthetic clips), side by side;
- ``trackcli.observe``: image measurement and observation models;
- ``trackcli.trackers``: the trackers and their frame loop;
- ``trackcli.run``: what a command runs (a clip, a batch, a training cycle, a score);
- ``trackcli.cli``: the commands.

Besides, the modules must not import each other in a circle, and two heavy libraries stay
in one place each: ``rerun`` in ``trackcli.io.recording``, ``click`` in ``trackcli.cli``.
(How long a module may be is ``tests/test_layout.py``'s business.)

What breaks these rules today is listed, with the reason, in :data:`EXCEPTIONS` and
:data:`CYCLES`, to be removed by whoever owns that code; an entry that no longer occurs fails
the test too, so the lists only shrink.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "trackcli"

#: the layers, lowest first; the parts in one layer may not import each other
LAYERS: tuple[tuple[str, ...], ...] = (
    ("trackcli", "trackcli.errors"),
    ("trackcli.io.outputs", "trackcli.registry"),
    ("trackcli.settings",),
    ("trackcli.io",),
    ("trackcli.shapes",),
    ("trackcli.dynamics", "trackcli.sample_data"),
    ("trackcli.observe",),
    ("trackcli.segment",),
    ("trackcli.trackers",),
    ("trackcli.run",),
    ("trackcli.cli",),
)

#: imports against the layers that remain, (importer, imported) -> why, and who removes them
EXCEPTIONS: dict[tuple[str, str], str] = {
}

#: import cycles between modules that remain (each as its modules, sorted) -> why
CYCLES: dict[tuple[str, ...], str] = {
}

#: third-party packages allowed only in these parts of trackcli
CONFINED: dict[str, tuple[str, ...]] = {
    "rerun": ("trackcli.io.recording",),
    "click": ("trackcli.cli",),
}


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> tuple[set[str], set[str]]:
    """The trackcli modules that module ``name`` imports anywhere in its source, and the
    top-level names of the other packages it imports."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    ours: set[str] = set()
    theirs: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package, level - 1 packages up
                up = package[: len(package) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            # `from trackcli.dynamics import kalman` imports the module trackcli.dynamics.kalman
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        for target in targets:
            if target == "trackcli" or target.startswith("trackcli."):
                ours.add(target)
            else:
                theirs.add(target.split(".")[0])
    return ours, theirs


IMPORTS = {name: _imports(name, path) for name, path in MODULES.items()}


def _part(module: str) -> tuple[str, int]:
    """The part of :data:`LAYERS` a module belongs to (the longest that contains it; the root
    only by name), and its layer."""
    best = None
    for rank, layer in enumerate(LAYERS):
        for part in layer:
            inside = module == part or (part != "trackcli" and module.startswith(part + "."))
            if inside and (best is None or len(part) > len(best[0])):
                best = (part, rank)
    if best is None:
        raise AssertionError(f"{module} is in no layer: add it, or the package it starts, to LAYERS")
    return best


def _violations() -> set[tuple[str, str]]:
    found = set()
    for module, (ours, _) in IMPORTS.items():
        part, rank = _part(module)
        for target in ours:
            their_part, their_rank = _part(target)
            if their_part != part and their_rank >= rank:
                found.add((module, target))
    return found


def _cycles() -> set[tuple[str, ...]]:
    """The strongly connected components of more than one module (Tarjan)."""
    graph = {m: sorted(t for t in IMPORTS[m][0] if t in MODULES and t != m) for m in MODULES}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: set[tuple[str, ...]] = set()

    def visit(m: str) -> None:
        index[m] = low[m] = len(index)
        stack.append(m)
        on_stack.add(m)
        for n in graph[m]:
            if n not in index:
                visit(n)
                low[m] = min(low[m], low[n])
            elif n in on_stack:
                low[m] = min(low[m], index[n])
        if low[m] == index[m]:
            component = []
            while True:
                n = stack.pop()
                on_stack.discard(n)
                component.append(n)
                if n == m:
                    break
            if len(component) > 1:
                found.add(tuple(sorted(component)))

    for m in graph:
        if m not in index:
            visit(m)
    return found


def test_every_module_is_in_a_layer():
    for module in MODULES:
        _part(module)


def test_no_module_imports_a_layer_above_its_own_or_beside_it():
    found = _violations()
    new = sorted(found - set(EXCEPTIONS))
    assert not new, "imports against the layers (see this test's docstring):\n" + "\n".join(
        f"  {a} imports {b}" for a, b in new)


def test_the_listed_exceptions_still_occur():
    gone = sorted(set(EXCEPTIONS) - _violations())
    assert not gone, "no longer needed, remove from EXCEPTIONS:\n" + "\n".join(f"  {a} -> {b}" for a, b in gone)


def test_no_modules_import_each_other_in_a_circle():
    found = _cycles()
    new = sorted(found - set(CYCLES))
    assert not new, "import cycles:\n" + "\n".join("  " + " <-> ".join(c) for c in new)
    gone = sorted(set(CYCLES) - found)
    assert not gone, "no longer a cycle, remove from CYCLES:\n" + "\n".join("  " + " <-> ".join(c) for c in gone)


@pytest.mark.parametrize("library", sorted(CONFINED))
def test_heavy_libraries_stay_in_their_module(library):
    allowed = CONFINED[library]
    users = sorted(m for m, (_, theirs) in IMPORTS.items() if library in theirs)
    assert users, f"no module imports {library}: update CONFINED"
    outside = [m for m in users if not any(m == a or m.startswith(a + ".") for a in allowed)]
    assert not outside, f"{library} imported outside {', '.join(allowed)}: {', '.join(outside)}"


def test_the_checks_see_imports_inside_functions_and_relative_ones(tmp_path):
    # the reader itself: an import in a function body and a relative import are both found
    source = tmp_path / "probe.py"
    source.write_text("from . import spline\n\ndef f():\n    from trackcli.run.evaluate import polygon_iou\n"
                      "    import rerun as rr\n")
    ours, theirs = _imports("trackcli.shapes.probe", source)
    assert ours == {"trackcli.shapes.spline", "trackcli.run.evaluate"}
    assert theirs == {"rerun"}
    assert _part("trackcli.shapes.probe") == ("trackcli.shapes", 4)
    assert _part("trackcli.io.outputs") == ("trackcli.io.outputs", 1)
    assert _part("trackcli") == ("trackcli", 0)
    with pytest.raises(AssertionError, match="in no layer"):
        _part("trackcli.newthing")
