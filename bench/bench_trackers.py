"""Speed of the Kalman contour tracker, CONDENSATION and ``learn`` on the sample training clip.

Trackers are timed alone: the frames of ``sample_data/train.mp4`` (480 x 360, 260 frames) are
decoded into a list first, and the frame loop of :mod:`trackcli.trackers.base` is run over that
list with nothing written or recorded.  The same frames resized to 640 x 480 (with the
template scaled to match) give the cost at VGA size.  Settings are the defaults
(``configs/default.yaml``): 24 normals, similarity shape-space, hand-set dynamics;
CONDENSATION at its default sample-set size (1500 samples on the first frame, falling to 500
over 4 frames).  The per-frame work a tracker does for recordings (gate ends, features; the
top particle contours and histogram for CONDENSATION) is part of the generator and so is
timed; for CONDENSATION a second row turns the particle contours off.

The template is made as ``trackcli draw --box`` makes it: GrabCut inside the true box of
frame 0 grown by 10 % of its size on each side, and a 12-control-point quadratic spline
fitted to the outline.  The mean centroid error against the truth is printed beside each
speed as a check that the tracker tracks.

``learn`` is timed end to end through the command (decode, track, write CSV and recording,
fit), with two cycles, with and without recordings; the per-cycle and per-clip seconds
come from its ``--json`` report.

Everything runs on one core (BLAS and OpenCV threads set to 1).

Usage::

    python bench/bench_trackers.py [--repeat 3] [--skip-learn]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from trackcli.run import drawing  # noqa: E402
from trackcli.segment import grabcut, masks  # noqa: E402
from trackcli.settings import load_settings  # noqa: E402
from trackcli.sample_data import load_truth  # noqa: E402
from trackcli.shapes.outline import build_space  # noqa: E402
from trackcli.dynamics.handset import handset_dynamics  # noqa: E402
from trackcli.trackers.condensation_tracker import track_condensation  # noqa: E402
from trackcli.trackers.kalman_tracker import track_kalman  # noqa: E402
from trackcli.io.video import open_video  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
CLIP = REPO / "sample_data" / "train.mp4"
TRUTH = REPO / "sample_data" / "train.truth.csv"
MARGIN = 0.1
VGA = (640, 480)


def decode(path: Path) -> tuple[list[SimpleNamespace], float, float]:
    """All frames of ``path`` as (index, time, image) records; also fps and decode ms/frame."""
    t0 = time.perf_counter()
    with open_video(path) as video:
        frames = [SimpleNamespace(index=f.index, time=f.time, image=f.image) for f in video]
        fps = video.fps
    return frames, fps, 1e3 * (time.perf_counter() - t0) / len(frames)


def resized(frames: list[SimpleNamespace], size: tuple[int, int]) -> list[SimpleNamespace]:
    return [SimpleNamespace(index=f.index, time=f.time, image=cv2.resize(f.image, size, interpolation=cv2.INTER_LINEAR))
            for f in frames]


def box_template(image: np.ndarray, truth):
    """The template ``draw --box`` makes from the true box of frame 0 grown by MARGIN."""
    x, y, w, h = truth.bbox_x[0], truth.bbox_y[0], truth.bbox_w[0], truth.bbox_h[0]
    box = (x - MARGIN * w, y - MARGIN * h, (1 + 2 * MARGIN) * w, (1 + 2 * MARGIN) * h)
    outline = masks.mask_outline(grabcut.segment_box(image, box))
    size = (image.shape[1], image.shape[0])
    return drawing.fit_template(outline, 12, frame_size=size, source="bench box")


def scaled_template(template, factor: float, size: tuple[int, int]):
    """The template in an image scaled by ``factor`` (pixel centres at integer coordinates)."""
    cp = (template.control_points + 0.5) * factor - 0.5
    return dataclasses.replace(template, control_points=cp, frame_size=size)


def time_tracker(make, frames, truth_xy: np.ndarray, repeat: int) -> tuple[float, float, float]:
    """Median and best frames/s over ``repeat`` runs, and the mean centroid error (px)."""
    rates, error = [], float("nan")
    for _ in range(repeat):
        t0 = time.perf_counter()
        results = list(make(frames))
        rates.append(len(frames) / (time.perf_counter() - t0))
        centres = np.array([r.centroid for r in results])
        error = float(np.mean(np.hypot(*(centres - truth_xy).T)))
    return statistics.median(rates), max(rates), error


def bench_trackers(repeat: int) -> None:
    settings = load_settings()
    truth = load_truth(TRUTH).select(0)
    frames, fps, decode_ms = decode(CLIP)
    tau = 1.0 / fps
    template = box_template(frames[0].image, truth)
    h, w = frames[0].image.shape[:2]
    factor = VGA[0] / w
    cases = [(f"{w}x{h}", frames, template, np.column_stack([truth.cx, truth.cy]))]
    if abs(VGA[1] / h - factor) > 1e-9:
        raise SystemExit(f"the clip is {w}x{h}; scaling it to {VGA} would change its aspect ratio")
    vga_frames = resized(frames, VGA)
    cases.append((f"{VGA[0]}x{VGA[1]}", vga_frames, scaled_template(template, factor, VGA),
                  (np.column_stack([truth.cx, truth.cy]) + 0.5) * factor - 0.5))

    no_display = dataclasses.replace(settings.condensation, display_particles=0)
    print(f"clip {CLIP.name}: {len(frames)} frames {w}x{h} at {fps:g} frames/s; decode {decode_ms:.2f} ms/frame; "
          f"{settings.measurement.n_normals} normals, {settings.shape_space} shape-space, {repeat} runs each")
    print()
    header = f"{'tracker':<44} {'frames':>9} {'fps (median)':>13} {'fps (best)':>11} {'ms/frame':>9} {'mean err px':>12}"
    print(header)
    print("-" * len(header))
    for label, fr, tmpl, truth_xy in cases:
        space = build_space(tmpl, settings.shape_space)
        dyn = handset_dynamics(space, settings.dynamics, tau)

        def kalman(f, space=space, dyn=dyn):
            return track_kalman(f, space, dyn, settings.measurement, settings.kalman)

        def condensation(f, space=space, dyn=dyn, cs=settings.condensation):
            return track_condensation(f, space, dyn, settings.measurement, cs, np.random.default_rng(0))

        def condensation_bare(f, space=space, dyn=dyn):
            return track_condensation(f, space, dyn, settings.measurement, no_display, np.random.default_rng(0))

        rows = [("Kalman", kalman),
                (f"CONDENSATION N={settings.condensation.particles}", condensation),
                (f"CONDENSATION N={settings.condensation.particles}, no particle contours", condensation_bare)]
        for name, make in rows:
            median, best, err = time_tracker(make, fr, truth_xy, repeat)
            print(f"{name:<44} {label:>9} {median:13.0f} {best:11.0f} {1e3 / median:9.2f} {err:12.2f}")


def bench_learn() -> None:
    from click.testing import CliRunner

    from trackcli.cli import cli

    truth = load_truth(TRUTH).select(0)
    x, y, w, h = truth.bbox_x[0], truth.bbox_y[0], truth.bbox_w[0], truth.bbox_h[0]
    box = f"{x - MARGIN * w:.1f},{y - MARGIN * h:.1f},{(1 + 2 * MARGIN) * w:.1f},{(1 + 2 * MARGIN) * h:.1f}"
    runner = CliRunner()
    print()
    header = f"{'learn, 2 cycles':<24} {'command s':>10} {'cycle 1 s':>10} {'cycle 2 s':>10} {'clip/cycle s':>13} {'fit s':>7}"
    print(header)
    print("-" * len(header))
    with tempfile.TemporaryDirectory() as tmp:
        tdir = Path(tmp)
        result = runner.invoke(cli, ["draw", str(CLIP), "--box", box, "-o", str(tdir / "head.yaml")])
        if result.exit_code:
            raise SystemExit(result.output)
        for label, extra in (("with recordings", []), ("--no-rrd", ["--no-rrd"])):
            out = tdir / label.strip("-").replace(" ", "_")
            t0 = time.perf_counter()
            result = runner.invoke(cli, ["learn", "--template", str(tdir / "head.yaml"), str(CLIP), "-o",
                                         str(out / "model.yaml"), "--cycles", "2", "--json", *extra])
            wall = time.perf_counter() - t0
            if result.exit_code:
                raise SystemExit(result.output)
            report = json.loads(result.stdout)
            cycles = [c["seconds"] for c in report["cycles"]]
            clips = [c["clips"][0]["seconds"] for c in report["cycles"]]
            fit = statistics.mean(c - k for c, k in zip(cycles, clips))
            print(f"{label:<24} {wall:10.2f} {cycles[0]:10.2f} {cycles[1]:10.2f} {statistics.mean(clips):13.2f} "
                  f"{fit:7.3f}")
    print("(cycle = track the clip + fit; clip/cycle = decode, track, CSV and recording of one clip in one cycle;\n"
          " with recordings, cycle 1 also pays the one-off start of the first recording stream, about 0.9 s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per tracker (median and best are printed)")
    parser.add_argument("--skip-learn", action="store_true", help="only the trackers")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    bench_trackers(max(1, args.repeat))
    if not args.skip_learn:
        bench_learn()


if __name__ == "__main__":
    main()
