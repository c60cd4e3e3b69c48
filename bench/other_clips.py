"""Cluttered clips made by a second generator, for judging the defaults on clips the tracker
was not developed on.

``trackcli sample-data`` renders the clips the tracker was developed on.  This script renders
clips of the same kinds (an object's outline in dense clutter that looks like it) written
independently of it, with other choices everywhere: three kinds of object (a bust with hair,
an open hand, a leaf on its stem) built from OpenCV's drawing primitives, with shading and
texture; backgrounds of smooth colour fields under random shapes, strokes, printed text,
stripes and look-alikes of the object (half of them its copies, at other sizes and angles;
one look-alike, its twin or not, may walk across);
motion as a random walk of the velocity with bursts, turning and growing or shrinking by up
to a quarter; a bar that may pass in front of the object; changes of exposure, sensor noise,
lens blur and JPEG compression.  Frames are rendered at twice the size and reduced (pixel
coverage at the edges).

Each clip is written in OTB's layout, ``NAME/img/0001.jpg …`` and ``NAME/groundtruth_rect.txt``
(the tight box ``x,y,w,h`` of the object's visible mask, 0-based pixels, one line per frame),
with that mask in ``NAME/masks/00000.png …`` as DAVIS gives it, so ``bench/quality.py
--footage DIR`` scores trackcli and the OpenCV trackers on them (``--outline``: from the true
outline), and ``bench/segmentation.py --footage DIR`` scores ``draw --box``'s masks:

    python bench/other_clips.py other-clips --count 12 --seed 0
    python bench/quality.py --seeds '' --footage other-clips --runs 3 --peers

The same ``--seed`` gives the same clips.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import cv2
import numpy as np

SS = 2  # supersampling of the rendering

SIZES = ((320, 240), (480, 360), (640, 480))
KINDS = ("bust", "hand", "leaf")


def _colour(rng, lo=30, hi=225) -> tuple[float, float, float]:
    return tuple(float(v) for v in rng.uniform(lo, hi, 3))


def _skin(rng) -> tuple[float, float, float]:
    # BGR skin tones from dark to light
    t = rng.uniform(0, 1)
    dark = np.array([45, 65, 100.0])
    light = np.array([170, 195, 235.0])
    return tuple(float(v) for v in (dark + t * (light - dark) + rng.normal(0, 8, 3)).clip(0, 255))


def make_sprite(kind: str, size: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The object as a BGR image and a 0..1 alpha, at supersampled resolution; ``size`` is its
    height in output pixels.  The object's centre is the sprite's centre.  Its colours,
    proportions and texture come from ``seed``: the same seed draws the same object."""
    rng = np.random.default_rng(seed)
    s = size * SS
    side = int(math.ceil(s * 1.6)) | 1
    img = np.zeros((side, side, 3), np.float32)
    alpha = np.zeros((side, side), np.uint8)
    c = side / 2.0

    def ell(target, centre, axes, angle, value):
        cv2.ellipse(target, (int(centre[0]), int(centre[1])), (max(1, int(axes[0])), max(1, int(axes[1]))),
                    angle, 0, 360, value, -1, cv2.LINE_AA)

    if kind == "bust":
        skin, hair, shirt = _skin(rng), _colour(rng, 10, 120), _colour(rng)
        hw = s * rng.uniform(0.17, 0.22)  # head half-width
        hh = hw * rng.uniform(1.2, 1.4)
        head = (c, c - s * 0.5 + hh)
        sh_w = s * rng.uniform(0.42, 0.55)
        top_sh = head[1] + hh * 1.25
        neck_w = hw * 0.55
        for tgt, body, face in ((img, shirt, skin), (alpha, 255, 255)):
            ell(tgt, (c, c + s * 0.5), (sh_w, (c + s * 0.5) - top_sh), 0, body)
            cv2.rectangle(tgt, (int(c - neck_w), int(head[1])), (int(c + neck_w), int(top_sh + 5)), face, -1)
            ell(tgt, head, (hw, hh), 0, face)
        # hair: a cap over the top of the head, a little wider than it
        cap = np.zeros_like(alpha)
        ell(cap, (head[0], head[1] - hh * 0.15), (hw * 1.08, hh * 0.95), 0, 255)
        cv2.rectangle(cap, (0, int(head[1] - hh * rng.uniform(0.1, 0.4))), (side, side), 0, -1)
        img[cap > 0] = hair
        alpha = np.maximum(alpha, cap)
        # collar and a shade on the shirt
        cv2.line(img, (int(c - neck_w), int(top_sh)), (int(c), int(top_sh + s * 0.12)), _colour(rng), SS * 2)
        cv2.line(img, (int(c + neck_w), int(top_sh)), (int(c), int(top_sh + s * 0.12)), _colour(rng), SS * 2)
    elif kind == "hand":
        skin = _skin(rng)
        pw = s * 0.24
        palm = (c, c + s * 0.18)
        for tgt, val in ((img, skin), (alpha, 255)):
            ell(tgt, palm, (pw, s * 0.28), 0, val)
            for k, ang in enumerate((-22, -8, 6, 20)):
                length = s * (0.40 + 0.08 * (1.5 - abs(k - 1.5)) / 1.5) * rng.uniform(0.9, 1.1)
                base = (palm[0] + (k - 1.5) * pw * 0.55, palm[1] - s * 0.18)
                tip = (base[0] + length * math.sin(math.radians(ang)), base[1] - length * math.cos(math.radians(ang)))
                cv2.line(tgt, (int(base[0]), int(base[1])), (int(tip[0]), int(tip[1])), val, int(s * 0.10), cv2.LINE_AA)
            thumb_a = math.radians(rng.uniform(50, 70))
            base = (palm[0] - pw * 0.8, palm[1] + s * 0.05)
            tip = (base[0] - s * 0.3 * math.sin(thumb_a), base[1] - s * 0.3 * math.cos(thumb_a))
            cv2.line(tgt, (int(base[0]), int(base[1])), (int(tip[0]), int(tip[1])), val, int(s * 0.11), cv2.LINE_AA)
            cv2.rectangle(tgt, (int(c - pw * 0.7), int(palm[1])), (int(c + pw * 0.7), int(c + s * 0.62)), val, -1)
        # knuckle creases
        for k in range(3):
            y = int(palm[1] - s * 0.05 + k * s * 0.08)
            cv2.line(img, (int(c - pw * 0.6), y), (int(c + pw * 0.5), y + int(s * 0.02)),
                     tuple(v * 0.8 for v in skin), SS)
    else:  # leaf
        green = (rng.uniform(20, 80), rng.uniform(110, 200), rng.uniform(30, 120))
        t = np.linspace(0, math.pi, 60)
        half_w = s * rng.uniform(0.2, 0.3)
        length = s * 0.78
        y = c - s * 0.5 + length * (1 - np.cos(t)) / 2
        x = half_w * np.sin(t) * (1 + 0.3 * np.sin(2 * t))
        poly = np.concatenate([np.stack([c + x, y], 1), np.stack([c - x[::-1], y[::-1]], 1)])
        poly = (poly + rng.normal(0, s * 0.006, poly.shape)).astype(np.int32)
        for tgt, val in ((img, green), (alpha, 255)):
            cv2.fillPoly(tgt, [poly], val, cv2.LINE_AA)
            cv2.line(tgt, (int(c), int(y[-1])), (int(c + s * 0.05), int(c + s * 0.55)), val, max(2, int(s * 0.04)))
        vein = tuple(min(255.0, v * 1.3) for v in green)
        cv2.line(img, (int(c), int(y[0])), (int(c), int(y[-1])), vein, max(1, SS))
        for k in range(1, 6):
            yy = y[0] + k * (y[-1] - y[0]) / 6
            for sgn in (-1, 1):
                cv2.line(img, (int(c), int(yy)), (int(c + sgn * half_w * 0.8), int(yy - s * 0.08)), vein, max(1, SS // 2))
    # shading from the upper left, and fine texture
    yy, xx = np.mgrid[0:side, 0:side].astype(np.float32) / side
    img *= (1.15 - 0.3 * (xx + yy) / 2)[..., None]
    img += rng.normal(0, 5, img.shape).astype(np.float32)
    return img.clip(0, 255), alpha.astype(np.float32) / 255.0


def smooth_field(rng, w: int, h: int, cells: int, amp: float) -> np.ndarray:
    small = rng.uniform(-amp, amp, (cells, int(cells * w / h) + 1, 3)).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


def _matrix(side: int, cx: float, cy: float, angle: float, scale: float) -> np.ndarray:
    """The affine map putting a sprite's centre at ``(cx, cy)`` (canvas pixels), turned and scaled."""
    m = cv2.getRotationMatrix2D((side / 2.0, side / 2.0), angle, scale)
    m[:, 2] += (cx - side / 2.0, cy - side / 2.0)
    return m


def paste(canvas: np.ndarray, cover: np.ndarray | None, sprite, alpha, cx, cy, angle, scale):
    """Warp the sprite to ``(cx, cy)`` (supersampled canvas pixels), over the canvas."""
    m = _matrix(sprite.shape[0], cx, cy, angle, scale)
    h, w = canvas.shape[:2]
    a = cv2.warpAffine(alpha, m, (w, h), flags=cv2.INTER_LINEAR, borderValue=0)
    col = cv2.warpAffine(sprite, m, (w, h), flags=cv2.INTER_LINEAR, borderValue=0)
    canvas *= (1 - a)[..., None]
    canvas += col * a[..., None]
    if cover is not None:
        cover[:] = np.maximum(cover, a)
    return a


def background(rng, w: int, h: int, kind: str, obj_size: float, avoid, n_lookalike: int, obj_seed: int) -> np.ndarray:
    """Clutter at supersampled size; look-alikes stay out of the ``avoid`` box (output pixels),
    half of them copies of the object (``make_sprite`` seed ``obj_seed``) at other sizes and angles."""
    W, H = w * SS, h * SS
    base = np.array(_colour(rng, 60, 200), np.float32)
    bg = (base + smooth_field(rng, W, H, 4, 50) + smooth_field(rng, W, H, 24, 12)).clip(0, 255).astype(np.uint8)
    area = w * h
    n = int(rng.uniform(0.6, 1.2) * area / 700)
    for _ in range(n):
        col = _colour(rng, 0, 255)
        what = rng.integers(0, 6)
        x, y = rng.uniform(0, W), rng.uniform(0, H)
        r = rng.uniform(4, 30) * SS
        if what == 0:
            cv2.ellipse(bg, (int(x), int(y)), (int(r), int(r * rng.uniform(0.3, 1))), rng.uniform(0, 180), 0, 360,
                        col, -1, cv2.LINE_AA)
        elif what == 1:
            ang = rng.uniform(0, math.pi)
            ln = rng.uniform(10, 80) * SS
            cv2.line(bg, (int(x), int(y)), (int(x + ln * math.cos(ang)), int(y + ln * math.sin(ang))), col,
                     int(rng.integers(1, 4) * SS), cv2.LINE_AA)
        elif what == 2:
            pts = (np.array([x, y]) + rng.normal(0, r, (int(rng.integers(3, 7)), 2))).astype(np.int32)
            cv2.fillPoly(bg, [pts], col, cv2.LINE_AA)
        elif what == 3:
            text = "".join(chr(int(c)) for c in rng.integers(65, 91, int(rng.integers(3, 9))))
            cv2.putText(bg, text, (int(x), int(y)), cv2.FONT_HERSHEY_SIMPLEX, rng.uniform(0.4, 1.2) * SS, col,
                        int(rng.integers(1, 3) * SS), cv2.LINE_AA)
        elif what == 4:
            cv2.ellipse(bg, (int(x), int(y)), (int(r), int(r)), 0, rng.uniform(0, 360), rng.uniform(60, 300), col,
                        int(rng.integers(1, 3) * SS), cv2.LINE_AA)
        else:  # a patch of stripes
            pw, ph = int(rng.uniform(15, 50) * SS), int(rng.uniform(15, 50) * SS)
            col2 = _colour(rng, 0, 255)
            step = int(rng.integers(3, 8)) * SS
            x0, y0 = int(x), int(y)
            for k in range(0, pw, 2 * step):
                cv2.rectangle(bg, (x0 + k, y0), (x0 + k + step, y0 + ph), col, -1)
                cv2.rectangle(bg, (x0 + k + step, y0), (x0 + k + 2 * step, y0 + ph), col2, -1)
    bg = bg.astype(np.float32)
    ax, ay, aw, ah = avoid
    placed = 0
    for _ in range(200):
        if placed >= n_lookalike:
            break
        sc = rng.uniform(0.75, 1.25)
        x, y = rng.uniform(0, w), rng.uniform(0, h)
        r = obj_size * sc * 0.8
        if x + r > ax and x - r < ax + aw and y + r > ay and y - r < ay + ah:
            continue
        same = rng.uniform() < 0.5
        sprite, alpha = make_sprite(kind, obj_size, obj_seed if same else int(rng.integers(1 << 30)))
        # a partly drawn look-alike now and then (cut by a random half-plane)
        if rng.uniform() < 0.3:
            side = alpha.shape[0]
            yy, xx = np.mgrid[0:side, 0:side]
            ang = rng.uniform(0, 2 * math.pi)
            alpha = alpha * (((xx - side / 2) * math.cos(ang) + (yy - side / 2) * math.sin(ang)) < side * 0.1)
            alpha = alpha.astype(np.float32)
        paste(bg, None, sprite, alpha, x * SS, y * SS, rng.uniform(-30, 30), sc)
        placed += 1
    return bg


def render_clip(out: Path, seed: int, index: int) -> str:
    rng = np.random.default_rng([seed, index, 0x07C1])
    kind = KINDS[index % len(KINDS)]
    w, h = SIZES[int(rng.integers(0, len(SIZES)))]
    n = int(rng.integers(120, 201))
    size = rng.uniform(0.28, 0.45) * h
    obj_seed = int(rng.integers(1 << 30))
    sprite, alpha = make_sprite(kind, size, obj_seed)
    # motion: the velocity a random walk with damping and bursts; turning and growing slowly
    pos = np.array([rng.uniform(0.35, 0.65) * w, rng.uniform(0.4, 0.6) * h])
    vel = np.zeros(2)
    speed = rng.uniform(1.5, 4.0)
    angle, scale = 0.0, 1.0
    dang, dscale = 0.0, 0.0
    poses = []
    for k in range(n):
        vel = 0.85 * vel + rng.normal(0, speed * 0.55, 2)
        if rng.uniform() < 0.04:
            vel += rng.normal(0, speed * 3, 2)
        pos = pos + vel
        r = size * scale * 0.5
        for d, lim in ((0, w), (1, h)):
            lo, hi = r * 0.6, lim - r * 0.6
            if pos[d] < lo or pos[d] > hi:
                pos[d] = min(max(pos[d], lo), hi)
                vel[d] = -0.5 * vel[d]
        dang = 0.9 * dang + rng.normal(0, 0.35)
        angle = float(np.clip(angle + dang, -20, 20))
        dscale = 0.92 * dscale + rng.normal(0, 0.002)
        scale = float(np.clip(scale + dscale, 0.78, 1.25))
        poses.append((pos[0], pos[1], angle, scale))
    # frame 0's box, for keeping look-alikes away from the object where the template is drawn
    a0 = cv2.warpAffine(alpha, _matrix(alpha.shape[0], poses[0][0] * SS, poses[0][1] * SS, *poses[0][2:]), (w * SS, h * SS))
    ys, xs = np.nonzero(a0 > 0.5)
    box0 = (xs.min() / SS, ys.min() / SS, (xs.max() - xs.min()) / SS, (ys.max() - ys.min()) / SS)
    bg = background(rng, w, h, kind, size, box0, int(rng.integers(3, 9)), obj_seed)
    mover = None
    if rng.uniform() < 0.5:  # a look-alike walking across
        twin = rng.uniform() < 0.5  # the object's twin, or another of its kind
        msprite, malpha = make_sprite(kind, size * rng.uniform(0.9, 1.1), obj_seed if twin else int(rng.integers(1 << 30)))
        y0 = rng.uniform(0.3, 0.7) * h
        x_from, x_to = (-0.3 * w, 1.3 * w) if rng.uniform() < 0.5 else (1.3 * w, -0.3 * w)
        t0 = int(rng.integers(0, n // 2))
        mover = (msprite, malpha, y0, x_from, x_to, t0, t0 + int(n * rng.uniform(0.5, 0.9)))
    bar = None
    if rng.uniform() < 0.5:  # a bar passing in front
        k0 = int(rng.integers(20, n - 40))
        bar = (k0, k0 + int(rng.integers(15, 30)), int(rng.uniform(0.06, 0.12) * size), _colour(rng))
    noise = rng.uniform(2, 7)
    blur = rng.uniform(0.3, 1.0)
    quality = int(rng.integers(75, 93))
    gain_phase, gain_amp = rng.uniform(0, 2 * math.pi), rng.uniform(0.05, 0.2)

    name = f"other_{kind}_{seed}_{index:02d}"
    folder = out / name
    (folder / "img").mkdir(parents=True, exist_ok=True)
    (folder / "masks").mkdir(exist_ok=True)
    rows = []
    for k, (x, y, ang, sc) in enumerate(poses):
        canvas = bg.copy()
        if mover is not None and mover[5] <= k <= mover[6]:
            msprite, malpha, my, xf, xt, t0, t1 = mover
            mx = xf + (xt - xf) * (k - t0) / max(1, t1 - t0)
            paste(canvas, None, msprite, malpha, mx * SS, (my + 6 * math.sin(k * 0.3)) * SS, 0.0, 1.0)
        cover = np.zeros(canvas.shape[:2], np.float32)
        paste(canvas, cover, sprite, alpha, x * SS, y * SS, ang, sc)
        if bar is not None and bar[0] <= k <= bar[1]:
            bx = x * SS + (k - (bar[0] + bar[1]) / 2) * 4 * SS
            cv2.rectangle(canvas, (int(bx - bar[2] * SS), 0), (int(bx + bar[2] * SS), h * SS), bar[3], -1)
            cv2.rectangle(cover, (int(bx - bar[2] * SS), 0), (int(bx + bar[2] * SS), h * SS), 0.0, -1)
        gain = 1.0 + gain_amp * math.sin(gain_phase + k * 0.05)
        frame = cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA) * gain
        frame = cv2.GaussianBlur(frame, (0, 0), blur)
        frame += rng.normal(0, noise, frame.shape).astype(np.float32)
        cv2.imwrite(str(folder / "img" / f"{k + 1:04d}.jpg"), frame.clip(0, 255).astype(np.uint8),
                    [cv2.IMWRITE_JPEG_QUALITY, quality])
        vis = cv2.resize(cover, (w, h), interpolation=cv2.INTER_AREA) > 0.5
        cv2.imwrite(str(folder / "masks" / f"{k:05d}.png"), vis.astype(np.uint8) * 255)
        ys, xs = np.nonzero(vis)
        if xs.size:
            rows.append(f"{xs.min()},{ys.min()},{xs.max() - xs.min() + 1},{ys.max() - ys.min() + 1}")
        else:
            rows.append("nan,nan,nan,nan")
    (folder / "groundtruth_rect.txt").write_text("\n".join(rows) + "\n")
    return name


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="folder to write the clips into")
    ap.add_argument("--count", type=int, default=12, help="clips to make (the kinds in turn)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    for i in range(args.count):
        print(render_clip(args.out, args.seed, i), flush=True)


if __name__ == "__main__":
    main()
