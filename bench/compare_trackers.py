"""CONDENSATION, Kalman and mode-based multiple hypotheses side by side, on clips with ground truth.

Every tracker starts as a new user starts it (``draw --box`` from the frame-0 box of the truth,
then ``track --template``; :func:`quality.draw_template`, :func:`quality.track_and_score`) and
is scored as :mod:`quality` scores it: precision at 20 px (P@20), success AUC and the frames
the tracker itself called lost.  Its own frames per second (decoding excluded) come from the
command's JSON summary.  The configurations:

- ``condensation``: the defaults (N = 500 samples after a start at 1500);
- ``cond N=KS``: CONDENSATION at the sample count of ``mht``, N = K·S from start to end
  (matched compute in the sense of 004 §5.1: as many hypotheses per frame);
- ``kalman``: the Kalman contour tracker;
- ``mht KxS``: ``mht.modes`` = K modes, ``mht.samples`` = S seeds per mode (defaults 3 × 10);
- ``mht 1x1``: one mode, one seed: an iterated Kalman filter (``mht.iterations`` Gauss–Newton
  steps per frame instead of Kalman's one), which separates what the iterations bring from
  what the several modes bring;
- ``coupled``: only when ``trackcli track`` offers ``--tracker coupled`` and a structure
  template is given for a clip (``--structure CLIP=TEMPLATE``), tracked from that template.

Clips: the shipped ``sample_data/*.mp4`` with their truth, the sample clips regenerated
with ``trackcli sample-data --seed S`` for each of ``--seeds`` (:func:`quality.synthetic_clips`)
and every folder of ``--footage`` with ``img/`` and ``groundtruth_rect.txt``
(:func:`quality.footage_clips`; default ``../shared/footage`` beside the repository).

Usage::

    python bench/compare_trackers.py [--seeds 1,2] [--footage DIR] [--only NAME ...]
        [--modes K] [--samples S] [--structure CLIP=TEMPLATE ...] [--json FILE]
"""

from __future__ import annotations

import argparse
import atexit
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import quality  # noqa: E402
from quality import Clip, draw_template, footage_clips, synthetic_clips, track_and_score  # noqa: E402

from trackcli.run.evaluate import load_truth  # noqa: E402

#: the object each shipped sample clip is scored on (the walker of three_heads, as in quality.py)
SAMPLE_OBJECTS = {"train": 0, "test": 0, "three_heads": 2}


def sample_clips(folder: Path) -> list[Clip]:
    """The shipped sample clips that have a truth CSV."""
    clips = []
    for name, obj in SAMPLE_OBJECTS.items():
        path, truth = folder / f"{name}.mp4", folder / f"{name}.truth.csv"
        if path.is_file() and truth.is_file():
            x, y, w, h = (float(v) for v in load_truth(truth, object_id=obj).box[0])
            clips.append(Clip(f"{name}", "synthetic", path, truth, (x, y, w, h), obj))
    return clips


def coupled_available() -> bool:
    """Whether this trackcli offers ``--tracker coupled``."""
    r = subprocess.run([sys.executable, "-c", "from trackcli.trackers import TRACKERS; print(' '.join(TRACKERS))"],
                       capture_output=True, text=True, cwd=quality.REPO)
    return "coupled" in r.stdout.split()


def configurations(k: int, s: int, work: Path) -> list[tuple[str, list[str]]]:
    """``(label, track options)`` of every configuration compared."""
    matched = work / "condensation-matched.yaml"
    matched.write_text(f"condensation:\n  particles: {k * s}\n  initial_particles: {k * s}\n", encoding="utf-8")
    mht = work / "mht.yaml"
    mht.write_text(f"mht:\n  modes: {k}\n  samples: {s}\n", encoding="utf-8")
    single = work / "mht-single.yaml"
    single.write_text("mht:\n  modes: 1\n  samples: 1\n", encoding="utf-8")
    return [
        ("condensation", ["--tracker", "condensation"]),
        (f"cond N={k * s}", ["--tracker", "condensation", "-c", str(matched)]),
        ("kalman", ["--tracker", "kalman"]),
        (f"mht {k}x{s}", ["--tracker", "mht", "-c", str(mht)]),
        ("mht 1x1", ["--tracker", "mht", "-c", str(single)]),
    ]


def _fmt(v, digits=2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{digits}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="1,2", help="sample-data seeds to regenerate (comma separated; '' for none)")
    ap.add_argument("--footage", type=Path, default=quality.DEFAULT_FOOTAGE)
    ap.add_argument("--cache", type=Path, default=quality.DEFAULT_CACHE)
    ap.add_argument("--only", nargs="+", action="extend", help="clip names (prefix match); may be repeated")
    ap.add_argument("--modes", type=int, default=3, help="mht modes K")
    ap.add_argument("--samples", type=int, default=10, help="mht seeds per mode S (CONDENSATION matched: N = K*S)")
    ap.add_argument("--structure", nargs="*", default=[], metavar="CLIP=TEMPLATE",
                    help="structure template of a clip, for --tracker coupled when available")
    ap.add_argument("--json", type=Path, help="write all results here")
    ap.add_argument("--keep", type=Path, help="keep templates and tracks in this folder")
    args = ap.parse_args()

    seeds = [int(v) for v in args.seeds.split(",") if v.strip()]
    args.cache.mkdir(parents=True, exist_ok=True)
    clips = sample_clips(quality.REPO / "sample_data") + synthetic_clips(seeds, args.cache) + footage_clips(args.footage)
    if args.only:
        clips = [c for c in clips if any(c.name.startswith(o) for o in args.only)]
    work = args.keep or Path(tempfile.mkdtemp(prefix="compare-"))
    work.mkdir(parents=True, exist_ok=True)
    if not args.keep:  # the templates and tracks go with the process, however it ends
        atexit.register(shutil.rmtree, work, True)
    configs = configurations(args.modes, args.samples, work)
    structures = {clip: Path(t).resolve() for clip, t in (item.split("=", 1) for item in args.structure)}
    if structures and coupled_available():
        configs.append(("coupled", ["--tracker", "coupled"]))
    elif structures:
        print("note: --structure given but this trackcli has no --tracker coupled; skipped", file=sys.stderr)

    width = 22
    print(f"{'clip':<{width}}{'frames':>7}  " + "".join(f"{label:>24}" for label, _ in configs))
    print(f"{'':<{width}}{'':>7}  " + "".join(f"{'P@20  AUC lost   fps':>24}" for _ in configs))
    results: dict[str, dict[str, dict]] = {}
    for clip in clips:
        row: dict[str, dict] = {}
        template, error = draw_template(clip, work)
        frames = None
        for label, options in configs:
            (work / label).mkdir(exist_ok=True)
            if label == "coupled":
                if clip.name not in structures:
                    row[label] = {"error": "no structure template"}
                    continue
                res, _ = track_and_score(clip, structures[clip.name], work / label, options)
            elif error:
                res = {"error": error}
            else:
                res, _ = track_and_score(clip, template, work / label, options)
            row[label] = res
            frames = frames or res.get("frames")
        results[clip.name] = row
        cells = []
        for label, _ in configs:
            res = row[label]
            if "error" in res:
                cells.append(f"{'-':>24}")
            else:
                cells.append(f"{_fmt(res['p20']):>7}{_fmt(res['auc']):>5}{res['lost']:>5}{_fmt(res.get('fps'), 0):>7}")
        print(f"{clip.name:<{width}}{frames or 0:>7}  " + "".join(cells), flush=True)
        for label, _ in configs:
            if "error" in row[label] and label != "coupled":
                print(f"    {label}: {row[label]['error']}", file=sys.stderr)
    for kind in ("synthetic", "real"):
        names = [c.name for c in clips if c.kind == kind]
        if not names:
            continue
        cells = []
        for label, _ in configs:
            ok = [results[n][label] for n in names if "error" not in results[n][label]]
            if not ok:
                cells.append(f"{'-':>24}")
                continue
            p20, auc = np.mean([r["p20"] for r in ok]), np.mean([r["auc"] for r in ok])
            lost = sum(r["lost"] for r in ok)
            fps = [r["fps"] for r in ok if r.get("fps")]
            cells.append(f"{_fmt(p20):>7}{_fmt(auc):>5}{lost:>5}{_fmt(float(np.median(fps)) if fps else None, 0):>7}")
        print(f"{'mean ' + kind:<{width}}{'':>7}  " + "".join(cells))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
