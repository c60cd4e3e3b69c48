"""Outline quality on DAVIS-layout folders: J and F per sequence and mean, as a user gets them.

For every sequence this script does what a user of the semi-supervised protocol does::

    trackcli draw SEQ/img --mask SEQ/masks/<first>.png -o T.yaml     # the first frame's mask
    trackcli track --template T.yaml SEQ/img -o OUT --json             # the defaults

(or ``draw --box`` on the first mask's tight box with ``--box``), fills each frame's outline
(the track CSV's outline columns) to a mask and scores it against the true mask with
:mod:`trackcli.run.masks`: J (IoU) and F (boundary F-measure, DAVIS-2016 tolerance), first and
last frame left out, the mean over sequences.  It also prints

- ``tmpl``: J of the frame-0 template's outline against the mask it was drawn from;
- ``lost``: frames the tracker reported lost; ``fps``: the tracker's own frames per second;
- the truthfulness of ``lost``: the share of the frames whose estimate is far off (centroid
  more than twice the object's size, sqrt of the true area, from the true one, or no overlap)
  that are flagged (``flag|off``, want high), and of the frames held (centroid within 10 % of
  the size) that are flagged (``flag|held``, want low).

A folder is either a set of sequences ``NAME/img/*.jpg`` + ``NAME/masks/*.png`` (how
``../shared/footage/davis_train`` is laid out), or a DAVIS release root with
``JPEGImages/480p/NAME`` and ``Annotations/480p/NAME``.  With ``--baseline`` two reference
outlines are scored beside: the first mask held still (``still``) and the first mask moved by
OpenCV's CSRT box (``csrt``, needs ``opencv-contrib-python-headless``).

Usage::

    python bench/davis.py [FOLDER ...] [--only a,b] [--box] [--baseline] [--json OUT.json]
        [--extra "TRACK OPTIONS"] [--work DIR] [--templates DIR]
    python bench/davis.py [FOLDER ...] --template-only [--box] [--draw-extra "--n-ctrl 12"]

``--templates DIR`` takes the templates an earlier run left in its ``--work DIR`` instead of
drawing them again (the draw is most of a run's time on short sequences): runs that differ
only in ``--extra`` then track from the very same templates.

With ``--template-only`` only the frame-0 templates are drawn and scored (``tmpl``, the number
of control points ``ctrl``, the draw's time in seconds and the fit's note from the template's
``source``): cheap enough to run on every sequence of a dev set.
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from trackcli.run.masks import mask_files, outline_mask, read_mask, score_masks  # noqa: E402

DEFAULT_FOLDERS = [ROOT.parent / "shared" / "footage" / "davis_train"]


@dataclass(frozen=True)
class Sequence:
    name: str
    frames: Path     # folder of frame images
    masks: Path      # folder of true masks, one per frame


def sequences(folder: Path) -> list[Sequence]:
    """The sequences of a DAVIS-layout folder (either layout, see the module docstring)."""
    out = []
    jpeg, ann = folder / "JPEGImages" / "480p", folder / "Annotations" / "480p"
    if jpeg.is_dir() and ann.is_dir():
        for d in sorted(p for p in jpeg.iterdir() if p.is_dir()):
            if (ann / d.name).is_dir():
                out.append(Sequence(d.name, d, ann / d.name))
        return out
    if (folder / "img").is_dir() and (folder / "masks").is_dir():
        return [Sequence(folder.name, folder / "img", folder / "masks")]
    for d in sorted(p for p in folder.iterdir() if p.is_dir()):
        if (d / "img").is_dir() and (d / "masks").is_dir():
            out.append(Sequence(d.name, d / "img", d / "masks"))
    return out


def _cli(*args: str) -> subprocess.CompletedProcess:
    # the package this script imports (the checkout it sits in, or PYTHONPATH's), not whichever
    # the environment's `trackcli` script was installed from
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "trackcli.cli", "-q", *args], capture_output=True, text=True,
                          timeout=3600, env=env)


def _last_line(r: subprocess.CompletedProcess) -> str:
    return (r.stderr.strip().splitlines() or ["?"])[-1]


def tight_box(mask: np.ndarray) -> tuple[float, float, float, float]:
    ys, xs = np.nonzero(mask)
    return float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1), float(ys.max() - ys.min() + 1)


def _centroid(m: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(m)
    return np.array([xs.mean(), ys.mean()]) if len(xs) else np.array([np.nan, np.nan])


def lost_truth(pred: list[np.ndarray], truth: list[np.ndarray], lost: np.ndarray) -> dict:
    """Flagged among frames far off and among frames held (frames with an empty truth left out)."""
    off, held = [], []
    for p, t, f in zip(pred, truth, lost):
        area = np.count_nonzero(t)
        if area == 0:
            continue
        size = math.sqrt(area)
        err = np.linalg.norm(_centroid(p) - _centroid(t))
        far = (not np.isfinite(err)) or err > 2 * size or not np.any(p & t)
        if far:
            off.append(bool(f))
        elif err < 0.1 * size:
            held.append(bool(f))
    return {"off": len(off), "flag_off": sum(off), "held": len(held), "flag_held": sum(held)}


def draw_template(seq: Sequence, work: Path, *, box: bool, draw_extra: list[str] = (),
                  templates: Path | None = None) -> dict:
    """``draw`` on the sequence's first frame (its mask, or with ``box`` the mask's tight box):
    the template's J against that mask (``tmpl``), its control points, how it was made.  With
    ``templates``, a folder where ``NAME.template.yaml`` is found is used instead of drawing."""
    from trackcli.shapes.spline import dense_polygon
    from trackcli.shapes.template import load_template

    truth0 = read_mask(mask_files(seq.masks)[0])
    tmpl = work / f"{seq.name}.template.yaml"
    wall = 0.0
    if templates is not None and (templates / tmpl.name).is_file():
        tmpl = templates / tmpl.name  # drawn by an earlier run: the same template, not drawn again
    else:
        how = ["--box", ",".join(f"{v:g}" for v in tight_box(truth0))] if box else ["--mask", str(mask_files(seq.masks)[0])]
        t0 = time.perf_counter()
        r = _cli("draw", str(seq.frames), *how, "-o", str(tmpl), "--preview", str(work / f"{seq.name}.template.png"),
                 *draw_extra)
        wall = time.perf_counter() - t0
        if r.returncode:
            return {"name": seq.name, "error": "draw: " + _last_line(r)}
    t = load_template(tmpl)
    tmpl_j = float(score_masks([outline_mask(dense_polygon(t.Q, t.basis(), 400), truth0.shape)], [truth0]).J[0])
    return {"name": seq.name, "tmpl": tmpl_j, "n_ctrl": t.n_ctrl, "source": t.source, "draw_wall": wall,
            "template": tmpl}


def run_sequence(seq: Sequence, work: Path, *, box: bool, extra: list[str], draw_extra: list[str] = (),
                 templates: Path | None = None) -> dict:
    from trackcli.io.tracks import read_columns, read_outlines

    truth = [read_mask(f) for f in mask_files(seq.masks)]
    shape = truth[0].shape
    drawn = draw_template(seq, work, box=box, draw_extra=draw_extra, templates=templates)
    if "error" in drawn:
        return drawn
    tmpl, tmpl_j = drawn["template"], drawn["tmpl"]
    out = work / seq.name
    t0 = time.perf_counter()
    r = _cli("track", "--template", str(tmpl), str(seq.frames), "-o", str(out), "--no-rrd", "--json", "--seed", "0",
             *extra)
    wall = time.perf_counter() - t0
    if r.returncode:
        return {"name": seq.name, "error": "track: " + _last_line(r), "tmpl": tmpl_j}
    summary = next((json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")), {})
    csv = Path(summary["csv"])
    frames, outlines, _ = read_outlines(csv)
    lost = read_columns(csv, ["lost"])["lost"]
    n = min(len(frames), len(truth))
    pred = [outline_mask(outlines[i], shape) for i in range(n)]
    s = score_masks(pred, truth[:n], frames[:n])
    res = {"name": seq.name, "frames": n, "J": s.J_mean, "F": s.F_mean, "tmpl": tmpl_j, "n_ctrl": drawn["n_ctrl"],
           "lost": int(np.nansum(lost[:n])), "fps": summary.get("tracker_fps"), "wall": wall,
           "J_per_frame": [round(float(v), 4) for v in s.J]}
    res.update(lost_truth(pred, truth[:n], lost[:n]))
    return res


def baselines(seq: Sequence) -> dict:
    """J of the first mask held still, and moved by CSRT's box (when opencv-contrib is there)."""
    import cv2

    truth = [read_mask(f) for f in mask_files(seq.masks)]
    res = {"still": score_masks([truth[0]] * len(truth), truth).J_mean}
    if not hasattr(cv2, "TrackerCSRT"):
        return res
    imgs = sorted(p for p in seq.frames.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    tr = cv2.TrackerCSRT.create()
    x, y, w, h = tight_box(truth[0])
    tr.init(cv2.imread(str(imgs[0])), (int(x), int(y), int(w), int(h)))
    pred = [truth[0]]
    for f in imgs[1:len(truth)]:
        ok, (bx, by, bw, bh) = tr.update(cv2.imread(str(f)))
        m = np.zeros_like(truth[0])
        if ok:
            M = np.float32([[bw / w, 0, bx - x * bw / w], [0, bh / h, by - y * bh / h]])
            m = cv2.warpAffine(truth[0].astype(np.uint8), M, (m.shape[1], m.shape[0]), flags=cv2.INTER_NEAREST) > 0
        pred.append(m)
    s = score_masks(pred, truth)
    res.update({"csrt": s.J_mean, "csrt_F": s.F_mean})
    return res


def _f(v, d=2) -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{d}f}"


def template_table(seqs: list[Sequence], work: Path, *, box: bool, draw_extra: list[str],
                   json_out: Path | None) -> None:
    """``--template-only``: per sequence the template's J against the first mask, its control
    points and the draw's time, then the mean."""
    rows = []
    print(f"{'sequence':<20} {'tmpl':>5} {'ctrl':>4} {'draw s':>6}  source")
    for seq in seqs:
        r = draw_template(seq, work, box=box, draw_extra=draw_extra)
        rows.append(r)
        if "error" in r:
            print(f"{seq.name:<20} {r['error']}", flush=True)
            continue
        note = r["source"].split(")", 1)[0].split("(", 1)[1] if "(" in r["source"] else ""
        print(f"{seq.name:<20} {_f(r['tmpl']):>5} {r['n_ctrl']:>4} {r['draw_wall']:>6.1f}  {note}", flush=True)
    ok = [r for r in rows if "error" not in r]
    if ok:
        print(f"{'mean (' + str(len(ok)) + ')':<20} {_f(np.mean([r['tmpl'] for r in ok])):>5} "
              f"{np.mean([r['n_ctrl'] for r in ok]):>4.0f} {np.mean([r['draw_wall'] for r in ok]):>6.1f}")
    if json_out:
        json_out.write_text(json.dumps([{k: (str(v) if isinstance(v, Path) else v) for k, v in r.items()}
                                        for r in rows], indent=1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folders", nargs="*", type=Path, help="DAVIS-layout folders (default: the shared dev set)")
    ap.add_argument("--only", help="comma-separated sequence names")
    ap.add_argument("--box", action="store_true", help="draw the template from the first mask's box, not the mask")
    ap.add_argument("--baseline", action="store_true", help="also score the still mask and CSRT's moved mask")
    ap.add_argument("--work", type=Path, help="keep outputs here (default: a temporary folder)")
    ap.add_argument("--json", type=Path, help="write every figure to this JSON file")
    ap.add_argument("--extra", default="", help="extra options for `trackcli track`, one string")
    ap.add_argument("--draw-extra", default="", help="extra options for `trackcli draw`, one string")
    ap.add_argument("--templates", type=Path,
                    help="use the templates NAME.template.yaml found in this folder (an earlier run's --work) "
                         "instead of drawing them again; sequences without one are drawn")
    ap.add_argument("--template-only", action="store_true",
                    help="only draw the frame-0 templates and score them against the first mask (no tracking)")
    a = ap.parse_args()
    folders = a.folders or [f for f in DEFAULT_FOLDERS if f.is_dir()]
    seqs = [s for f in folders for s in sequences(f)]
    if a.only:
        keep = set(a.only.split(","))
        seqs = [s for s in seqs if s.name in keep]
    if not seqs:
        sys.exit("no DAVIS-layout sequences found")
    work = a.work or Path(tempfile.mkdtemp(prefix="davis-"))
    work.mkdir(parents=True, exist_ok=True)
    if a.template_only:
        return template_table(seqs, work, box=a.box, draw_extra=a.draw_extra.split(), json_out=a.json)
    rows = []
    head = f"{'sequence':<20} {'J':>5} {'F':>5} {'tmpl':>5} {'lost':>5} {'flag|off':>9} {'flag|held':>9} {'fps':>5}"
    if a.baseline:
        head += f" {'still':>5} {'csrt':>5}"
    print(head)
    for seq in seqs:
        r = run_sequence(seq, work, box=a.box, extra=a.extra.split(), draw_extra=a.draw_extra.split(),
                         templates=a.templates)
        if a.baseline:
            r.update(baselines(seq))
        r.pop("template", None)
        rows.append(r)
        if "error" in r:
            print(f"{seq.name:<20} {r['error']}")
            continue
        line = (f"{seq.name:<20} {_f(r['J']):>5} {_f(r['F']):>5} {_f(r['tmpl']):>5} {r['lost']:>5} "
                f"{r['flag_off']:>4}/{r['off']:<4} {r['flag_held']:>4}/{r['held']:<4} {_f(r['fps'], 0):>5}")
        if a.baseline:
            line += f" {_f(r.get('still')):>5} {_f(r.get('csrt')):>5}"
        print(line, flush=True)
    ok = [r for r in rows if "error" not in r]
    if ok:
        off, held = sum(r["off"] for r in ok), sum(r["held"] for r in ok)
        fo, fh = sum(r["flag_off"] for r in ok), sum(r["flag_held"] for r in ok)
        line = (f"{'mean (' + str(len(ok)) + ')':<20} {_f(np.mean([r['J'] for r in ok])):>5} "
                f"{_f(np.mean([r['F'] for r in ok])):>5} {_f(np.mean([r['tmpl'] for r in ok])):>5} "
                f"{sum(r['lost'] for r in ok):>5} {_f(fo / off if off else math.nan):>9} "
                f"{_f(fh / held if held else math.nan):>9} {_f(np.mean([r['fps'] for r in ok]), 0):>5}")
        if a.baseline:
            line += f" {_f(np.mean([r['still'] for r in ok])):>5} {_f(np.nanmean([r.get('csrt', np.nan) for r in ok])):>5}"
        print(line)
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
