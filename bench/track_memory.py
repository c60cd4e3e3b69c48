"""Memory of a long ``track`` run: resident set size at frames 1 k, 10 k and 20 k.

A long 320 x 240 clip (a textured ellipse drifting over a noisy background, Motion-JPEG) is
written once into a temporary folder; ``trackcli track`` then follows the ellipse with the
default settings, CSV and recording on, in this process, and the resident set size is read
from ``/proc/self/status`` when the chosen frames are reached.  Printed: RSS at each mark,
its growth per frame between marks, and the size of the recording per frame.

Usage::

    python bench/track_memory.py [--frames 20000] [--marks 1000,10000,20000]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from trackcli.settings import load_settings  # noqa: E402
from trackcli.run import clips  # noqa: E402


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def write_clip(path: Path, n: int) -> tuple[float, float, float, float]:
    rng = np.random.default_rng(0)
    background = (120 + 25 * rng.standard_normal((240, 320, 3))).clip(0, 255).astype(np.uint8)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (320, 240))
    for k in range(n):
        img = background.copy()
        cx = 160 + 60 * np.sin(2 * np.pi * k / 400.0)
        cy = 120 + 30 * np.sin(2 * np.pi * k / 290.0)
        cv2.ellipse(img, ((cx, cy), (56, 76), 0.0), (40, 60, 150), -1, cv2.LINE_AA)
        writer.write(img)
    writer.release()
    return 160 - 28, 120 - 38, 56, 76


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=20000)
    parser.add_argument("--marks", default="1000,10000,20000")
    parser.add_argument("--no-rrd", action="store_true", help="without the recording")
    args = parser.parse_args()
    marks = sorted(int(m) for m in args.marks.split(",") if int(m) <= args.frames)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        box = write_clip(tmp / "long.avi", args.frames)
        print(f"wrote a {args.frames}-frame 320x240 clip in {time.perf_counter() - t0:.0f} s")
        from click.testing import CliRunner
        from trackcli.cli import cli

        res = CliRunner().invoke(cli, ["-q", "draw", str(tmp / "long.avi"), "--box", ",".join(map(str, box)),
                                       "-o", str(tmp / "t.yaml")])
        assert res.exit_code == 0, res.output
        seen: dict[int, float] = {}
        count = 0

        class Bar:
            def __enter__(self):
                return self

            def __exit__(self, *a):
                return False

            def update(self, n: int) -> None:
                nonlocal count
                count += n
                if count in marks:
                    seen[count] = rss_mb()

        t0 = time.perf_counter()
        summary = clips.track_clip(tmp / "long.avi", settings=load_settings(), outdir=tmp / "out",
                                   template=tmp / "t.yaml", progress=lambda label, n: Bar(), rrd=not args.no_rrd)
        wall = time.perf_counter() - t0
        rrd = Path(summary.rrd).stat().st_size if summary.rrd else 0
        print(f"tracked {summary.frames} frames in {wall:.0f} s ({summary.frames / wall:.0f} frames/s), "
              f"{summary.frames_lost} lost; load average {os.getloadavg()[0]:.2f}")
        prev = None
        for m in marks:
            growth = "" if prev is None else f"  {(seen[m] - seen[prev]) * 1024 / (m - prev):.2f} KB/frame since {prev}"
            print(f"RSS at frame {m:>6}: {seen[m]:.1f} MB{growth}")
            prev = m
        print(f"recording: {rrd / 1e6:.1f} MB, {rrd / 1024 / max(summary.frames, 1):.1f} KB/frame")


if __name__ == "__main__":
    main()
