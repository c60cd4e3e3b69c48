"""Sample paths of a learned or hand-set model (AC Fig 11.7).

Simulating a model and looking at the result is the quickest check that it has learned
the motion it was trained on: the paths should wander, oscillate and deform the way the
training object did.  Every path starts at rest at the model's template (``X = 0``), so a
stationary model is seen settling from the template into its steady state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trackcli.dynamics.model import Model
from trackcli.io.outputs import atomic_path
from trackcli.shapes.outline import contour_summary


def simulate_paths(model: Model, n_frames: int, n_paths: int, rng: np.random.Generator) -> np.ndarray:
    """``(n_paths, n_frames, Nx)`` sample paths of the model's dynamics, each from rest at the template."""
    dyn = model.dynamics
    x0 = np.zeros(dyn.nx)
    return np.stack([dyn.simulate(n_frames, rng, x0=x0) for _ in range(n_paths)])


_COLOURS = [(40, 60, 255), (40, 200, 40), (255, 120, 0), (200, 0, 200), (0, 200, 255), (120, 120, 255)]


def render_paths(model: Model, paths: np.ndarray, png: Path, *, canvas: tuple[int, int] | None = None,
                 every: int = 10, marks: list[np.ndarray] | None = None) -> Path:
    """PNG: template (grey), centroid trajectories, and the contour every ``every`` frames.

    ``marks[k]``: frames of path ``k`` to mark with a black ring on its track (e.g. the
    frames a mixed-state model's event label moved)."""
    import cv2

    space = model.space
    size = canvas or (model.template.frame_size or (640, 480))
    w, h = int(size[0]), int(size[1])
    img = np.full((h, w, 3), 255, np.uint8)

    def poly(p: np.ndarray) -> np.ndarray:
        return np.round(p * 16).astype(np.int32).reshape(-1, 1, 2)

    c0, _, _ = contour_summary(space, np.zeros(space.Nx))
    cv2.polylines(img, [poly(c0)], True, (150, 150, 150), 2, cv2.LINE_AA, shift=4)
    # All contours first, then all centroid tracks, so no path's outlines hide another's track.
    tracks = []
    for k, path in enumerate(paths):
        col = _COLOURS[k % len(_COLOURS)]
        light = tuple(int(255 - 0.45 * (255 - c)) for c in col)
        cents = []
        for t, X in enumerate(path):
            contour, c, _ = contour_summary(space, X)
            cents.append(c)
            if t % every == 0:
                cv2.polylines(img, [poly(contour)], True, light, 1, cv2.LINE_AA, shift=4)
        tracks.append((np.asarray(cents), col))
    for cents, col in tracks:
        cv2.polylines(img, [poly(cents)], False, col, 2, cv2.LINE_AA, shift=4)
    for (cents, _), frames in zip(tracks, marks or []):
        for t in frames:
            x, y = (np.round(cents[int(t)] * 16)).astype(int)
            cv2.circle(img, (int(x), int(y)), 6 * 16, (0, 0, 0), 2, cv2.LINE_AA, shift=4)
    cv2.putText(img, f"{len(paths)} paths x {paths.shape[1]} frames", (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                (0, 0, 0), 1, cv2.LINE_AA)
    ok, buf = cv2.imencode(".png", img)
    with atomic_path(png) as tmp:
        tmp.write_bytes(buf.tobytes())
    return png


def record_paths(model: Model, paths: np.ndarray, rrd: Path, *, seed: int = 0, labels: np.ndarray | None = None,
                 label_names: list[str] | None = None) -> Path:
    """Recording: each path's contour animated over the ``frame`` timeline, and its components as series.

    ``labels`` ``(n_paths, n_frames)``: a mixed-state model's label per frame, logged as a
    series ``series/label{k}`` (the index into ``label_names``, which go in the parameters)."""
    from trackcli.io.recording import Recording

    space = model.space
    tau = model.dynamics.tau
    n_paths, n_frames, _ = paths.shape
    with Recording(rrd, recording_id=f"simulate-seed{seed}", blueprint="simulate", properties={"seed": seed}) as rec:
        params = {"model_provenance": model.provenance, "paths": n_paths, "frames": n_frames, "seed": seed}
        if label_names is not None:
            params["labels"] = list(label_names)
        rec.log_params("params", params)
        c0, _, _ = contour_summary(space, np.zeros(space.Nx))
        for t in range(n_frames):
            rec.set_frame(t, t * tau)
            if t == 0:
                rec.log_contour("video/template", c0, color=(150, 150, 150), width=1.0)
            for k in range(n_paths):
                contour, c, _ = contour_summary(space, paths[k, t])
                rec.log_contour(f"video/path{k}", contour, color=_COLOURS[k % len(_COLOURS)][::-1], width=1.5)
        frames = np.arange(n_frames)
        for k in range(n_paths):
            rec.send_series(f"series/path{k}", frames, frames * tau, paths[k], names=list(space.names),
                            unit="shape vector")
            if labels is not None:
                rec.send_series(f"series/label{k}", frames, frames * tau, labels[k].astype(float),
                                names=f"label of path {k}", unit="label")
    return rrd
