"""How well `draw --box` segments the object: mask IoU against true outlines.

Cases:

- the sample clips regenerated with ``--seeds`` (frame 0 of ``test`` and ``train`` and the
  walker of ``three_heads``), with the tight box of the true outline and the box grown by
  15 % (a loosely drawn box);
- the folders of ``--footage`` with ``img/`` and ``masks/`` (DAVIS's layout, and the clips of
  ``bench/other_clips.py``): every ``--every``-th frame, the box of the true mask.

Prints the mean IoU of the mask ``segment_box`` returns per group, and per footage folder,
next to the template's own mask (after the B-spline fit of ``draw``) with ``--fit``; with
``--grey``, of grey copies of the frames.

    python bench/segmentation.py --seeds 1,2,3,4 --footage ../shared/footage
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from trackcli.sample_data import load_outline, load_truth, true_outline  # noqa: E402
from trackcli.run import drawing  # noqa: E402
from trackcli.segment import grabcut, masks  # noqa: E402
from trackcli.shapes import draw  # noqa: E402

CACHE = REPO / "bench" / ".cache"


def _grow(box, f):
    x, y, w, h = box
    return (x - f * w / 2, y - f * h / 2, w * (1 + f), h * (1 + f))


def synthetic_cases(seeds):
    from trackcli.io.video import open_video

    for seed in seeds:
        folder = CACHE / f"sample-{seed}"
        for clip, obj in (("test", 0), ("train", 0), ("three_heads", 2)):
            if not (folder / f"{clip}.truth.csv").is_file():
                import subprocess

                subprocess.run([sys.executable, "-m", "trackcli.cli", "-q", "sample-data", str(folder), "--seed",
                                str(seed), "--clip", clip], check=True)
            truth = load_truth(folder / f"{clip}.truth.csv")
            base = load_outline(folder / f"{clip}.outline.json")
            i = int(np.flatnonzero((truth.frame == 0) & (truth.object == obj))[0])
            row = truth.row(i)
            outline = true_outline(row, base)
            with open_video(folder / f"{clip}.mp4") as v:
                img = next(iter(v)).image
            size = (img.shape[1], img.shape[0])
            mask = draw.polygon_mask(outline, size)
            x0, y0 = outline.min(axis=0)
            x1, y1 = outline.max(axis=0)
            tight = (float(x0), float(y0), float(x1 - x0), float(y1 - y0))
            yield f"sample {clip}", img, mask, tight
            yield f"sample {clip} loose", img, mask, _grow(tight, 0.15)


def footage_cases(footage: Path, every: int):
    for folder in sorted(p for p in footage.iterdir() if (p / "img").is_dir() and (p / "masks").is_dir()):
        imgs = sorted((folder / "img").iterdir())
        masks = sorted((folder / "masks").iterdir())
        for k in range(0, len(imgs), every):
            img = cv2.imread(str(imgs[k]))
            m = cv2.imread(str(masks[k]), cv2.IMREAD_GRAYSCALE)
            ys, xs = np.nonzero(m)
            box = (float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1), float(ys.max() - ys.min() + 1))
            yield folder.name, img, (m > 0).astype(np.uint8) * 255, box


def template_mask(mask: np.ndarray) -> np.ndarray:
    """The mask of the template ``draw`` fits to ``mask``'s outline (its default control points:
    from 12 up until the curve covers the outline, :func:`trackcli.run.drawing.fit_covering`),
    rasterised."""
    import logging

    from trackcli.shapes.spline import dense_polygon

    logging.getLogger("trackcli").setLevel(logging.ERROR)  # the fit's warnings
    t = drawing.fit_template(masks.mask_outline(mask), drawing.DEFAULT_CTRL, frame_size=(mask.shape[1], mask.shape[0]),
                             detail_ctrl=drawing.DETAIL_CTRL)
    return draw.polygon_mask(dense_polygon(t.Q, t.basis(), 400), (mask.shape[1], mask.shape[0]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2,3,4")
    ap.add_argument("--footage", type=Path, default=REPO.parent / "shared" / "footage")
    ap.add_argument("--every", type=int, default=5, help="DAVIS: every N-th frame")
    ap.add_argument("--grey", action="store_true",
                    help="segment grey copies of the frames (as monochrome benchmark sequences are)")
    ap.add_argument("--fit", action="store_true",
                    help="also score the template draw makes of each mask (its default control points), rasterised")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",") if s]
    groups: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    n = 0
    cases = list(synthetic_cases(seeds))
    if args.footage.is_dir():
        cases += list(footage_cases(args.footage, args.every))
    fitted: dict[str, list[float]] = {}
    for name, img, truth, box in cases:
        if args.grey:
            img = cv2.cvtColor(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
        mask = grabcut.segment_box(img, box)
        groups.setdefault(name, []).append(masks.mask_iou(mask, truth))
        if args.fit:
            fitted.setdefault(name, []).append(masks.mask_iou(template_mask(mask), truth))
        n += 1
    sec = time.perf_counter() - t0
    head = f"{'group':28s} {'cases':>5s} {'mean IoU':>9s} {'min':>6s}"
    print(head + (f" {'template':>9s} {'min':>6s}" if args.fit else ""))
    synth, real = [], []
    synth_fit, real_fit = [], []
    for name, v in groups.items():
        (synth if name.startswith("sample ") else real).extend(v)
        line = f"{name:28s} {len(v):5d} {statistics.mean(v):9.3f} {min(v):6.3f}"
        if args.fit:
            f = fitted[name]
            (synth_fit if name.startswith("sample ") else real_fit).extend(f)
            line += f" {statistics.mean(f):9.3f} {min(f):6.3f}"
        print(line)
    for label, v, f in (("all sample clips", synth, synth_fit), ("all --footage folders", real, real_fit)):
        if v:
            line = f"{label:28s} {len(v):5d} {statistics.mean(v):9.3f} {min(v):6.3f}"
            if args.fit:
                line += f" {statistics.mean(f):9.3f} {min(f):6.3f}"
            print(line)
    print(f"{n} segmentations in {sec:.1f} s")


if __name__ == "__main__":
    main()
