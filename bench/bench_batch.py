"""How `trackcli batch` scales with workers on the sample batch (examples/sample_manifest.yaml).

Times the whole batch (wall clock, outputs rewritten with --force) with ``--jobs 1``,
``--jobs 2`` and on a two-worker Dask ``LocalCluster`` (one thread per worker, processes),
``--repeat`` times each, and prints the medians and the speed-ups over ``--jobs 1``.  The
Dask figure is given warm (workers already started and imported) and cold (the first run).
Needs the sample-run templates and model: run ``examples/batch_sample.sh`` once first.

    python bench/bench_batch.py --repeat 3
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MANIFEST = REPO / "examples" / "sample_manifest.yaml"


def _batch(out: Path, *extra: str) -> float:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "trackcli.cli", "-q", "batch", str(MANIFEST), "-o", str(out), "--force",
                        *extra], capture_output=True, text=True, cwd=REPO)
    if r.returncode:
        raise SystemExit(f"batch {' '.join(extra)} failed: {r.stderr.strip()[-500:]}")
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-dask", action="store_true")
    args = ap.parse_args()
    if not (REPO / "examples" / "sample-run" / "head-model.yaml").is_file():
        raise SystemExit("run examples/batch_sample.sh once first (it draws the templates and learns the model)")
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    times: dict[str, list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for _ in range(args.repeat):
            for jobs in (1, 2):
                times.setdefault(f"--jobs {jobs}", []).append(_batch(out / f"j{jobs}", "--jobs", str(jobs)))
        if not args.no_dask:
            from distributed import LocalCluster

            with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
                runs = [_batch(out / "dask", "--scheduler", cluster.scheduler_address) for _ in range(args.repeat + 1)]
            times["dask 2 workers, cold"] = runs[:1]
            times["dask 2 workers, warm"] = runs[1:]
    base = statistics.median(times["--jobs 1"])
    print(f"{'run':24s} {'median s':>9s} {'runs':>24s} {'speed-up':>9s}")
    for name, v in times.items():
        med = statistics.median(v)
        print(f"{name:24s} {med:9.2f} {', '.join(f'{x:.2f}' for x in v):>24s} {base / med:8.2f}x")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
