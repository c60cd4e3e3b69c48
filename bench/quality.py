"""Tracking quality on a fixed dev set: the command line, defaults, templates from the frame-0 box.

For every clip of the dev set this script does what a new user does::

    trackcli draw CLIP --box X,Y,W,H -o T.yaml          # the frame-0 box of the ground truth
    trackcli track --template T.yaml CLIP -o OUT --json  # default settings, CONDENSATION

and scores the track CSV against the ground truth with :mod:`trackcli.run.evaluate`: precision at
20 px (OTB convention: the estimate's box centre within 20 px of the truth's; centroids for the
synthetic clips, whose truth has them), precision at 10 px, success AUC (mean over IoU
thresholds 0, 0.05, ..., 1 of the fraction of frames with IoU above the threshold) and the
frames the tracker itself reported lost.  The truthfulness of that verdict is shown as two
counts: frames flagged lost among frames whose centre error is > 20 px ("flag|bad") and among
frames whose error is < 5 px ("flag|good"; should be near 0); under the means, the same in the
object's size, as ``bench/davis.py`` counts them: flagged among frames more than twice the size
(the square root of the true box's area) off, and among frames within a tenth of it.

The dev set:

- the synthetic sample clips regenerated with ``trackcli sample-data --seed S`` for each seed
  of ``--seeds`` (the cluttered ``test`` clip, the walker of ``three_heads``), cached in
  ``--cache``;
- every folder of ``--footage`` (default ``../shared/footage`` beside the repository, when
  present) holding ``img/`` frames and ``groundtruth_rect.txt`` (OTB's layout), or its frames
  and ``groundtruth.txt`` (VOT's; polygons are scored by the rectangle around them).

With ``--grey`` every clip is replaced by a grey copy of it (one-channel JPEG frames, as many
public benchmark sequences are), with ``--scale F`` by a copy at F times its resolution, with
``--every K`` by a copy of every K-th frame (K times faster motion), with ``--start F`` by the
clip from F of its length on, with ``--reverse`` by the clip played backwards from its last
frame (or from F back to its start), with ``--noise S`` by a copy with Gaussian noise of S grey
levels, with ``--jpeg Q`` by a copy stored at JPEG quality Q; the options combine, and
the copies are cached in ``--cache``.  They show how far the defaults hold on footage of the
same kind but not the same make.

With ``--outline`` the template is drawn from the object's true outline on the first frame
instead (``trackcli draw --mask``): the generator's outline for the synthetic clips, the
first mask of ``masks/`` for the DAVIS folders; clips without a true outline are left out.

With ``--peers`` the same clips are tracked by OpenCV's CSRT, KCF and MIL from the same box
(CSRT and KCF need ``opencv-contrib-python-headless``; MIL is in the plain wheel), five times
per clip in a fresh process, the scores averaged (MIL is random).  Peer results do not depend
on trackcli and are cached.

Usage::

    python bench/quality.py [--seeds 1,2,3] [--footage DIR] [--peers] [--only NAME ...]
        [--json FILE] [--grey] [--scale F] [--every K] [--start F] [--reverse] [--noise S] [--jpeg Q]
        [--outline] [--runs K] [--extra "TRACK OPTIONS"] [--keep DIR] [--templates DIR]
        [-- EXTRA TRACK OPTIONS]

``--extra`` (one string, split at spaces, as ``bench/davis.py`` takes it) and everything after
``--`` are passed to ``trackcli track`` (e.g. ``--extra "-c off.yaml"`` or ``-- --particles 1000``).
``--templates DIR`` takes the templates an earlier run left in its ``--keep DIR`` instead of
drawing them again, so that runs that differ only in their track options start from the very
same templates.  ``--runs K`` tracks every clip with seeds 0..K-1 and averages the scores: one run of a particle
filter on one clip is a noisy measurement.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from trackcli.io.truth import TRUTH_FILE_NAMES  # noqa: E402
from trackcli.io.video import IMAGE_SUFFIXES  # noqa: E402
from trackcli.run.evaluate import load_track, load_truth, score_frames, summarise  # noqa: E402

DEFAULT_FOOTAGE = REPO.parent / "shared" / "footage"
DEFAULT_CACHE = REPO / "bench" / ".cache"


@dataclass(frozen=True)
class Clip:
    name: str
    kind: str  # "synthetic" or "real"
    path: Path
    truth: Path
    box: tuple[float, float, float, float]
    object_id: int = 0


def _cli(*args: str, timeout: float = 1800) -> subprocess.CompletedProcess:
    env = dict(os.environ, CI="true")
    return subprocess.run([sys.executable, "-m", "trackcli.cli", "-q", *args], capture_output=True,
                          text=True, env=env, timeout=timeout, cwd=REPO)


def synthetic_clips(seeds: list[int], cache: Path) -> list[Clip]:
    clips = []
    for seed in seeds:
        folder = cache / f"sample-{seed}"
        need = [c for c in ("test", "three_heads") if not (folder / f"{c}.truth.csv").is_file()]
        if need:
            args = ["sample-data", str(folder), "--seed", str(seed)]
            for c in need:
                args += ["--clip", c]
            r = _cli(*args)
            if r.returncode:
                raise SystemExit(f"sample-data --seed {seed} failed: {r.stderr.strip()}")
        for clip, obj in (("test", 0), ("three_heads", 2)):
            truth = folder / f"{clip}.truth.csv"
            gt = load_truth(truth, object_id=obj)
            x, y, w, h = (float(v) for v in gt.box[0])
            clips.append(Clip(f"{clip}@{seed}", "synthetic", folder / f"{clip}.mp4", truth, (x, y, w, h), obj))
    return clips


def footage_clips(footage: Path) -> list[Clip]:
    clips = []
    if not footage.is_dir():
        return clips
    for folder in sorted(p for p in footage.iterdir() if p.is_dir()):
        # OTB's layout (img/, groundtruth_rect.txt) or VOT's (frames and groundtruth.txt together)
        truth = next((folder / n for n in TRUTH_FILE_NAMES if (folder / n).is_file()), None)
        frames = (folder / "img").is_dir() or any(p.suffix.lower() in IMAGE_SUFFIXES for p in folder.iterdir())
        if truth is None or not frames:
            continue
        gt = load_truth(truth)
        x, y, w, h = (float(v) for v in gt.box[0])
        clips.append(Clip(folder.name, "real", folder, truth, (x, y, w, h)))
    return clips


def variant_copy(clip: Clip, cache: Path, *, grey: bool = False, scale: float = 1.0, every: int = 1,
                 reverse: bool = False, start: float = 0.0, noise: float = 0.0, quality: int = 95) -> Clip:
    """The clip changed as footage of the same kind may be, cached under ``cache/variants``:

    - ``grey``: its frames in grey (one-channel JPEGs, as grey benchmark sequences ship);
    - ``scale``: its frames resized by this factor (a lower or higher resolution), the truth
      and the frame-0 box with them;
    - ``every``: every ``every``-th frame only (the object moves that many times farther
      between frames), the truth with them;
    - ``start``: from the first frame with the object in view at or after this share of the
      clip's length (another first frame, another template, the rest of the clip ahead);
    - ``reverse``: played backwards, from the last frame with the object in view (after
      ``start``: from there back to the first frame).  A clip run backwards is a new clip of
      the same kind: another first frame to draw the template on, the motion reversed;
    - ``noise``: Gaussian noise of this standard deviation (grey levels) added to every pixel
      and channel (a dim scene, a small sensor), drawn from a stream seeded by the frame;
    - ``quality``: stored at this JPEG quality instead of 95 (strong compression: blocks,
      ringing and smeared colour, as in streamed or re-encoded footage).

    Frames go into an image folder (JPEG quality 95 unless ``quality``) and the truth beside it: a trackcli truth
    CSV for the synthetic clips (their centroids are scored), a box file for the others (box
    centres are scored)."""
    import cv2

    from trackcli.io.video import open_video

    if not grey and scale == 1.0 and every == 1 and not reverse and start == 0.0 and not noise and quality == 95:
        return clip
    tag = "-".join([*(["grey"] if grey else []), *([f"x{scale:g}"] if scale != 1.0 else []),
                    *([f"noise{noise:g}"] if noise else []), *([f"q{quality}"] if quality != 95 else []),
                    *([f"every{every}"] if every != 1 else []), *([f"from{start:g}"] if start else []),
                    *(["reverse"] if reverse else [])])
    folder = cache / "variants" / tag / clip.name.replace("@", "-")
    done = folder / ".complete"
    truth = load_truth(clip.truth, object_id=clip.object_id)
    # the original frames kept, in the copy's order
    kept = truth.frame[(truth.frame % every == 0)]
    present = dict(zip(truth.frame.tolist(), truth.present.tolist()))
    in_view = [f for f in kept.tolist() if present[f]]
    if not in_view:
        raise SystemExit(f"{clip.name}: the object is never in view")
    first = next((f for f in in_view if f >= start * (int(truth.frame.max()) + 1)), in_view[-1])
    if reverse:  # from `first` (or the last frame in view) back to the first frame
        anchor = first if start else in_view[-1]
        order = [f for f in kept.tolist() if f <= anchor][::-1]
    else:
        order = [f for f in kept.tolist() if f >= first]
    row = {f: i for i, f in enumerate(truth.frame.tolist())}  # the truth's row of each frame
    if not done.is_file():
        (folder / "img").mkdir(parents=True, exist_ok=True)
        position = {f: i for i, f in enumerate(order)}  # each kept frame's place in the copy
        with open_video(clip.path, fps=25.0) as video:  # the rate is not used
            for f in video:
                if f.index not in position:
                    continue
                frame = f.image
                if scale != 1.0:
                    size = (max(1, round(frame.shape[1] * scale)), max(1, round(frame.shape[0] * scale)))
                    frame = cv2.resize(frame, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
                if grey:
                    frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
                if noise:
                    grain = np.random.default_rng(f.index).normal(0.0, noise, frame.shape)
                    frame = np.clip(frame + grain, 0, 255).astype(np.uint8)
                cv2.imwrite(str(folder / "img" / f"{position[f.index]:05d}.jpg"), frame,
                            [cv2.IMWRITE_JPEG_QUALITY, quality])
        idx = [row[k] for k in order]
        rows = zip(range(len(order)), truth.centre[idx] * scale, truth.box[idx] * scale, truth.present[idx])
        if truth.centre_kind == "centroid":  # a trackcli truth CSV: the centroid is scored
            lines = ["frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,visible"]
            lines += [f"{f},0,{c[0]:.4f},{c[1]:.4f},{b[0]:.4f},{b[1]:.4f},{b[2]:.4f},{b[3]:.4f},{int(v)}"
                      for f, c, b, v in rows]
        else:  # a benchmark box file, one line per frame from frame 0: the box centre is scored
            lines = [",".join(f"{x:.3f}" for x in b) if v else "0,0,0,0" for _, _, b, v in rows]
        (folder / TRUTH_NAME[truth.centre_kind]).write_text("\n".join(lines) + "\n")
        done.touch()
    box = tuple(float(v) * scale for v in truth.box[row[order[0]]])
    return Clip(f"{clip.name}-{tag}", clip.kind, folder, folder / TRUTH_NAME[truth.centre_kind], box)


TRUTH_NAME = {"centroid": "truth.csv", "box": "groundtruth_rect.txt"}


def score(csv: Path, clip: Clip) -> dict:
    truth = load_truth(clip.truth, object_id=clip.object_id)
    track = load_track(csv)
    frames = score_frames(track, truth)
    s20 = summarise(frames, threshold=20.0)
    s10 = summarise(frames, threshold=10.0)
    err = frames.centre_error
    lost_flag = _lost_flags(csv, frames.frame)
    bad = err > 20
    good = err < 5
    # the object's size (square root of the true box's area) per scored frame: "off" is more than
    # twice it from the truth, "held" within a tenth of it (DAVIS's flag|off and flag|held)
    at = {int(f): k for k, f in enumerate(truth.frame)}
    box = truth.box[[at[int(f)] for f in frames.frame]]
    size = np.sqrt(np.maximum(box[:, 2] * box[:, 3], 1.0))
    off, held = err > 2 * size, err < 0.1 * size
    return {
        "p20": s20.precision, "p10": s10.precision, "auc": s20.success_auc,
        "err_mean": s20.centre_error_mean, "frames": int(frames.frame.size),
        "lost": int(lost_flag.sum()), "bad": int(bad.sum()), "good": int(good.sum()),
        "lost_bad": int((lost_flag & bad).sum()), "lost_good": int((lost_flag & good).sum()),
        "off": int(off.sum()), "held": int(held.sum()),
        "lost_off": int((lost_flag & off).sum()), "lost_held": int((lost_flag & held).sum()),
    }


def _lost_flags(csv: Path, frames: np.ndarray) -> np.ndarray:
    import csv as csvmod

    with open(csv, newline="") as f:
        rows = list(csvmod.DictReader(f))
    flag = {int(r["frame"]): r.get("lost", "0") in ("1", "True", "true") for r in rows}
    return np.array([flag.get(int(k), True) for k in frames], dtype=bool)


def run_trackcli_seeds(clip: Clip, work: Path, extra: list[str], runs: int,
                      outline: bool = False, templates: Path | None = None) -> tuple[dict, float]:
    """:func:`run_trackcli` with ``--seed 0 .. runs-1``; scores averaged (counts summed)."""
    if runs <= 1:
        return run_trackcli(clip, work, extra, outline, templates)
    results, wall = [], 0.0
    for seed in range(runs):
        res, w = run_trackcli(clip, work, [*extra, "--seed", str(seed)], outline, templates)
        if "error" in res:
            return res, w
        results.append(res)
        wall += w
    return mean_scores(results), wall / runs


def mean_scores(results: list[dict]) -> dict:
    """The scores of several runs of one clip: rates averaged, frame counts summed, and each
    run's P@20."""
    out = {k: float(np.mean([r[k] for r in results])) for k in ("p20", "p10", "auc", "err_mean")}
    out.update({k: int(sum(r[k] for r in results)) for k in ("frames", "lost", "bad", "good", "lost_bad", "lost_good",
                                                            "off", "held", "lost_off", "lost_held")})
    out["p20_runs"] = [r["p20"] for r in results]
    return out


def run_trackcli(clip: Clip, work: Path, extra: list[str], outline: bool = False,
                 templates: Path | None = None) -> tuple[dict, float]:
    """Draw the template from the frame-0 box (or true outline), track with ``extra`` options,
    score: ``(scores, wall s)``.  With ``templates``, a folder where ``NAME.template.yaml`` is
    found (an earlier run's ``--keep``), that template is used instead of drawing one."""
    reuse = templates / f"{clip.name}.template.yaml" if templates is not None else None
    if reuse is not None and reuse.is_file():
        return track_and_score(clip, reuse, work, extra)
    tmpl, error = draw_template(clip, work, outline)
    if error:
        return {"error": error}, 0.0
    return track_and_score(clip, tmpl, work, extra)


def true_mask(clip: Clip) -> np.ndarray | None:
    """The object's true mask on the clip's first frame (uint8, 0/255), or None when the clip
    has none: the generator's outline of a synthetic clip, the first of a DAVIS folder's masks."""
    import cv2

    if clip.kind == "synthetic":
        from trackcli.io.video import open_video
        from trackcli.sample_data import load_outline, true_outline
        from trackcli.sample_data import load_truth as load_sample_truth
        from trackcli.shapes.draw import polygon_mask

        truth = load_sample_truth(clip.truth)
        rows = np.flatnonzero((truth.frame == 0) & (truth.object == clip.object_id))
        if not rows.size:
            return None
        outline = true_outline(truth.row(int(rows[0])), load_outline(clip.truth.with_name(
            clip.truth.name.replace(".truth.csv", ".outline.json"))))
        with open_video(clip.path) as video:
            frame = video.read(0).image
        return polygon_mask(outline, (frame.shape[1], frame.shape[0]))
    masks = sorted((clip.path / "masks").glob("*.png")) if (clip.path / "masks").is_dir() else []
    if not masks:
        return None
    m = cv2.imread(str(masks[0]), cv2.IMREAD_GRAYSCALE)
    return None if m is None else np.where(m > 0, 255, 0).astype(np.uint8)


def draw_template(clip: Clip, work: Path, outline: bool = False) -> tuple[Path, str | None]:
    """``trackcli draw --box`` on frame 0 from the ground truth's box (with ``outline``:
    ``draw --mask`` from the true outline): ``(template, error or None)``."""
    import cv2

    tmpl = work / f"{clip.name}.template.yaml"
    if outline:
        mask = true_mask(clip)
        if mask is None:
            return tmpl, "no true outline"
        mask_png = work / f"{clip.name}.truemask.png"
        cv2.imwrite(str(mask_png), mask)
        how = ["--mask", str(mask_png)]
    else:
        how = ["--box", ",".join(f"{v:.2f}" for v in clip.box)]
    r = _cli("draw", str(clip.path), *how, "-o", str(tmpl), "--preview", str(work / f"{clip.name}.png"))
    if r.returncode:
        return tmpl, "draw: " + r.stderr.strip().splitlines()[-1]
    return tmpl, None


def track_and_score(clip: Clip, template: Path, work: Path, extra: list[str]) -> tuple[dict, float]:
    """``trackcli track --template`` with ``extra`` options, scored against the truth: ``(scores, wall s)``.

    The scores include ``fps``, the tracker's own frames per second (decoding excluded) from
    the command's JSON summary.
    """
    out = work / clip.name
    t0 = time.perf_counter()
    r = _cli("track", "--template", str(template), str(clip.path), "-o", str(out), "--no-rrd", "--json", *extra)
    wall = time.perf_counter() - t0
    if r.returncode:
        return {"error": "track: " + (r.stderr.strip().splitlines() or ["?"])[-1]}, wall
    summary = next((json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")), {})
    csv = Path(summary["csv"]) if summary.get("csv") else (
        sorted(out.glob("*.condensation.csv")) or sorted(out.glob("*.csv")))[0]
    res = score(csv, clip)
    res["fps"] = summary.get("tracker_fps")
    return res, wall


# ---------------------------------------------------------------------------------------------
# OpenCV's trackers


PEERS = ("CSRT", "KCF", "MIL")


def _peer_factory(name: str):
    import cv2

    for where in (cv2, getattr(cv2, "legacy", None)):
        f = getattr(where, f"Tracker{name}_create", None) if where is not None else None
        if f is not None:
            return f
    return None


def run_peer(name: str, clip: Clip, work: Path) -> dict | None:
    import cv2

    from trackcli.io.tracks import clip_box
    from trackcli.io.video import open_video

    factory = _peer_factory(name)
    if factory is None:
        return None
    rows = ["frame,time,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,lost"]
    tracker = None
    with open_video(clip.path) as video:
        for frame in video:
            if tracker is None:
                tracker = factory()
                hgt, wid = frame.image.shape[:2]
                x0, y0 = max(0.0, clip.box[0]), max(0.0, clip.box[1])
                x1 = min(float(wid - 1), clip.box[0] + clip.box[2])
                y1 = min(float(hgt - 1), clip.box[1] + clip.box[3])
                box = tuple(int(round(v)) for v in (x0, y0, x1 - x0, y1 - y0))
                try:
                    tracker.init(frame.image, box)
                except cv2.error:
                    return None
                ok, b = True, box
            else:
                ok, b = tracker.update(frame.image)
            # clipped to the frame as trackcli's box columns are (the part of the object in view)
            x, y, w, h = clip_box(b, (wid, hgt))
            rows.append(f"{frame.index},{frame.time},{x + w / 2},{y + h / 2},{x},{y},{w},{h},{0 if ok else 1}")
    csv = work / f"{clip.name}.{name}.csv"
    csv.write_text("\n".join(rows) + "\n")
    return score(csv, clip)


#: runs of each peer per clip, averaged (MIL is random, and cannot be seeded from here)
PEER_RUNS = 5


def run_peer_fresh(name: str, clip: Clip, work: Path, runs: int = PEER_RUNS) -> dict | None:
    """:func:`run_peer` ``runs`` times in a process of its own, the scores averaged.

    MIL draws random samples and keeps its random state from one tracker to the next within
    a process; ``cv2.setRNGSeed`` does not reset it.  The same clip scored P@20 0.42 on a
    process's first run and 1.00 on its second, and figures cached by earlier runs of this
    script moved with the order of the clips (one from 1.00 to 0.10).  A fresh process makes
    the runs the same every time, and their mean is a fairer figure than one run."""
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(1) as pool:
        return pool.apply(_peer_runs, (name, clip, work, runs))


def _peer_runs(name: str, clip: Clip, work: Path, runs: int) -> dict | None:
    results = [run_peer(name, clip, work) for _ in range(runs)]
    return None if any(r is None for r in results) else mean_scores(results)


def peer_results(clips: list[Clip], cache: Path) -> dict:
    import cv2

    path = cache / f"peers-{cv2.__version__}-x{PEER_RUNS}-clipped.json"
    done = json.loads(path.read_text()) if path.is_file() else {}
    work = Path(tempfile.mkdtemp(prefix="peers-"))
    for clip in clips:
        for name in PEERS:
            key = f"{clip.name}:{name}"
            if key not in done:
                res = run_peer_fresh(name, clip, work)
                if res is not None:
                    done[key] = res
                    path.write_text(json.dumps(done, indent=1))
    return done


# ---------------------------------------------------------------------------------------------


def _fmt(v, digits=2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.{digits}f}"


def main() -> None:
    argv = sys.argv[1:]
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="1,2,3,4,5", help="sample-data seeds (comma separated; '' for none)")
    ap.add_argument("--footage", type=Path, default=DEFAULT_FOOTAGE)
    ap.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    ap.add_argument("--peers", action="store_true", help="also run OpenCV's CSRT, KCF, MIL")
    ap.add_argument("--only", nargs="+", action="extend", help="clip names (prefix match); may be repeated")
    ap.add_argument("--json", type=Path, help="write all results here")
    ap.add_argument("--keep", type=Path, help="keep templates and tracks in this folder")
    ap.add_argument("--grey", action="store_true",
                    help="track grey copies of the clips instead (as monochrome benchmark sequences are)")
    ap.add_argument("--scale", type=float, default=1.0,
                    help="track copies of the clips resized by this factor (e.g. 0.5: half the resolution)")
    ap.add_argument("--every", type=int, default=1,
                    help="track copies of the clips with every EVERY-th frame only (faster motion)")
    ap.add_argument("--reverse", action="store_true",
                    help="track the clips played backwards, from the last frame with the object in view")
    ap.add_argument("--start", type=float, default=0.0,
                    help="track the clips from the first frame in view at or after this share of their length "
                         "(e.g. 0.5: from the middle; with --reverse, back from there)")
    ap.add_argument("--noise", type=float, default=0.0,
                    help="track copies of the clips with Gaussian noise of this standard deviation (grey levels) added")
    ap.add_argument("--jpeg", type=int, default=95,
                    help="store the copies at this JPEG quality (e.g. 20: strong compression; default 95)")
    ap.add_argument("--outline", action="store_true",
                    help="draw the templates from the true outline of the first frame (draw --mask) instead of its box; "
                         "clips without one (no masks/) are left out")
    ap.add_argument("--runs", type=int, default=1,
                    help="track every clip with --seed 0..RUNS-1 and average the scores (frame counts are summed)")
    ap.add_argument("--templates", type=Path,
                    help="use the templates NAME.template.yaml found in this folder (an earlier run's --keep) instead "
                         "of drawing them again; clips without one are drawn")
    ap.add_argument("--extra", default="",
                    help="extra options for `trackcli track`, one string (e.g. \"-c off.yaml\"); before those after --")
    args = ap.parse_args(argv)
    extra = [*args.extra.split(), *extra]

    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    args.cache.mkdir(parents=True, exist_ok=True)
    clips = synthetic_clips(seeds, args.cache) + footage_clips(args.footage)
    if args.only:
        clips = [c for c in clips if any(c.name.startswith(o) for o in args.only)]
    if (not (0.05 <= args.scale <= 4) or args.every < 1 or not (0.0 <= args.start < 1.0)
            or not (0.0 <= args.noise <= 100.0) or not (1 <= args.jpeg <= 100)):
        ap.error("--scale must be in [0.05, 4], --every at least 1, --start in [0, 1), --noise in [0, 100] "
                 "and --jpeg in [1, 100]")
    changed = (args.grey or args.scale != 1.0 or args.every != 1 or args.reverse or args.start or args.noise
               or args.jpeg != 95)
    if args.outline and changed:
        ap.error("--outline goes with the clips as they are (not with --grey, --scale, --every, --reverse, --start, "
                 "--noise, --jpeg)")
    clips = [variant_copy(c, args.cache, grey=args.grey, scale=args.scale, every=args.every, reverse=args.reverse,
                          start=args.start, noise=args.noise, quality=args.jpeg) for c in clips]
    if args.outline:
        clips = [c for c in clips if c.kind == "synthetic" or (c.path / "masks").is_dir()]
    peers = peer_results(clips, args.cache) if args.peers else {}
    work = args.keep or Path(tempfile.mkdtemp(prefix="quality-"))
    work.mkdir(parents=True, exist_ok=True)

    head = f"{'clip':<22}{'frames':>7}{'P@20':>7}{'P@10':>7}{'AUC':>7}{'err':>8}{'lost':>6}{'flag|bad':>10}{'flag|good':>10}{'s':>7}"
    peer_head = "".join(f"{n + ' P@20':>10}" for n in PEERS) if peers else ""
    print(head + peer_head)
    results = {}
    for clip in clips:
        res, wall = run_trackcli_seeds(clip, work, extra, args.runs, args.outline, args.templates)
        results[clip.name] = res
        if "error" in res:
            print(f"{clip.name:<22} {res['error']}")
            continue
        line = (f"{clip.name:<22}{res['frames']:>7}{_fmt(res['p20']):>7}{_fmt(res['p10']):>7}{_fmt(res['auc']):>7}"
                f"{_fmt(res['err_mean'], 1):>8}{res['lost']:>6}{res['lost_bad']:>5}/{res['bad']:<4}"
                f"{res['lost_good']:>5}/{res['good']:<4}{wall:>7.1f}")
        if peers:
            line += "".join(f"{_fmt(peers.get(f'{clip.name}:{n}', {}).get('p20')):>10}" for n in PEERS)
        print(line, flush=True)
    for kind in ("synthetic", "real"):
        names = [c.name for c in clips if c.kind == kind and "error" not in results[c.name]]
        if not names:
            continue
        mean = {k: float(np.mean([results[n][k] for n in names])) for k in ("p20", "p10", "auc")}
        line = (f"{'mean ' + kind:<22}{'':>7}{_fmt(mean['p20']):>7}{_fmt(mean['p10']):>7}{_fmt(mean['auc']):>7}"
                f"{'':>8}{'':>6}{'':>10}{'':>10}{'':>7}")
        if peers:
            for n in PEERS:
                vals = [peers[f"{c}:{n}"]["p20"] for c in names if f"{c}:{n}" in peers]
                line += f"{_fmt(float(np.mean(vals)) if vals else None):>10}"
        print(line)
        off, held = (sum(results[n][k] for n in names) for k in ("off", "held"))
        lost_off, lost_held = (sum(results[n][k] for n in names) for k in ("lost_off", "lost_held"))
        print(f"  {kind}: lost on frames more than twice the object's size off {lost_off}/{off}"
              f" ({_fmt(lost_off / off if off else None)}), within a tenth of it {lost_held}/{held}"
              f" ({_fmt(lost_held / held if held else None)})")
    if args.json:
        args.json.write_text(json.dumps({"trackcli": results, "peers": peers}, indent=1))


if __name__ == "__main__":
    main()
