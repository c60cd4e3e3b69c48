"""Per-frame cost of a CONDENSATION step on synthetic cluttered 640 x 480 frames.

One step = select by weight + predict (AR(2), planar affine shape-space, Nx = 6) + curve
evaluation (M points and normals of a closed quadratic B-spline with 12 control points, as
a plain matrix product) + the log-likelihood of every sample (h = 15 px): by default the
contour discriminant with the colour term (the tracker's default observation model,
``trackcli.observe.discriminant``, appearance learned on the first frame), or with
``--likelihood clutter`` the clutter model of AC eq 12.2.  The feature image (one blur per
frame) and the per-frame images of the discriminant (colour map, clutter density) are timed
on their own, and so is decoding the same frames from a short video written with OpenCV.  Everything runs on one core.  The frames
have dense clutter (about 1.3 features above threshold per 31-px normal segment), and the
tracking error of the weighted mean is printed as a check that the filter tracks.

The table gives, per N: the median step time, its mean, and its parts — selection and
prediction, curve evaluation, and the likelihood (sampling 34 points along each of N x M
normals, then finding the maxima and summing over them) — and the serial part: the median time
of a step during which no thread is scoring samples (selection, prediction, handing the
blocks to the threads and collecting them, normalising the weights).  ``/N=1000`` is the cost relative to N = 1000.

With more than one thread count, a second table times the weighting alone
(``condensation.weigh`` on curves evaluated beforehand: the likelihood of every sample, the
part of the step the threads share) with each count: the speed-up the threads give where
nothing is serial.

``--floor`` times, on the same curves, a compiled loop that does nothing but read each
normal's profile (the 34 bilinear samples of the ±15 px search, read by the kernel's own
loop, the sums kept in one slot per sample so that no add waits for another), and the same with one pixel per sample: the cost of the reads alone, which any
likelihood of this kind pays, against the whole likelihood (``x floor``).

``--ceiling`` then runs the one-thread step in two processes at once, each held to its own
CPU, sharing nothing: the step time each of them gets, and the speed-up two processes give
over one (four times the one-thread step over the sum of theirs).  That is the most a second
thread can give on this machine; on a virtual machine it depends on the host's other work,
and can be well below 2.

Usage::

    python bench/bench_condensation.py [--frames 40] [--sizes 100,300,1000,3000,10000]
                                       [--normals 24] [--curves matrix|trackcli] [--repeat 3]
                                       [--threads 1,2] [--likelihood discriminant|clutter] [--floor]
                                       [--ceiling]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import multiprocessing  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from numba import njit, uintp  # noqa: E402

from trackcli.trackers import condensation  # noqa: E402
from trackcli.observe import appearance, discriminant, likelihoods, measure  # noqa: E402
from trackcli.observe.kernels import _profile_inside  # noqa: E402

WIDTH, HEIGHT = 640, 480
TAU = 0.04
N_CONTROL = 12


# ---------------------------------------------------------------------------------------------
# A closed quadratic B-spline template and the affine shape-space, evaluated as matrices.


def periodic_quadratic_basis(n_control: int, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives of the uniform periodic quadratic B-spline basis: (M, Nq) each."""
    s = np.arange(n_points) * n_control / n_points
    span = np.floor(s).astype(int)
    t = s - span
    vals = np.zeros((n_points, n_control))
    ders = np.zeros((n_points, n_control))
    rows = np.arange(n_points)
    for k, (v, d) in enumerate((((1 - t) ** 2 / 2, -(1 - t)), ((-2 * t**2 + 2 * t + 1) / 2, 1 - 2 * t), (t**2 / 2, t))):
        vals[rows, (span + k) % n_control] += v
        ders[rows, (span + k) % n_control] += d
    return vals, ders


def curve_model(centre: tuple[float, float], radii: tuple[float, float], n_points: int):
    """Matrices mapping shape vectors X (N, 6) to points and tangents (N, M, 2)."""
    ang = 2 * np.pi * (np.arange(N_CONTROL) + 0.5) / N_CONTROL
    qx = radii[0] * np.cos(ang)
    qy = radii[1] * np.sin(ang)
    one, zero = np.ones(N_CONTROL), np.zeros(N_CONTROL)
    # Planar affine space about the template's own centre: X = (tx, ty, a11-1, a22-1, a21, a12).
    w = np.block([[one[:, None], zero[:, None], qx[:, None], zero[:, None], zero[:, None], qy[:, None]],
                  [zero[:, None], one[:, None], zero[:, None], qy[:, None], qx[:, None], zero[:, None]]])
    q0 = np.concatenate([qx + centre[0], qy + centre[1]])
    vals, ders = periodic_quadratic_basis(N_CONTROL, n_points)

    def interleave(basis: np.ndarray) -> np.ndarray:
        u = np.zeros((2 * n_points, 2 * N_CONTROL))
        u[0::2, :N_CONTROL] = basis  # x of point i in column 2 i
        u[1::2, N_CONTROL:] = basis
        return u

    upts, utan = interleave(vals), interleave(ders)
    model = SimpleNamespace(
        w_pts=(upts @ w).T.copy(), off_pts=upts @ q0,
        w_tan=(utan @ w).T.copy(), off_tan=utan @ q0, n_points=n_points,
    )
    model.evaluate = lambda x: curves(model, x)
    return model


def curves(model, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and unit normals (N, M, 2) of the curves with shape vectors ``x`` (N, 6)."""
    n = x.shape[0]
    pts = (x @ model.w_pts + model.off_pts).reshape(n, model.n_points, 2)
    tan = x @ model.w_tan + model.off_tan  # (N, 2M), x and y interleaved
    tx, ty = tan[:, 0::2], tan[:, 1::2]
    inv = tx * tx
    inv += ty * ty
    np.sqrt(inv, out=inv)
    np.divide(1.0, inv, out=inv)
    nrm = np.empty_like(tan)
    np.multiply(ty, inv, out=nrm[:, 0::2])
    np.multiply(tx, inv, out=nrm[:, 1::2])
    np.negative(nrm[:, 1::2], out=nrm[:, 1::2])
    return pts, nrm.reshape(n, model.n_points, 2)


def trackcli_curve_model(centre: tuple[float, float], radii: tuple[float, float], n_points: int):
    """The same template evaluated by trackcli's own spline and shape-space modules."""
    from trackcli.shapes import shape_space
    from trackcli.shapes import spline

    basis = spline.SplineBasis(N_CONTROL)
    ang = 2 * np.pi * (np.arange(N_CONTROL) + 0.5) / N_CONTROL
    q0 = np.concatenate([centre[0] + radii[0] * np.cos(ang), centre[1] + radii[1] * np.sin(ang)])
    space = shape_space.affine(basis, q0, origin=np.array(centre))
    sampler = basis.sampler(basis.measurement_params(n_points))
    return SimpleNamespace(evaluate=lambda x: space.points_normals(x, sampler))


# ---------------------------------------------------------------------------------------------
# Synthetic footage: a light head-sized ellipse moving over dense static clutter.


def clutter_background(rng: np.random.Generator) -> np.ndarray:
    img = np.full((HEIGHT, WIDTH, 3), 100, np.uint8)
    for _ in range(250):
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        kind = rng.integers(3)
        x, y = int(rng.integers(0, WIDTH)), int(rng.integers(0, HEIGHT))
        if kind == 0:
            cv2.rectangle(img, (x, y), (x + int(rng.integers(5, 80)), y + int(rng.integers(5, 80))), colour, -1)
        elif kind == 1:
            cv2.circle(img, (x, y), int(rng.integers(3, 40)), colour, int(rng.choice([-1, 2])))
        else:
            cv2.line(img, (x, y), (int(rng.integers(0, WIDTH)), int(rng.integers(0, HEIGHT))), colour, int(rng.integers(1, 4)))
    return img


def make_frames(n_frames: int, rng: np.random.Generator) -> tuple[list[np.ndarray], np.ndarray]:
    background = clutter_background(rng)
    frames, truth = [], []
    for k in range(n_frames):
        cx = 320 + 120 * np.sin(2 * np.pi * k / 50)
        cy = 240 + 40 * np.sin(2 * np.pi * k / 35)
        img = background.copy()
        cv2.ellipse(img, (int(round(cx)), int(round(cy))), (40, 55), 0, 0, 360, (170, 190, 230), -1, cv2.LINE_AA)
        noise = rng.normal(0, 4, img.shape)
        frames.append(np.clip(img + noise, 0, 255).astype(np.uint8))
        truth.append((cx, cy))
    return frames, np.array(truth)


def dynamics() -> SimpleNamespace:
    """Critically damped AR(2) per component (AC §9.6 with f = 0): agile translation, stiff shape."""
    beta = np.array([2.0, 2.0, 10.0, 10.0, 10.0, 10.0])
    b0 = np.array([4.0, 4.0, 0.01, 0.01, 0.01, 0.01])
    return SimpleNamespace(
        A1=np.diag(2 * np.exp(-beta * TAU)), A2=np.diag(-np.exp(-2 * beta * TAU)), B0=np.diag(b0), mean=np.zeros(6)
    )


# ---------------------------------------------------------------------------------------------


def time_decode(frames: list[np.ndarray], workdir: Path) -> dict[str, float]:
    """Milliseconds per frame to decode the frames written as MJPG .avi and mp4v .mp4."""
    out = {}
    for name, fourcc in (("clip.avi", "MJPG"), ("clip.mp4", "mp4v")):
        path = workdir / name
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 25.0, (WIDTH, HEIGHT))
        for f in frames:
            writer.write(f)
        writer.release()
        cap = cv2.VideoCapture(str(path))
        count = 0
        t0 = time.perf_counter()
        while True:
            ok, _ = cap.read()
            if not ok:
                break
            count += 1
        elapsed = time.perf_counter() - t0
        cap.release()
        out[fourcc] = 1e3 * elapsed / max(count, 1)
    return out


def discriminant_model(frames, fimgs, model):
    """The default observation model: appearance learned on frame 0, per-frame evidence.

    Returns ``(score(k, pts, nrm), ms per frame for the evidence)``.
    """
    x0 = np.zeros((1, 6))
    x0[0, :2] = TRUTH[0] - (320, 240)
    pts0, nrm0 = (a[0] for a in model.evaluate(x0))
    app = appearance.learn_appearance(frames[0], fimgs[0], pts0, nrm0, pts0, h=15.0, sigma=3.0, threshold=8.0)
    t0 = time.perf_counter()
    evs = [discriminant.evidence(app, f, g, TRUTH[k], 8.0) for k, (f, g) in enumerate(zip(frames, fimgs))]
    t_ev = 1e3 * (time.perf_counter() - t0) / len(frames)

    def score(k: int, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
        return discriminant.score(app, evs[k], pts, nrm, h=15.0, sigma=3.0, threshold=8.0, miss=0.1, colour_weight=3.0)

    return score, t_ev


def likelihood(score, fimgs, k: int, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """The log-likelihood of curves on frame ``k``: the discriminant's ``score``, or AC eq 12.2 without one."""
    if score is not None:
        return score(k, pts, nrm)
    return likelihoods.log_likelihood(fimgs[k], pts, nrm, h=15.0, sigma=3.0, alpha=0.02, threshold=8.0)


def run(n: int, frames, fimgs, model, dyn, n_frames: int, normals: int, seed: int, threads: int = 1,
        score=None) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    spent = {"curves": 0.0, "likelihood": 0.0}

    def loglik(x: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        pts, nrm = model.evaluate(x)
        t1 = time.perf_counter()
        ll = likelihood(score, fimgs, state["k"], pts, nrm)
        t2 = time.perf_counter()
        spent["curves"] += t1 - t0
        spent["likelihood"] += t2 - t1
        spans.append((t0, t2))  # list.append is atomic: the scoring threads may call at once
        return ll

    state = {"k": 0}
    spans: list[tuple[float, float]] = []
    start = np.zeros(6)
    start[:2] = TRUTH[0] - (320, 240)
    particles = condensation.init_gaussian(start, np.diag([10.0**2, 10.0**2, 1e-4, 1e-4, 1e-4, 1e-4]), n, rng)
    # One warm-up step (compilation, caches), then timed steps.
    particles, _ = condensation.step(particles, dyn, loglik, rng)
    spent = {"curves": 0.0, "likelihood": 0.0}
    step_times = []
    outside = []  # the part of each step when no thread is scoring: the serial part
    err = []
    for k in range(1, n_frames):
        state["k"] = k % len(fimgs)
        spans.clear()
        t0 = time.perf_counter()
        particles, info = condensation.step(particles, dyn, loglik, rng, threads=threads)
        step_times.append(time.perf_counter() - t0)
        outside.append(step_times[-1] - (max(b for _, b in spans) - min(a for a, _ in spans)))
        mean = condensation.weighted_mean(particles)
        err.append(np.hypot(*(mean[:2] + (320, 240) - TRUTH[state["k"]])))
    steps = len(step_times)
    total = sum(step_times)
    return {
        "median": 1e3 * float(np.median(step_times)),
        "mean": 1e3 * total / steps,
        "select_predict": 1e3 * (total - spent["curves"] - spent["likelihood"]) / steps,
        "curves": 1e3 * spent["curves"] / steps,
        "likelihood": 1e3 * spent["likelihood"] / steps,
        "serial": 1e3 * float(np.median(outside)),
        "error": float(np.median(err)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--sizes", default="100,300,1000,3000,10000")
    parser.add_argument("--normals", type=int, default=24)
    parser.add_argument("--repeat", type=int, default=3,
                        help="passes over all sizes; each row reports the pass with the lowest median")
    parser.add_argument("--threads", default="1,2",
                        help="thread counts of the weighting step to compare (comma separated)")
    parser.add_argument("--curves", choices=("matrix", "trackcli"), default="matrix",
                        help="curve evaluation: this script's matrix product, or trackcli's spline + shape-space")
    parser.add_argument("--likelihood", choices=("discriminant", "clutter"), default="discriminant",
                        help="observation model: the default contour discriminant with colour, or AC eq 12.2")
    parser.add_argument("--floor", action="store_true",
                        help="also time, on the same curves, loops that only read each normal's profile: how far "
                             "the likelihood is from the cost of its memory reads")
    parser.add_argument("--ceiling", action="store_true",
                        help="also run the one-thread step in two processes at once, one per CPU: the most two "
                             "threads can gain on this machine")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    rng = np.random.default_rng(1)
    frames, truth = make_frames(args.frames, rng)
    global TRUTH
    TRUTH = truth
    t0 = time.perf_counter()
    fimgs = [measure.feature_image(f, sigma=1.0, edge_sigma=1.5) for f in frames]
    t_fimg = 1e3 * (time.perf_counter() - t0) / len(frames)
    build = curve_model if args.curves == "matrix" else trackcli_curve_model
    model = build((320.0, 240.0), (40.0, 55.0), args.normals)
    dyn = dynamics()
    score, t_ev = discriminant_model(frames, fimgs, model) if args.likelihood == "discriminant" else (None, 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        decode = time_decode(frames, Path(tmp))

    print(f"curves: {args.curves}; M = {args.normals} normals, h = 15 px, Nx = 6, {args.frames} frames of {WIDTH}x{HEIGHT}")
    print(f"likelihood: {args.likelihood}")
    print(f"feature image (grey + blur sigma {np.hypot(1.0, 1.5):.2f}): {t_fimg:.2f} ms/frame")
    if score is not None:
        print(f"discriminant's per-frame evidence (colour map, clutter density): {t_ev:.2f} ms/frame")
    print("decode: " + ", ".join(f"{k} {v:.2f} ms/frame" for k, v in decode.items()))
    print()
    print(f"load average {os.getloadavg()[0]:.2f}; with several threads the curve and likelihood columns are "
          "summed over the threads")
    header = (f"{'thr':>3} {'N':>6} {'step ms':>8} {'(mean)':>7} {'sel+pred':>8} {'curves':>7} {'lik':>7} "
              f"{'serial':>7} {'ns/smp':>7} {'fps':>6} {'/N=1000':>8} {'speed-up':>8} {'err px':>7}")
    print(header)
    print("-" * len(header))
    sizes = [int(s) for s in args.sizes.split(",")]
    thread_counts = [int(t) for t in args.threads.split(",")]
    rows: dict[tuple[int, int], dict[str, float]] = {}
    # Interleaved passes: a burst of load from other processes hits one pass, not one size.
    for _ in range(args.repeat):
        for t in thread_counts:
            for n in sizes:
                r = run(n, frames, fimgs, model, dyn, args.frames, args.normals, seed=n, threads=t, score=score)
                if (t, n) not in rows or r["median"] < rows[t, n]["median"]:
                    rows[t, n] = r
    for t in thread_counts:
        for n in sizes:
            r = rows[t, n]
            ratio = f"{r['median'] / rows[t, 1000]['median']:.2f}" if (t, 1000) in rows else ""
            base = rows.get((thread_counts[0], n))
            speed = f"{base['median'] / r['median']:.2f}" if base else ""
            sel = f"{r['select_predict']:.2f}" if t == 1 else "-"  # parts overlap in time with threads
            print(f"{t:>3} {n:>6} {r['median']:>8.2f} {r['mean']:>7.2f} {sel:>8} {r['curves']:>7.2f} "
                  f"{r['likelihood']:>7.2f} {r['serial']:>7.2f} {1e6 * r['median'] / n:>7.0f} {1e3 / r['median']:>6.0f} {ratio:>8} "
                  f"{speed:>8} {r['error']:>7.1f}")
    if len(thread_counts) > 1:
        scoring(sizes, thread_counts, args, fimgs, model, score)
    if args.floor:
        floor(sizes, args, fimgs, model, score)
    if args.ceiling:
        ceiling(sizes, args, frames, fimgs, model, dyn, score, {n: rows[1, n] for n in sizes if (1, n) in rows})


def scoring(sizes, thread_counts, args, fimgs, model, score) -> None:
    """The weighting alone (``condensation.weigh``: the likelihood of every sample, the part the
    threads share) on curves evaluated beforehand: its speed-up is what the threads give
    where nothing of the step is serial."""
    rng = np.random.default_rng(0)
    best: dict[tuple[int, int], float] = {}
    for n in sizes:
        curves_of = []
        for k in range(len(fimgs)):
            x = np.zeros((n, 6))
            x[:, :2] = TRUTH[k] - (320, 240) + rng.normal(0, 10, (n, 2))
            curves_of.append(model.evaluate(x))
        index = np.arange(n, dtype=float)[:, None]  # weigh hands out blocks of these
        for _ in range(args.repeat):
            for t in thread_counts:
                times = []
                for k, (pts, nrm) in enumerate(curves_of):
                    def loglik(block: np.ndarray, pts=pts, nrm=nrm, k=k) -> np.ndarray:
                        i0, i1 = int(block[0, 0]), int(block[-1, 0]) + 1
                        return likelihood(score, fimgs, k, pts[i0:i1], nrm[i0:i1])
                    t0 = time.perf_counter()
                    condensation.weigh(index, loglik, threads=t)
                    times.append(time.perf_counter() - t0)
                med = 1e3 * float(np.median(times))
                best[t, n] = min(best.get((t, n), math.inf), med)
    print(f"\nthe weighting alone, curves evaluated beforehand (load average {os.getloadavg()[0]:.2f}):")
    header = f"{'thr':>3} {'N':>6} {'weigh ms':>9} {'ns/smp':>7} {'speed-up':>9}"
    print(header)
    print("-" * len(header))
    for t in thread_counts:
        for n in sizes:
            print(f"{t:>3} {n:>6} {best[t, n]:>9.2f} {1e6 * best[t, n] / n:>7.0f} "
                  f"{best[thread_counts[0], n] / best[t, n]:>9.2f}")


@njit(cache=False, nogil=True, fastmath={"contract"})
def _profile_reads(fimg, pts, nrm, n_prof, bilinear):  # pragma: no cover - compiled
    """The sum of every normal's ``n_prof`` profile samples (step 1 along the normal, centred on
    its base point), read bilinearly by the kernel's own loop (``kernels._profile_inside``) or
    at the pixel below and left: nothing else of the likelihood, so its time is what reading
    the profiles costs at the least.  The sums go to one slot per sample, so that no add waits
    for another."""
    w = fimg.shape[1]
    flat = fimg.reshape(-1)
    u0 = np.float32(n_prof / 2 - 0.5)
    idx = np.empty(n_prof, np.uint32)
    ax = np.empty(n_prof, np.float32)
    ay = np.empty(n_prof, np.float32)
    prof = np.empty(n_prof, np.float32)
    acc = np.zeros(n_prof, np.float32)
    for k in range(pts.shape[0]):
        px, py, nx, ny = pts[k, 0], pts[k, 1], nrm[k, 0], nrm[k, 1]
        if bilinear:
            _profile_inside(flat, w, px, py, nx, ny, u0, idx, ax, ay, prof)
        else:
            for j in range(n_prof):
                u = np.float32(j) - u0
                prof[j] = flat[uintp(np.int32(ny * u + py) * np.int32(w) + np.int32(nx * u + px))]
        for j in range(n_prof):
            acc[j] += prof[j]
    return acc.sum()


def floor(sizes, args, fimgs, model, score) -> None:
    """The likelihood of N curves against loops that only read their profiles (34 samples per
    normal, as the default model's ±15 px search reads): the lower bound of any likelihood that
    reads the feature image along every normal, on this machine."""
    n_prof = 2 * 15 + 4
    rng = np.random.default_rng(0)
    lo, hi = np.float32(n_prof), np.float32(min(WIDTH, HEIGHT) - n_prof)
    for n in sizes:
        curves_of = []
        for k in range(len(fimgs)):
            x = np.zeros((n, 6))
            x[:, :2] = TRUTH[k] - (320, 240) + rng.normal(0, 10, (n, 2))
            pts, nrm = model.evaluate(x)
            nrm32 = np.ascontiguousarray(nrm.reshape(-1, 2), dtype=np.float32)
            inside = np.clip(pts.reshape(-1, 2), lo, hi).astype(np.float32)  # the reads stay inside the frame
            curves_of.append((pts, nrm, nrm32, inside))
        fimg32 = [np.ascontiguousarray(f, dtype=np.float32) for f in fimgs]
        for bilinear in (True, False):  # compile
            _profile_reads(fimg32[0], curves_of[0][3], curves_of[0][2], n_prof, bilinear)
        best = {"likelihood": math.inf, "bilinear": math.inf, "nearest": math.inf}
        for _ in range(args.repeat):
            for name in best:
                times = []
                for k, (pts, nrm, nrm32, inside) in enumerate(curves_of):
                    t0 = time.perf_counter()
                    if name == "likelihood":
                        likelihood(score, fimgs, k, pts, nrm)
                    else:
                        _profile_reads(fimg32[k], inside, nrm32, n_prof, name == "bilinear")
                    times.append(time.perf_counter() - t0)
                best[name] = min(best[name], 1e3 * float(np.median(times)))
        reads = n * args.normals * n_prof
        print(f"\nN = {n}, one thread: {reads} profile samples (load average {os.getloadavg()[0]:.2f})")
        header = f"{'':>34} {'ms':>7} {'ns/read':>8} {'x floor':>8}"
        print(header)
        print("-" * len(header))
        for name, label in (("likelihood", "the likelihood (whole)"),
                            ("bilinear", "profile reads only, bilinear"),
                            ("nearest", "profile reads only, one pixel")):
            print(f"{label:>34} {best[name]:>7.2f} {1e6 * best[name] / reads:>8.2f} "
                  f"{best[name] / best['bilinear']:>8.2f}")


def _paired(cpu, barrier, results, sizes, args, frames, fimgs, model, dyn, score) -> None:
    """One of the two processes of :func:`ceiling`: the best median of each size into ``results``."""
    os.sched_setaffinity(0, {cpu})
    try:
        for _ in range(args.repeat):
            for n in sizes:
                barrier.wait()  # both processes step at the same time
                r = run(n, frames, fimgs, model, dyn, args.frames, args.normals, seed=n, threads=1, score=score)
                if n not in results or r["median"] < results[n]:
                    results[n] = r["median"]
    except BaseException:
        barrier.abort()  # the other process stops waiting for this one
        raise


def ceiling(sizes, args, frames, fimgs, model, dyn, score, single) -> None:
    """The one-thread step in two processes at once, each held to its own CPU (when the
    system lets a process choose its CPUs): what two cores give with nothing shared."""
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    if len(cpus) < 2:
        print("\n--ceiling: this process may use only one CPU")
        return
    ctx = multiprocessing.get_context("fork")  # the children inherit the frames and the model
    with ctx.Manager() as manager:
        barrier = ctx.Barrier(2, timeout=3600)
        results = [manager.dict(), manager.dict()]
        procs = [ctx.Process(target=_paired, args=(cpus[i], barrier, results[i], sizes, args, frames, fimgs, model,
                                                   dyn, score)) for i in range(2)]
        for p in procs:
            p.start()
        for p in procs:
            p.join()
        if any(p.exitcode for p in procs):
            print("\n--ceiling: a process failed")
            return
        results = [dict(r) for r in results]
    print(f"\ntwo processes at once, one thread each, on CPUs {cpus[0]} and {cpus[1]} (load average "
          f"{os.getloadavg()[0]:.2f}):")
    header = f"{'N':>6} {'alone ms':>9} {'pair ms':>15} {'two-process speed-up':>21}"
    print(header)
    print("-" * len(header))
    for n in sizes:
        a, b = results[0][n], results[1][n]
        alone = single[n]["median"] if n in single else float("nan")  # nan without --threads 1
        print(f"{n:>6} {alone:>9.2f} {a:>7.2f} {b:>7.2f} {4 * alone / (a + b):>21.2f}")


TRUTH = np.zeros((1, 2))

if __name__ == "__main__":
    main()
