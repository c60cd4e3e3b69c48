"""Whole ``trackcli track`` runs, timed as a user runs them: decode, tracking, CSV and ``.rrd``.

For each clip the template is drawn from the frame-0 box of the ground truth and the command

    trackcli track --template T.yaml CLIP -o OUT --json [--no-rrd]

is run ``--repeat`` times with the default settings.  Printed per clip: frames, the median
wall time of the command, frames per second of the whole run (frames / wall time, process
start-up included), the start-up (the median wall time of the same command on the clip's
first two frames: imports, template, opening the recording, the first call of the compiled
kernel, writing the outputs), frames per second without it ((frames - 2) / (wall -
start-up): the throughput a long clip approaches), and the tracker's own frames per second
(from the ``--json`` summary: tracking alone, without decoding and recording).

Clips: the sample cluttered clip at 480 x 360 and the same clip shrunk to 320 x 240 (the size
the speed guard is stated for), a longer take of that clip (``--long`` frames, generated with
``trackcli sample-data --frames``, 320 x 240), plus ``pres_debate.mp4`` (1280 x 720) from the
footage folder when present.  Run with ``OMP_NUM_THREADS=1`` etc. to hold numpy and OpenCV to
one core, or with ``--one-core`` to hold each command to a single CPU with ``--threads 1`` (the
speed guard: a default run on a 320 x 240 clip at 100 frames/s or more on one core).

With ``--wide`` it times instead the speed guard at 854 x 480: the default ``track`` (CONDENSATION,
the refined outline, the AV1 recording and the CSV) on every sequence of a DAVIS-layout folder
(``NAME/img/*.jpg`` with ``NAME/masks/*.png``; by default ``davis_train`` of the footage folder,
``--davis`` names others), its template drawn from the first frame's mask as a user does
(``trackcli draw SEQ/img --mask SEQ/masks/00000.png``); when there is none, on a generated clip
(the sample cluttered clip, 160 frames, stretched to 854 x 480, as a folder of JPEG frames as
DAVIS gives them).  Per sequence and mean: frames, the wall time of the command, its start-up
(the same command on the first two frames), frames per second net of start-up, the tracker's own
(``tracker_fps`` of ``--json``), and the processor time of the command net of start-up per
frame, every thread counted (the figure that does not depend on what else the machine runs;
``--repeat`` runs, medians).  The load average is printed before and after: on a shared machine
wall times mean little unless it is below the number of cores.

Usage::

    python bench/bench_run.py [--repeat 3] [--no-rrd] [--footage DIR] [--long 1600] [--threads N] [--one-core]
    python bench/bench_run.py --wide [--davis DIR ...] [--only a,b] [--repeat 3] [--no-rrd]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from trackcli.run.evaluate import load_truth  # noqa: E402


#: with ``--one-core``, the CPU every command is held to
ONE_CPU: int | None = None


def _pin() -> None:
    if ONE_CPU is not None:
        os.sched_setaffinity(0, {ONE_CPU})


def _cli(*args: str) -> tuple[float, subprocess.CompletedProcess]:
    wall, _, r = _timed_cli(*args)
    return wall, r


def _timed_cli(*args: str) -> tuple[float, float, subprocess.CompletedProcess]:
    """Run ``trackcli -q ARGS`` from this checkout: (wall seconds, processor seconds of every thread, result)."""
    env = dict(os.environ, CI="true", PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "trackcli.cli", "-q", *args], capture_output=True, text=True, env=env,
                       cwd=REPO, preexec_fn=_pin)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, r


def shrink(src: Path, dst: Path, size: tuple[int, int]) -> Path:
    cap = cv2.VideoCapture(str(src))
    fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
    out = cv2.VideoWriter(str(dst), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        out.write(cv2.resize(frame, size, interpolation=cv2.INTER_AREA))
    out.release()
    cap.release()
    return dst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-rrd", action="store_true")
    ap.add_argument("--footage", type=Path, default=REPO.parent / "shared" / "footage")
    ap.add_argument("--long", type=int, default=1600, help="frames of the long 320x240 clip (0: none)")
    ap.add_argument("--threads", type=int, default=None, help="track --threads (default: the setting's default)")
    ap.add_argument("--one-core", action="store_true",
                    help="hold every command to one CPU (and track to --threads 1): the speed guard's setting")
    ap.add_argument("--wide", action="store_true",
                    help="the speed guard at 854x480: DAVIS-layout sequences (or a generated clip), net of start-up")
    ap.add_argument("--davis", type=Path, nargs="*", default=None,
                    help="with --wide: DAVIS-layout folders (default: davis_train of --footage)")
    ap.add_argument("--only", default="", help="with --wide: only these sequences (comma-separated)")
    args = ap.parse_args()
    if args.one_core:
        global ONE_CPU
        ONE_CPU = min(os.sched_getaffinity(0))
        args.threads = 1
    with tempfile.TemporaryDirectory(prefix="bench-run-") as tmp:  # its clips and outputs: 340 MB
        if args.wide:
            _wide(args, Path(tmp))
        else:
            _bench(args, Path(tmp))


def _sequences(folders: list[Path]) -> list[tuple[str, Path, Path]]:
    """(name, frames folder, first mask) of every ``NAME/img`` + ``NAME/masks`` sequence of ``folders``."""
    out = []
    for folder in folders:
        if not folder.is_dir():
            continue
        for d in sorted(p for p in folder.iterdir() if (p / "img").is_dir() and (p / "masks").is_dir()):
            masks = sorted((d / "masks").glob("*.png"))
            if masks:
                out.append((d.name, d / "img", masks[0]))
    return out


def _generated(work: Path) -> tuple[str, Path, list[str]]:
    """The sample cluttered clip stretched to 854x480, as a folder of JPEG frames, and how to draw its template."""
    _, r = _cli("sample-data", str(work / "gen"), "--clip", "test")
    if r.returncode:
        sys.exit(f"sample-data failed: {r.stderr.strip()}")
    src = work / "gen" / "test.mp4"
    frames = work / "wide" / "img"
    frames.mkdir(parents=True)
    cap = cv2.VideoCapture(str(src))
    w0, h0 = cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)
    k = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        cv2.imwrite(str(frames / f"{k:05d}.jpg"), cv2.resize(frame, (854, 480), interpolation=cv2.INTER_LINEAR),
                    [cv2.IMWRITE_JPEG_QUALITY, 90])
        k += 1
    cap.release()
    box = load_truth(work / "gen" / "test.truth.csv").box[0] * np.array([854 / w0, 480 / h0, 854 / w0, 480 / h0])
    return "generated 854x480", frames, ["--box", ",".join(f"{v:.1f}" for v in box)]


def _wide(args: argparse.Namespace, work: Path) -> None:
    folders = args.davis if args.davis is not None else [args.footage / "davis_train"]
    seqs = [(name, img, ["--mask", str(mask)]) for name, img, mask in _sequences(folders)]
    if args.only:
        keep = set(args.only.split(","))
        seqs = [s for s in seqs if s[0] in keep]
    if not seqs:
        print(f"no DAVIS-layout sequences in {', '.join(map(str, folders))}: a generated clip instead")
        seqs = [_generated(work)]
    extra = ["--no-rrd"] if args.no_rrd else []
    if args.threads is not None:
        extra += ["--threads", str(args.threads)]
    cores = f"held to CPU {ONE_CPU}" if ONE_CPU is not None else f"{os.cpu_count()} cores"
    print(f"load average {os.getloadavg()[0]:.2f}; {cores}; the default track at 854x480"
          f"{' without the recording' if args.no_rrd else ''}; medians of {args.repeat}")
    print(f"{'sequence':<20}{'frames':>7}{'wall s':>8}{'start-up s':>11}{'fps w/o start':>15}{'tracker fps':>13}"
          f"{'cpu ms/frame':>14}")
    rows = []
    for name, img, how in seqs:
        tmpl = work / f"{name}.yaml"
        _, r = _cli("draw", str(img), *how, "-o", str(tmpl))
        if r.returncode:
            print(f"{name}: draw failed: {r.stderr.strip()}")
            continue
        walls, cpus, starts, start_cpus, tracker_fps, frames = [], [], [], [], [], 0
        for i in range(args.repeat):
            wall, cpu, r = _timed_cli("track", "--template", str(tmpl), str(img), "-o", str(work / "short"),
                                      "--end", "2", *extra)
            if r.returncode == 0:
                starts.append(wall)
                start_cpus.append(cpu)
            wall, cpu, r = _timed_cli("track", "--template", str(tmpl), str(img), "-o", str(work / "out"), "--json",
                                      *extra)
            if r.returncode:
                print(f"{name}: track failed: {r.stderr.strip()}")
                break
            summary = json.loads(r.stdout.strip().splitlines()[-1])
            frames = summary["frames"]
            walls.append(wall)
            cpus.append(cpu)
            tracker_fps.append(summary["tracker_fps"])
        if not walls or not starts:
            continue
        wall, startup = statistics.median(walls), statistics.median(starts)
        net = (frames - 2) / max(wall - startup, 1e-9)
        cpu = 1000 * (statistics.median(cpus) - statistics.median(start_cpus)) / max(frames - 2, 1)
        rows.append((net, statistics.median(tracker_fps), cpu))
        print(f"{name:<20}{frames:>7}{wall:>8.2f}{startup:>11.2f}{net:>15.1f}{statistics.median(tracker_fps):>13.1f}"
              f"{cpu:>14.1f}", flush=True)
    if len(rows) > 1:
        m = np.mean(rows, axis=0)
        print(f"{'mean (' + str(len(rows)) + ')':<20}{'':>7}{'':>8}{'':>11}{m[0]:>15.1f}{m[1]:>13.1f}{m[2]:>14.1f}")
        # a short clip whose start-up run happened to be slow gives a wild net rate: the median holds
        md = np.median(rows, axis=0)
        print(f"{'median':<20}{'':>7}{'':>8}{'':>11}{md[0]:>15.1f}{md[1]:>13.1f}{md[2]:>14.1f}")
    print(f"load average {os.getloadavg()[0]:.2f}")


def _bench(args: argparse.Namespace, work: Path) -> None:
    sample = REPO / "sample_data"
    box = load_truth(sample / "test.truth.csv").box[0]
    clips = [("test 480x360", sample / "test.mp4", box)]
    small = shrink(sample / "test.mp4", work / "test_320.avi", (320, 240))
    clips.insert(0, ("test 320x240", small, box * (320 / 480)))
    if args.long:
        _, r = _cli("sample-data", str(work / "long"), "--clip", "test", "--frames", str(args.long))
        if r.returncode:
            sys.exit(f"sample-data failed: {r.stderr.strip()}")
        long_box = load_truth(work / "long" / "test.truth.csv").box[0] * (320 / 480)
        clips.insert(1, ("test 320x240 long", shrink(work / "long" / "test.mp4", work / "long_320.avi", (320, 240)),
                         long_box))
    debate = args.footage / "pres_debate.mp4"
    if debate.is_file():
        clips.append(("pres_debate 1280x720", debate, np.array([320.9, 175.2, 103.5, 129.1])))
    cores = f"held to CPU {ONE_CPU}" if ONE_CPU is not None else f"{os.cpu_count()} cores"
    print(f"load average {os.getloadavg()[0]:.2f}; {cores}; threads {args.threads or 'default'}")
    print(f"{'clip':<22}{'frames':>7}{'wall s':>8}{'run fps':>9}{'start-up s':>11}{'fps w/o start':>15}"
          f"{'tracker fps':>13}")
    for name, clip, b in clips:
        tmpl = work / f"{clip.stem}.yaml"
        _, r = _cli("draw", str(clip), "--box", ",".join(f"{v:.1f}" for v in b), "-o", str(tmpl))
        if r.returncode:
            print(f"{name}: draw failed: {r.stderr.strip()}")
            continue
        walls, tracker_fps, frames, starts = [], [], 0, []
        extra = ["--no-rrd"] if args.no_rrd else []
        if args.threads is not None:
            extra += ["--threads", str(args.threads)]
        for i in range(args.repeat):
            wall, r = _cli("track", "--template", str(tmpl), str(clip), "-o", str(work / f"short{i}"), "--end", "2",
                           *extra)
            if r.returncode == 0:
                starts.append(wall)
            wall, r = _cli("track", "--template", str(tmpl), str(clip), "-o", str(work / f"out{i}"), "--json", *extra)
            if r.returncode:
                print(f"{name}: track failed: {r.stderr.strip()}")
                break
            summary = json.loads(r.stdout.strip().splitlines()[-1])
            frames = summary["frames"]
            walls.append(wall)
            tracker_fps.append(summary["tracker_fps"])
        if not walls:
            continue
        wall = statistics.median(walls)
        startup = statistics.median(starts) if starts else float("nan")
        print(f"{name:<22}{frames:>7}{wall:>8.2f}{frames / wall:>9.1f}{startup:>11.2f}"
              f"{(frames - 2) / max(wall - startup, 1e-9):>15.1f}{statistics.median(tracker_fps):>13.1f}")


if __name__ == "__main__":
    main()
