"""Run many ``trackcli`` command lines, each in its own process, paying Python's start-up once.

Used by ``test_bad_input.py``.  Reads a JSON list of cases on stdin, each
``{"args": [...], "cwd": "..."}``, and writes a JSON list of results on stdout, each
``{"code", "stdout", "stderr", "maxrss_mib", "inputs"}``.

Every case runs in a child forked from this process after the heavy libraries are
imported: the child changes to ``cwd``, sends its stdout and stderr to files and runs the
``trackcli`` entry point (:func:`trackcli.cli.main`) on ``args`` exactly as the console
script does.  An exception that escapes is printed with its traceback, as the interpreter
would.  While it runs, the parent watches its resident memory and kills it beyond
:data:`RSS_LIMIT` (so a runaway allocation fails the case quickly instead of swapping; an
address-space limit would not do: Rerun and the thread pools reserve gigabytes they never
touch).  The parent reaps the child with ``os.wait4`` to get its peak resident memory, and
after each case records a digest of every file under the inputs folder (``argv[1]``), so a
case that changed an input is named.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

#: Resident memory beyond which a case is killed (bytes).
RSS_LIMIT = 1024**3
#: How often the parent looks at a running case's memory (seconds).
POLL = 0.02


def digest(folder: Path) -> str:
    """Hash of every file's relative path and contents under ``folder``."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(str(p.relative_to(folder)).encode("utf-8", "surrogateescape") + b"\0")
        if p.is_file() and not p.is_symlink():
            h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def rss(pid: int) -> int:
    """Resident memory of process ``pid`` in bytes (0 once it has exited)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def run_case(args: list[str], cwd: str) -> dict:
    out = tempfile.TemporaryFile()
    err = tempfile.TemporaryFile()
    pid = os.fork()
    if pid == 0:  # the child: behave like `trackcli ARGS` started in cwd
        code = 1
        try:
            os.chdir(cwd)
            os.dup2(out.fileno(), 1)
            os.dup2(err.fileno(), 2)
            sys.argv = ["trackcli", *args]
            from trackcli.cli import main

            main()
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except BaseException:
            import traceback

            traceback.print_exc()
            code = 1
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    killed = False
    while True:
        done, status, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        if not killed and rss(pid) > RSS_LIMIT:
            os.kill(pid, signal.SIGKILL)
            killed = True
        time.sleep(POLL)
    out.seek(0)
    err.seek(0)
    return {"code": os.waitstatus_to_exitcode(status), "killed_for_memory": killed,
            "stdout": out.read().decode("utf-8", "replace"),
            "stderr": err.read().decode("utf-8", "replace"), "maxrss_mib": usage.ru_maxrss / 1024}


def main() -> None:
    inputs = Path(sys.argv[1])
    cases = json.load(sys.stdin)
    import numpy  # noqa: F401  -- the heavy imports, once, before forking
    import cv2  # noqa: F401
    import yaml  # noqa: F401

    import trackcli.run.batch  # noqa: F401
    import trackcli.cli  # noqa: F401
    import trackcli.run.drawing  # noqa: F401
    import trackcli.segment.grabcut  # noqa: F401
    import trackcli.run.evaluate  # noqa: F401
    import trackcli.run.train  # noqa: F401

    results = []
    for case in cases:
        r = run_case(case["args"], case["cwd"])
        r["inputs"] = digest(inputs)
        results.append(r)
    json.dump(results, sys.stdout)


if __name__ == "__main__":
    main()
