"""Results in the formats other tools read: per-frame masks (DAVIS PNGs) and VOT region lines.

Video-object-segmentation benchmarks exchange one mask per frame; VOT's toolkit reads one
region per line.  Both are made from the estimated outline of each frame (a closed curve in
image pixels, ``x`` right, ``y`` down, pixel ``(i, j)`` centred at ``x = j, y = i``):

- **masks** (:class:`MaskSink`): one PNG per frame, named as the frame (``00042.png`` for
  ``00042.jpg``; for a video file the index in five digits), the outline filled
  (:func:`trackcli.run.masks.outline_mask`): 0 background and 255 object, or with ``palette``
  an 8-bit palette image with the object at index 1 (DAVIS-2017 style).  A frame without an
  outline gets an empty mask.  The folder is written as ``.NAME.part`` and renamed into place
  when complete; an existing folder is replaced only if trackcli wrote it (it holds the
  hidden file :data:`MASK_FOLDER_MARK`) or it is empty.
- **VOT region lines** (:class:`VotSink`): one line per frame, the outline's polygon
  ``x1,y1,x2,y2,...`` (VOT's polygon region, at 0.01 px), or ``0`` for a frame without an
  outline (VOT's code for "no region").

Both are sinks of the frame loop (:class:`trackcli.run.sinks.Sink`): ``trackcli track --masks``
and ``batch`` give them to the run (:func:`export_sinks`), and they write each frame's outline
as the tracker makes it (the refined outline, else the estimate's curve); ``close`` commits
them with the run's other outputs.  :func:`export_track` feeds them from the outline columns
of a track CSV written earlier (``trackcli render --masks``).
"""

from __future__ import annotations

import logging
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from trackcli.errors import ConfigError, InputError
from trackcli.io.outputs import atomic_path, ensure_dir, partial_name
from trackcli.run.masks import encode_mask_png, outline_mask
from trackcli.run.sinks import Sink

log = logging.getLogger(__name__)


def _outline_of(result: Any) -> np.ndarray | None:
    out = getattr(result, "outline", None)
    return getattr(result, "contour", None) if out is None else out


class MaskSink(Sink):
    """Per-frame mask PNGs in a folder (see the module docstring); a sink of the frame loop.

    Parameters
    ----------
    folder : path
        The output folder.
    size : (width, height)
        The frames' size.
    name : callable
        Frame index -> file name without suffix (:meth:`trackcli.io.video.Video.frame_name`).
    palette : bool
        Palette PNGs (object at index 1) instead of grey 0/255.
    """

    def __init__(self, folder: str | os.PathLike[str], size: tuple[int, int], name: Callable[[int], str], *,
                 palette: bool = False) -> None:
        self.folder = Path(folder)
        _check_mask_folder(self.folder)
        self.tmp = partial_name(self.folder)
        shutil.rmtree(self.tmp, ignore_errors=True)
        ensure_dir(self.tmp)
        (self.tmp / MASK_FOLDER_MARK).write_text("masks written by trackcli; the folder is replaced when they are "
                                                  "written again\n", encoding="utf-8")
        self.shape = (int(size[1]), int(size[0]))
        self._name = name
        self._palette = palette
        self.written = 0

    def write(self, index: int, outline: np.ndarray | None) -> None:
        """Write frame ``index``'s mask: ``outline`` (P, 2) filled, or empty when None or NaN."""
        mask = (outline_mask(outline, self.shape) if outline is not None
                else np.zeros(self.shape, dtype=bool))
        try:
            (self.tmp / f"{self._name(int(index))}.png").write_bytes(encode_mask_png(mask, palette=self._palette))
        except OSError as exc:
            raise InputError(f"{self.folder}: cannot write masks ({exc.strerror or exc})") from None
        self.written += 1

    def frame(self, frame: Any, result: Any) -> None:
        self.write(result.index, _outline_of(result))

    def close(self, error: BaseException | None = None) -> None:
        """Rename the folder into place (``error`` None), or remove what was written."""
        if error is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return
        if self.folder.exists():
            shutil.rmtree(self.folder)
        os.replace(self.tmp, self.folder)


#: A hidden file in every mask folder trackcli writes: only such a folder (or an empty one) is
#: ever replaced, so that a folder of annotations or frames given by mistake is never lost.
MASK_FOLDER_MARK = ".trackcli-masks"


def _check_mask_folder(folder: Path) -> None:
    """Refuse to replace a folder that trackcli did not write (see :data:`MASK_FOLDER_MARK`)."""
    if not folder.exists():
        return
    if not folder.is_dir():
        raise InputError(f"{folder}: exists and is not a folder")
    if (folder / MASK_FOLDER_MARK).is_file() or not any(folder.iterdir()):
        return
    raise InputError(f"{folder}: the folder exists and holds files trackcli did not write (annotations? "
                     "frames?); choose another folder for the masks")


def check_export_outputs(masks: str | os.PathLike[str] | None, vot: str | os.PathLike[str] | None, *,
                         inputs: dict[str, Any] | None = None) -> None:
    """Refuse, before any work, a mask folder trackcli would not replace and a region file that
    names an input or a folder (one-line errors)."""
    from trackcli.io.outputs import check_output_folders, refuse_overwriting_inputs

    if masks is not None:
        _check_mask_folder(Path(masks))
    if vot is not None:
        if Path(vot).is_dir():
            raise InputError(f"{vot}: is a folder; give the region file's name")
        refuse_overwriting_inputs({"--vot": vot}, dict(inputs or {}))
        check_output_folders(vot)


class VotSink(Sink):
    """VOT region lines, one per frame, written atomically (see the module docstring); a sink of the frame loop."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise InputError(f"{self.path}: is a folder; give the region file's name")
        self.lines: list[str] = []

    def write(self, index: int, outline: np.ndarray | None) -> None:
        p = None if outline is None else np.asarray(outline, dtype=float).reshape(-1, 2)
        if p is None or len(p) < 3 or not np.all(np.isfinite(p)):
            self.lines.append("0")
        else:
            self.lines.append(",".join(f"{v:.2f}" for v in p.ravel()))

    def frame(self, frame: Any, result: Any) -> None:
        self.write(result.index, _outline_of(result))

    def close(self, error: BaseException | None = None) -> None:
        if error is None:
            with atomic_path(self.path) as tmp:
                tmp.write_text("\n".join(self.lines) + "\n", encoding="utf-8")


def export_sinks(masks: str | os.PathLike[str] | None, vot: str | os.PathLike[str] | None, *,
                 palette: bool = False) -> Callable[[Any], list[Sink]]:
    """The sinks that write a run's masks and VOT region lines, made from the opened clip (the
    ``sinks`` of :func:`trackcli.run.clips.track_clip`)."""
    def make(video: Any) -> list[Sink]:
        out: list[Sink] = []
        if masks is not None:
            out.append(MaskSink(masks, (video.width, video.height), video.frame_name, palette=palette))
        if vot is not None:
            out.append(VotSink(vot))
        return out
    return make


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export_track` wrote: the folder of masks and the region file (None if not asked), and how many frames."""

    masks: Path | None
    vot: Path | None
    frames: int

    def line(self) -> str:
        """``masks -> DIR, VOT regions -> FILE (N frames)``: what a command prints."""
        parts = ([f"masks -> {self.masks}"] if self.masks else []) + ([f"VOT regions -> {self.vot}"] if self.vot else [])
        return f"{', '.join(parts)} ({self.frames} frames)"


def export_track(track_csv: str | os.PathLike[str], clip: str | os.PathLike[str], *,
                 masks: str | os.PathLike[str] | None = None, vot: str | os.PathLike[str] | None = None,
                 palette: bool = False, fps: float | None = None,
                 warn: Callable[[str], None] | None = None) -> ExportResult:
    """Masks and/or VOT region lines of every frame of a track CSV, from its outline columns.

    ``clip`` (the video file or image folder the track was made on) gives the frames' size and
    names.  The track must fit the clip (:func:`trackcli.run.checks.check_track_on_clip`);
    notes about estimates that do not fit its frames go to ``warn`` (default: the log).

    Raises
    ------
    ConfigError
        Neither ``masks`` nor ``vot`` is given.
    InputError
        The CSV has no outline columns; the mask folder holds other files.
    DataError
        The track has frames the clip does not have.
    """
    from trackcli.io.tracks import read_outlines
    from trackcli.io.video import open_video
    from trackcli.run.checks import check_track_on_clip

    if masks is None and vot is None:
        raise ConfigError("nothing to export: give a mask folder, a VOT region file or both")
    frames, outlines, _ = read_outlines(track_csv)
    with open_video(clip, fps=fps) as video:
        for note in check_track_on_clip(frames, outlines, width=video.width, height=video.height,
                                        n_frames=video.n_total, track=str(track_csv), clip=str(clip)):
            (warn or log.warning)(note)
        sinks: list[Any] = []
        try:
            if masks is not None:
                sinks.append(MaskSink(masks, (video.width, video.height), video.frame_name, palette=palette))
            if vot is not None:
                sinks.append(VotSink(vot))
            for f, o in zip(frames, outlines):
                for s in sinks:
                    s.write(int(f), o)
        except BaseException as exc:
            for s in sinks:
                s.close(exc)
            raise
        for s in sinks:
            s.close(None)
    return ExportResult(Path(masks) if masks is not None else None, Path(vot) if vot is not None else None,
                        len(frames))


__all__ = ["ExportResult", "MASK_FOLDER_MARK", "MaskSink", "VotSink", "check_export_outputs", "export_sinks",
           "export_track"]
