"""Rendering a clip and writing its video, truth and outline files atomically."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np

from trackcli.io.outputs import partial_name, write_text
from trackcli.errors import ConfigError, InputError, VideoError
from trackcli.sample_data.clip_bouncing_ball import _build_bouncing_ball
from trackcli.sample_data.clip_test import _build_test
from trackcli.sample_data.clip_three_heads import _build_three_heads
from trackcli.sample_data.clip_train import _build_train
from trackcli.sample_data.common import CLIP_NAMES, DEFAULT_SEED, FPS, FRAME_SIZE, Progress, _COLUMN_TEXT, _DEFAULT_FRAMES, log
from trackcli.sample_data.scene import _Scene, _render, _scene_truth
from trackcli.sample_data.truth import Truth


_BUILDERS: dict[str, Callable[[int, int], _Scene]] = {
    "train": _build_train,
    "test": _build_test,
    "three_heads": _build_three_heads,
    "bouncing_ball": _build_bouncing_ball,
}


# =============================================================================================
# Public entry points


def default_n_frames(clip: str) -> int:
    """Number of frames of the full-length ``clip``."""
    return _DEFAULT_FRAMES[_check_clip(clip)]


def _check_clip(clip: str) -> str:
    if clip not in _BUILDERS:
        raise ConfigError(f"unknown clip {clip!r}; valid clips are {', '.join(CLIP_NAMES)}")
    return clip


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_n_frames(n_frames, clip: str) -> int:
    if n_frames is None:
        return _DEFAULT_FRAMES[clip]
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise ConfigError(f"n_frames must be a positive integer or None, got {n_frames!r}")
    return int(n_frames)


def _scene(clip: str, seed: int, n_frames: int | None) -> _Scene:
    clip = _check_clip(clip)
    return _BUILDERS[clip](_check_seed(seed), _check_n_frames(n_frames, clip))


def clip_truth(clip: str, *, seed: int = DEFAULT_SEED, n_frames: int | None = None) -> Truth:
    """Ground truth of a clip without rendering it (as written to ``<clip>.truth.csv``)."""
    return _scene_truth(_scene(clip, seed, n_frames))


def render_frames(clip: str, *, seed: int = DEFAULT_SEED, n_frames: int | None = None) -> Iterator[np.ndarray]:
    """The frames of a clip, before video encoding.

    Yields
    ------
    ndarray of shape (360, 480, 3), uint8, BGR
    """
    scene = _scene(clip, seed, n_frames)
    for k in range(scene.n_frames):
        yield _render(scene, k)


def _outline_json(scene: _Scene, video_name: str) -> str:
    doc = {
        "format": 1,
        "description": (
            "Base outline of the objects of this clip, in object coordinates (pixels at scale 1, "
            "x right, y down), centred on its area centroid, counter-clockwise as seen on the "
            "screen (signed shoelace area in (x, y) is negative). In frame k, object j is bounded "
            "by p_image = scale * R(angle) @ p + (tx, ty), R(a) = [[cos a, -sin a], [sin a, cos a]], "
            "with tx, ty, angle, scale from the row of <clip>.truth.csv for frame k and object j."
        ),
        "clip": {
            "name": scene.name,
            "video": video_name,
            "truth": f"{scene.name}.truth.csv",
            "fps": FPS,
            "width": FRAME_SIZE[0],
            "height": FRAME_SIZE[1],
            "n_frames": scene.n_frames,
            "seed": scene.seed,
            "objects": list(scene.objects),
        },
        "columns": _COLUMN_TEXT,
        "motion": scene.motion,
        "n_points": int(scene.base.shape[0]),
        "points": [[float(x) + 0.0, float(y) + 0.0] for x, y in np.round(scene.base, 4)],
    }
    return json.dumps(doc, indent=1, ensure_ascii=False) + "\n"


_CODECS = (("vp09", ".mp4"), ("MJPG", ".avi"))


def _write_video(scene: _Scene, outdir: Path, progress: Progress | None) -> Path:
    W, H = FRAME_SIZE
    for fourcc, ext in _CODECS:
        final = outdir / f"{scene.name}{ext}"
        tmp = partial_name(final, keep_suffix=True)
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), FPS, (W, H))
        if writer.isOpened():
            break
        writer.release()
        tmp.unlink(missing_ok=True)
        log.warning("OpenCV cannot write %s%s here; trying the next codec", fourcc, ext)
    else:
        raise VideoError(f"OpenCV can write none of {', '.join(f + e for f, e in _CODECS)} in {outdir}")
    try:
        for k in range(scene.n_frames):
            writer.write(_render(scene, k))
            if progress is not None:
                progress(scene.name, k, scene.n_frames)
        writer.release()
        _check_readback(tmp, scene.n_frames)
        os.replace(tmp, final)
    except BaseException:
        writer.release()
        tmp.unlink(missing_ok=True)
        raise
    return final


def _check_readback(path: Path, n_frames: int) -> None:
    cap = cv2.VideoCapture(str(path))
    try:
        count = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            if frame.shape[:2] != FRAME_SIZE[::-1]:
                raise VideoError(f"{path}: frame {count} reads back as {frame.shape}, expected {FRAME_SIZE[::-1]}")
            count += 1
    finally:
        cap.release()
    if count != n_frames:
        raise VideoError(f"{path}: wrote {n_frames} frames but {count} read back")


def write_clip(
    clip: str,
    outdir,
    *,
    seed: int = DEFAULT_SEED,
    n_frames: int | None = None,
    truth_only: bool = False,
    progress: Progress | None = None,
) -> list[Path]:
    """Write one clip, its truth CSV and its outline JSON into ``outdir``.

    Parameters
    ----------
    clip : str
        One of :data:`CLIP_NAMES`.
    outdir : str or os.PathLike
        Created if missing.  Each file is written to a temporary name in the folder and
        renamed into place.
    seed : int
        Non-negative seed; the same seed gives byte-identical truth and outline files.
    n_frames : int, optional
        Shorten (or lengthen) the clip; a shortened clip is the start of the full one.
    truth_only : bool
        Write only the truth and outline files (fast: nothing is rendered).
    progress : callable, optional
        Called as ``progress(clip, frame_index, n_frames)`` after each frame is written.

    Returns
    -------
    list of Path
        ``[video, truth, outline]`` (without the video when ``truth_only``).
    """
    scene = _scene(clip, seed, n_frames)
    out = Path(outdir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create output folder {out}: {exc.strerror or exc}") from None
    paths = []
    if truth_only:
        video_name = next((f"{clip}{e}" for _, e in _CODECS if (out / f"{clip}{e}").exists()), f"{clip}.mp4")
    else:
        video = _write_video(scene, out, progress)
        paths.append(video)
        video_name = video.name
    truth_path = out / f"{clip}.truth.csv"
    outline_path = out / f"{clip}.outline.json"
    write_text(truth_path, _scene_truth(scene).to_csv())
    write_text(outline_path, _outline_json(scene, video_name))
    return paths + [truth_path, outline_path]


def make_train(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
               progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``train``: gentle AR(2) motion over a clean background (see :func:`write_clip`)."""
    return write_clip("train", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only, progress=progress)


def make_test(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
              progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``test``: agile motion over heavy clutter, with an occluding pole (see :func:`write_clip`)."""
    return write_clip("test", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only, progress=progress)


def make_three_heads(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
                     progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``three_heads``: two still heads, one walking in front (see :func:`write_clip`)."""
    return write_clip("three_heads", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only,
                      progress=progress)  # fmt: skip


def make_bouncing_ball(outdir, *, seed: int = DEFAULT_SEED, n_frames: int | None = None, truth_only: bool = False,
                       progress: Progress | None = None) -> list[Path]:  # fmt: skip
    """Write ``bouncing_ball``: ballistic flight with bounces (see :func:`write_clip`)."""
    return write_clip("bouncing_ball", outdir, seed=seed, n_frames=n_frames, truth_only=truth_only,
                      progress=progress)  # fmt: skip


def generate(
    outdir,
    *,
    seed: int = DEFAULT_SEED,
    clips: Sequence[str] | None = None,
    progress: Progress | None = None,
    n_frames: int | None = None,
    truth_only: bool = False,
) -> list[Path]:
    """Write the sample clips with their ground truth into ``outdir``.

    Parameters
    ----------
    outdir : str or os.PathLike
    seed : int
        Seed of every clip (each clip uses its own stream derived from it).
    clips : sequence of str, optional
        Which of :data:`CLIP_NAMES` to write; all by default.
    progress : callable, optional
        ``progress(clip, frame_index, n_frames)``, called after each frame is written.
    n_frames : int, optional
        Frame count for every selected clip instead of its default length.
    truth_only : bool
        Write only the truth and outline files.

    Returns
    -------
    list of Path
        The files written, clip by clip.
    """
    if isinstance(clips, str):
        clips = [clips]
    names = list(CLIP_NAMES if clips is None else clips)
    for name in names:
        _check_clip(name)
    _check_seed(seed)
    paths: list[Path] = []
    for name in names:
        paths += write_clip(name, outdir, seed=seed, n_frames=n_frames, truth_only=truth_only,
                            progress=progress)  # fmt: skip
    return paths
