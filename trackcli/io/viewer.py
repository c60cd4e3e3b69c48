"""Opening a recording in the Rerun viewer, or saying what is missing.

The ``rerun-sdk`` wheel that trackcli depends on ships the viewer as the ``rerun`` program.
The native viewer needs a screen; on a machine without one (a server reached over SSH) the
same program can serve the web viewer over HTTP (``--web``), to be opened in a browser
elsewhere.  Either way a viewer of Rerun's own minor version (0.41) is needed: older and
newer viewers may refuse the file.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from trackcli.errors import InputError, TrackcliError

#: What to install where trackcli is not: a viewer of the recordings' version.
INSTALL_HINT = 'pip install "rerun-sdk==0.41.*"'

#: First bytes of an .rrd file.
RRD_MAGIC = b"RRF"


def check_recording(path: str | os.PathLike[str]) -> Path:
    """``path`` as a Path, or InputError if it is not a readable Rerun recording."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such recording")
    try:
        with p.open("rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise InputError(f"{p}: cannot read recording ({exc.strerror or exc})") from None
    if not head.startswith(RRD_MAGIC):
        raise InputError(f"{p}: not a Rerun recording (.rrd files start with {RRD_MAGIC.decode()})")
    return p


def find_viewer() -> str | None:
    """The ``rerun`` program: beside this Python (a virtual environment) or on PATH."""
    here = Path(sys.executable).with_name("rerun")
    if here.is_file() and os.access(here, os.X_OK):
        return str(here)
    return shutil.which("rerun")


def has_display(environ: dict[str, str] | None = None, platform: str | None = None) -> bool:
    """Whether a native window can open: always on macOS and Windows, with X11 or Wayland on Linux."""
    env = os.environ if environ is None else environ
    plat = sys.platform if platform is None else platform
    if not plat.startswith("linux"):
        return True
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def viewer_command(recording: Path, *, web: bool = False, port: int | None = None,
                   viewer: str | None = None, display: bool | None = None) -> list[str]:
    """The command that shows ``recording``, or a TrackcliError saying what to do instead."""
    exe = viewer if viewer is not None else find_viewer()
    if exe is None:
        raise TrackcliError(f"no Rerun viewer found (the 'rerun' program); install one with {INSTALL_HINT}, "
                            f"then run: rerun {recording}")
    if web:
        cmd = [exe, "--web-viewer", str(recording)]
        if port is not None:
            cmd[1:1] = ["--web-viewer-port", str(port)]
        return cmd
    if not (has_display() if display is None else display):
        raise TrackcliError(f"no screen for the native viewer here (DISPLAY is not set): run "
                            f"`trackcli view --web {recording}` and open the address it prints in a browser, "
                            f"or copy the file to a machine with a screen and run `rerun {recording}` there "
                            f"({INSTALL_HINT})")
    return [exe, str(recording)]


def run_viewer(cmd: list[str]) -> int:
    """Run the viewer until it is closed; its exit code."""
    try:
        return subprocess.call(cmd)
    except OSError as exc:
        raise TrackcliError(f"cannot start the viewer {cmd[0]}: {exc.strerror or exc}") from None


__all__ = ["INSTALL_HINT", "check_recording", "find_viewer", "has_display", "run_viewer", "viewer_command"]
