"""The shape of the package: short command modules, no module too long to read, a light ``--help``."""

from __future__ import annotations

import json
import subprocess
import sys

from conftest import REPO

PACKAGE = REPO / "trackcli"
#: a command module is parsing and printing only
COMMAND_LINES = 300
#: beyond this a module holds more than one idea
MODULE_LINES = 700


def line_counts(folder):
    return {p.relative_to(PACKAGE).as_posix(): len(p.read_text(encoding="utf-8").splitlines())
            for p in sorted(folder.rglob("*.py"))}


def test_command_modules_are_short():
    counts = line_counts(PACKAGE / "cli")
    assert len(counts) >= 12, sorted(counts)  # the commands have a module each
    long = {name: n for name, n in counts.items() if n > COMMAND_LINES}
    assert not long, f"command modules over {COMMAND_LINES} lines (move the work to trackcli/run/): {long}"


def test_no_module_is_too_long():
    long = {name: n for name, n in line_counts(PACKAGE).items() if n > MODULE_LINES}
    assert not long, f"modules over {MODULE_LINES} lines: {long}"


def test_help_loads_neither_numpy_nor_opencv():
    code = (
        "import contextlib, io, json, sys\n"
        "from trackcli.cli.main import cli\n"
        "from click import Group\n"
        "def paths(group, prefix=()):\n"
        "    for name, cmd in group.commands.items():\n"
        "        yield (*prefix, name)\n"
        "        if isinstance(cmd, Group):\n"
        "            yield from paths(cmd, (*prefix, name))\n"
        "for args in [(), *paths(cli)]:\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        cli.main([*args, '--help'], prog_name='trackcli')\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    loaded = set(json.loads(out.stdout))
    assert "click" in loaded  # the check sees what was imported
    heavy = loaded & {"numpy", "cv2", "rerun", "yaml", "scipy", "numba"}
    assert not heavy, f"--help imported {sorted(heavy)}: import them inside the command functions"
