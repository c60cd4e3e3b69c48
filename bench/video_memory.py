"""Memory and speed of streaming a long clip through ``trackcli.io.video.open_video``.

Writes a synthetic clip (default 10,000 frames of 320x240, MJPG in an AVI) to a temporary
folder, streams it, and prints the peak resident memory (``getrusage`` maxrss and VmRSS
sampled from ``/proc/self/status``) and the decode rate.  Streaming should keep memory flat:
the target is a peak RSS under 300 MB.

Usage::

    python bench/video_memory.py [--frames 10000] [--step 1]
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from trackcli.io.video import open_video

TARGET_MB = 300.0


def vm_rss_mb() -> float:
    """Current resident set size in MB from /proc/self/status (nan where unavailable)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def max_rss_mb() -> float:
    """Peak resident set size of this process so far, in MB (Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def write_clip(path: Path, n_frames: int, width: int = 320, height: int = 240) -> None:
    """A textured background with a moving disc and the frame number, as MJPG."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (width, height))
    if not writer.isOpened():
        sys.exit("OpenCV cannot write MJPG .avi on this machine")
    rng = np.random.default_rng(0)
    background = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    background = cv2.GaussianBlur(background, (0, 0), 3)
    for i in range(n_frames):
        frame = background.copy()
        x = int(width / 2 + 0.4 * width * np.sin(i / 25.0))
        y = int(height / 2 + 0.3 * height * np.cos(i / 40.0))
        cv2.circle(frame, (x, y), 20, (40, 200, 240), -1)
        cv2.putText(frame, str(i), (8, 30), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
        writer.write(frame)
    writer.release()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000, help="clip length")
    parser.add_argument("--step", type=int, default=1, help="read every step-th frame")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.avi"
        t0 = time.perf_counter()
        write_clip(path, args.frames)
        t_write = time.perf_counter() - t0
        print(f"wrote {args.frames} frames 320x240 MJPG, {path.stat().st_size / 1e6:.1f} MB, "
              f"in {t_write:.1f} s")
        print(f"before reading: VmRSS {vm_rss_mb():.1f} MB, maxrss {max_rss_mb():.1f} MB")

        video = open_video(path, step=args.step)
        rss_peak, rss_first, n, checksum = 0.0, float("nan"), 0, 0
        t0 = time.perf_counter()
        for frame in video:
            checksum += int(frame.image[0, 0, 0])  # touch the pixels
            n += 1
            if n % 50 == 1:
                rss = vm_rss_mb()
                rss_peak = max(rss_peak, rss)
                if n == 1:
                    rss_first = rss
        t_read = time.perf_counter() - t0
        rss_end = vm_rss_mb()
        rss_peak = max(rss_peak, rss_end)
        video.close()

        if n != len(video):
            sys.exit(f"read {n} frames, expected {len(video)}")
        maxrss = max_rss_mb()
        print(f"read {n} frames (step {args.step}) in {t_read:.2f} s: "
              f"{n / t_read:.0f} frames/s delivered, "
              f"{video.indices.stop / t_read:.0f} clip frames/s traversed")
        print(f"VmRSS: first frame {rss_first:.1f} MB, peak sampled {rss_peak:.1f} MB, "
              f"last frame {rss_end:.1f} MB")
        print(f"maxrss (whole process, including writing): {maxrss:.1f} MB")
        verdict = "OK" if maxrss < TARGET_MB else "OVER TARGET"
        print(f"target peak RSS < {TARGET_MB:.0f} MB: {verdict}")


if __name__ == "__main__":
    main()
