"""Pictures of a track: the estimated outline drawn on the clip's frames.

Everything drawn comes from the track CSV (see :mod:`trackcli.io.tracks`): the outline columns
``outline_x*, outline_y*`` (no shape-space, model or template needed), the centroid
``cx, cy``, the tracker's ``lost`` verdict and, when present, a ``confidence`` column.
Optionally the ground-truth box of a truth file (anything ``trackcli eval`` reads) is drawn
too.  The frames come from the clip through :func:`trackcli.io.video.open_video`, so video files
and image folders work alike.

Three products, each written atomically (an interrupted run leaves nothing half-written):

- a video, one frame per selected frame: an ``.mp4`` is H.264 (High profile, 4:2:0, even
  sides, index at the front) written with PyAV (:class:`trackcli.io.encode.H264Writer`),
  which plays in browsers and common players and encodes faster than the tracker tracks;
  OpenCV's VP9 (or MPEG-4 part 2) only when PyAV's H.264 encoder is missing; ``.avi``
  is Motion JPEG, ``.mkv``/``.webm`` VP9 and ``.mov``/``.m4v`` MPEG-4 part 2, through OpenCV;
- a folder of PNG frames ``frame_000123.png`` (the original frame index);
- a contact sheet: N frames spread evenly over the selection, shrunk and tiled into one PNG,
  each labelled with its frame number.

Colours (BGR): estimate orange-red, ground truth green, "lost" frames with the outline dashed
in grey.

A track must fit the clip it is drawn on (:func:`trackcli.run.checks.check_track_on_clip`): one
with frames past the clip's last is refused, and estimates that lie outside its frames, or all
in a corner of them (a track made on a smaller clip), are warned about.  Masks and VOT region
lines of a track CSV are written by :func:`trackcli.run.export.export_track`.
"""

from __future__ import annotations

import csv
import logging
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from trackcli.errors import ConfigError, DataError, InputError
from trackcli.io.outputs import ensure_dir, partial_name

log = logging.getLogger(__name__)

ESTIMATE_BGR = (40, 60, 255)
LOST_BGR = (160, 160, 160)
TRUTH_BGR = (60, 200, 40)
TEXT_BGR = (255, 255, 255)

#: Codecs tried, in order, for an MP4 through OpenCV (fourcc), when PyAV's H.264 encoder is missing.
VIDEO_CODECS = ("vp09", "mp4v")
#: the codecs tried for an ``.avi`` output (an AVI holds no VP9: OpenCV would print its fallback)
AVI_CODECS = ("MJPG", "XVID")
#: the codecs tried for each ending of a video output, in order (OpenCV's FFmpeg names VP9 "VP90"
#: in Matroska and WebM and "vp09" in MP4, and prints a fallback line for the other name; a
#: QuickTime or M4V file holds no VP9 here)
SUFFIX_CODECS = {".mp4": VIDEO_CODECS, ".avi": AVI_CODECS, ".mkv": ("VP90", "mp4v"), ".webm": ("VP90",),
                 ".mov": ("mp4v",), ".m4v": ("mp4v",)}
#: the endings of a video output this OpenCV writes
VIDEO_SUFFIXES = tuple(SUFFIX_CODECS)


@dataclass(frozen=True)
class TrackOutlines:
    """What :func:`load_track_outlines` reads from a track CSV, indexed by row.

    Attributes
    ----------
    frame : ndarray of shape (T,), int
    outline : ndarray of shape (T, P, 2)
        NaN where a row has no outline.
    closed : ndarray of shape (T,), bool
    centroid : ndarray of shape (T, 2)
    lost : ndarray of shape (T,), bool
    confidence : ndarray of shape (T,) or None
        The ``confidence`` column when the file has one.
    """

    frame: np.ndarray
    outline: np.ndarray
    closed: np.ndarray
    centroid: np.ndarray
    lost: np.ndarray
    confidence: np.ndarray | None

    def row_of(self) -> dict[int, int]:
        return {int(f): k for k, f in enumerate(self.frame)}


def load_track_outlines(path: str | os.PathLike[str]) -> TrackOutlines:
    """Read the outline and the per-frame labels of a track CSV, columns found by name."""
    from trackcli.io.tracks import read_outlines

    p = Path(path)
    frames, outlines, closed = read_outlines(p)
    with open(p, newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.DictReader(fh) if r.get("frame", "").strip()]

    def column(name: str) -> np.ndarray | None:
        if not rows or name not in rows[0]:
            return None
        out = np.full(len(rows), np.nan)
        for k, r in enumerate(rows):
            cell = (r.get(name) or "").strip()
            try:
                out[k] = float(cell) if cell else np.nan
            except ValueError:
                raise InputError(f"{p} line {k + 2}: {name} must be a number, got {cell!r}") from None
        return out

    cx, cy, lost = column("cx"), column("cy"), column("lost")
    centroid = (np.column_stack([cx, cy]) if cx is not None and cy is not None
                else np.nanmean(outlines, axis=1))
    return TrackOutlines(frames, outlines, closed, centroid,
                         np.zeros(len(frames), bool) if lost is None else lost == 1,
                         column("confidence"))


def default_selection(frames: np.ndarray) -> tuple[int, int, int]:
    """``(start, end, step)`` covering a track's frames: first, last + 1, and their spacing."""
    f = np.asarray(frames, dtype=int)
    step = int(np.gcd.reduce(np.diff(f))) if f.size > 1 else 1
    return int(f.min()), int(f.max()) + 1, max(step, 1)


def sheet_indices(indices: range | list[int], n: int) -> list[int]:
    """``n`` frame indices spread evenly over ``indices`` (first and last included)."""
    idx = list(indices)
    if n < 1:
        raise ConfigError(f"a contact sheet needs at least 1 frame, got {n}")
    if not idx:
        raise DataError("no frames selected")
    if n >= len(idx):
        return idx
    picks = np.rint(np.linspace(0, len(idx) - 1, n)).astype(int)
    return [idx[i] for i in dict.fromkeys(picks.tolist())]


# ---------------------------------------------------------------------------------------------
# Drawing


def _dashed(img: np.ndarray, pts: np.ndarray, closed: bool, colour, width: int) -> None:
    import cv2

    p = np.vstack([pts, pts[:1]]) if closed else pts
    for k in range(0, len(p) - 1, 2):
        a, b = p[k], p[k + 1]
        cv2.line(img, tuple(np.rint(a).astype(int)), tuple(np.rint(b).astype(int)), colour, width, cv2.LINE_AA)


def draw_frame(image: np.ndarray, index: int, track: TrackOutlines, row: int | None, *,
               truth_box: np.ndarray | None = None, label: bool = True, width: int = 2) -> np.ndarray:
    """A copy of ``image`` (BGR) with the estimate of track row ``row`` (None: no estimate) drawn."""
    import cv2

    out = image.copy()
    if truth_box is not None and np.all(np.isfinite(truth_box)):
        x, y, w, h = truth_box
        cv2.rectangle(out, (int(round(x)), int(round(y))), (int(round(x + w)), int(round(y + h))),
                      TRUTH_BGR, max(1, width // 2), cv2.LINE_AA)
    if row is not None:
        pts = track.outline[row]
        lost = bool(track.lost[row])
        if np.all(np.isfinite(pts)):
            if lost:
                _dashed(out, pts, bool(track.closed[row]), LOST_BGR, width)
            else:
                shift = 4
                q = np.rint(pts * (1 << shift)).astype(np.int32)
                cv2.polylines(out, [q], bool(track.closed[row]), ESTIMATE_BGR, width, cv2.LINE_AA, shift)
        c = track.centroid[row]
        if np.all(np.isfinite(c)):
            cv2.circle(out, (int(round(c[0])), int(round(c[1]))), 3, LOST_BGR if lost else ESTIMATE_BGR, -1,
                       cv2.LINE_AA)
    if label:
        _label(out, _frame_text(index, track, row), (6, 6))
    return out


def _frame_text(index: int, track: TrackOutlines, row: int | None, *, short: bool = False) -> str:
    """A frame's label: its number, the confidence and LOST (``short``: a contact sheet's tile)."""
    text = f"{index}" if short else f"frame {index}"
    if row is None:
        return text if short else text + "  (no estimate)"
    if track.confidence is not None and np.isfinite(track.confidence[row]):
        text += f" {track.confidence[row]:.2f}" if short else f"  conf {track.confidence[row]:.2f}"
    return text + ("  LOST" if track.lost[row] else "")


def _label(img: np.ndarray, text: str, org: tuple[int, int], scale: float | None = None) -> None:
    import cv2

    scale = scale or max(0.4, min(img.shape[1] / 900.0, 1.2))
    (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    x, y = org
    cv2.rectangle(img, (x, y), (x + w + 8, y + h + base + 6), (0, 0, 0), -1)
    cv2.putText(img, text, (x + 4, y + h + 3), cv2.FONT_HERSHEY_SIMPLEX, scale, TEXT_BGR, 1, cv2.LINE_AA)


def contact_sheet(tiles: list[np.ndarray], *, columns: int | None = None, gap: int = 4) -> np.ndarray:
    """Tile equally sized BGR images into one, row by row, on a dark background."""
    if not tiles:
        raise DataError("a contact sheet needs at least one frame")
    h, w = tiles[0].shape[:2]
    cols = columns or min(len(tiles), max(1, math.ceil(math.sqrt(len(tiles) * 4 / 3))))
    rows = math.ceil(len(tiles) / cols)
    sheet = np.full((rows * h + (rows + 1) * gap, cols * w + (cols + 1) * gap, 3), 30, dtype=np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cols)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        sheet[y:y + h, x:x + w] = t
    return sheet


# ---------------------------------------------------------------------------------------------
# Writers


class _VideoOut:
    """A video written under a temporary name and renamed into place on success: H.264 through
    PyAV for an ``.mp4`` (when PyAV has the encoder), else OpenCV's codecs for the ending."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int]):
        import cv2

        self.path = path
        ensure_dir(path.parent)
        if path.is_dir():
            raise InputError(f"{path}: is a folder; give the video's file name (or --png for a folder of frames)")
        self.tmp = path.with_name(f".{path.stem}.part{path.suffix}")
        try:  # OpenCV only says it could not open the writer: find out why first
            self.tmp.touch()
        except OSError as exc:
            raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
        self.codec = None
        self._h264 = None
        if path.suffix.lower() == ".mp4":
            from trackcli.io.encode import EncoderUnavailable, H264Writer

            try:
                self._h264 = H264Writer(path, fps, size)
                self.codec = H264Writer.codec
                return
            except EncoderUnavailable as exc:
                log.warning("%s: %s; writing the MP4 with OpenCV instead (VP9, which some players cannot play)",
                            path, exc)
        codecs = SUFFIX_CODECS.get(path.suffix.lower(), VIDEO_CODECS)
        for code in codecs:
            writer = cv2.VideoWriter(str(self.tmp), cv2.VideoWriter_fourcc(*code), fps, size)
            if writer.isOpened():
                self.writer, self.codec = writer, code
                break
            writer.release()
        if self.codec is None:
            self.tmp.unlink(missing_ok=True)
            raise DataError(f"{path}: OpenCV cannot write this video here (tried {', '.join(codecs)})")

    def write(self, image: np.ndarray) -> None:
        if self._h264 is not None:
            self._h264.write(image)
        else:
            self.writer.write(image)

    def close(self, ok: bool) -> None:
        if self._h264 is not None:
            self._h264.close(ok)
            return
        self.writer.release()
        if ok:
            os.replace(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)


def _write_png(path: Path, image: np.ndarray) -> None:
    import cv2

    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise DataError(f"{path}: PNG encoding failed")
    path.write_bytes(buf.tobytes())


@dataclass(frozen=True)
class RenderResult:
    """What :func:`render` wrote."""

    output: Path
    kind: str  # "video" | "frames" | "sheet"
    frames: int
    with_estimate: int
    codec: str | None = None


def render(
    track_csv: str | os.PathLike[str],
    clip: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    kind: str = "video",
    sheet_frames: int = 12,
    tile_width: int = 240,
    truth: Any = None,
    fps: float | None = None,
    start: int | None = None,
    end: int | None = None,
    step: int | None = None,
    label: bool = True,
    progress: Callable[[int], None] | None = None,
    on_open: Callable[[int], None] | None = None,
    warn: Callable[[str], None] | None = None,
) -> RenderResult:
    """Draw the track of ``track_csv`` on the frames of ``clip`` and write ``output``.

    Parameters
    ----------
    track_csv : path
        A track CSV with outline columns.
    clip : path
        The video file or image folder the track was made on.
    output : path
        The MP4 (``kind="video"``), the folder of PNGs (``"frames"``) or the PNG (``"sheet"``).
    kind : {"video", "frames", "sheet"}
    sheet_frames : int
        Frames on the contact sheet.
    tile_width : int
        Width (px) of each contact-sheet tile; the frames are shrunk (never enlarged) to it.
    truth : GroundTruth, optional
        Its box is drawn on every frame it has.
    fps, start, end, step : optional
        Frame selection as in ``trackcli track``; by default the track's own frames.
    label : bool
        Write the frame number (and LOST, confidence) on each frame.
    progress : callable, optional
        Called with 1 per frame read.
    on_open : callable, optional
        Called once with the number of frames that will be read (to size a progress bar).
    warn : callable, optional
        Called with each one-line note about a track that does not fit the clip (default: the log).

    Raises
    ------
    InputError
        The CSV has no outline columns; the output folder exists with other files in it.
    DataError
        The track has frames past the clip's last.
    ConfigError
        A bad selection or option.
    VideoError
        The clip cannot be read.
    """
    import cv2

    from trackcli.io.video import open_video

    if kind not in ("video", "frames", "sheet"):
        raise ConfigError(f"kind: expected video, frames or sheet, got {kind!r}")
    track = load_track_outlines(track_csv)
    d_start, d_end, d_step = default_selection(track.frame)
    sel_start = d_start if start is None else start
    sel_end = d_end if end is None and start is None else end
    sel_step = (d_step if start is None and end is None else 1) if step is None else step
    rows = track.row_of()
    out = Path(output)
    truth_rows = None
    if truth is not None:
        truth_rows = {int(f): k for k, f in enumerate(truth.frame)}

    with open_video(clip, fps=fps, start=sel_start, end=sel_end, step=sel_step) as video:
        wanted = set(sheet_indices(video.indices, sheet_frames)) if kind == "sheet" else None
        if not any(int(i) in rows for i in video.indices):
            raise DataError(f"{track_csv} has no estimate in the selected frames "
                            f"{video.indices.start}-{video.indices.stop - 1} of {clip}; "
                            f"the track covers frames {d_start}-{d_end - 1}")
        from trackcli.run.checks import check_track_on_clip

        for note in check_track_on_clip(track.frame, track.outline, width=video.width, height=video.height,
                                        n_frames=video.n_total, track=str(track_csv), clip=str(clip)):
            (warn or log.warning)(note)
        if on_open is not None:
            on_open(len(video))
        scale = min(1.0, tile_width / video.width) if kind == "sheet" else 1.0
        line = max(2, int(round(2 / scale)))
        writer: _VideoOut | None = None
        tmp_dir: Path | None = None
        tiles: list[np.ndarray] = []
        n = n_est = 0
        ok = False
        try:
            if kind == "video":
                writer = _VideoOut(out, video.fps / sel_step, (video.width, video.height))
            elif kind == "frames":
                _check_frames_dir(out)
                tmp_dir = partial_name(out)
                shutil.rmtree(tmp_dir, ignore_errors=True)
                ensure_dir(tmp_dir)
            for frame in video:
                if progress is not None:
                    progress(1)
                if wanted is not None and frame.index not in wanted:
                    continue
                row = rows.get(int(frame.index))
                box = None
                if truth_rows is not None and int(frame.index) in truth_rows:
                    k = truth_rows[int(frame.index)]
                    box = truth.box[k] if truth.present[k] else None
                img = draw_frame(frame.image, frame.index, track, row, truth_box=box,
                                 label=label and kind != "sheet", width=line)
                n += 1
                n_est += row is not None
                if writer is not None:
                    writer.write(img)
                elif tmp_dir is not None:
                    _write_png(tmp_dir / f"frame_{frame.index:06d}.png", img)
                else:
                    tile = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else img
                    if label:
                        _label(tile, _frame_text(frame.index, track, row, short=True), (3, 3), 0.4)
                    tiles.append(tile)
            if kind == "sheet":
                from trackcli.io.outputs import atomic_path

                with atomic_path(out) as tmp:
                    ok_png, buf = cv2.imencode(".png", contact_sheet(tiles), [cv2.IMWRITE_PNG_COMPRESSION, 9])
                    if not ok_png:
                        raise DataError(f"{out}: PNG encoding failed")
                    tmp.write_bytes(buf.tobytes())
            ok = True
        finally:
            if writer is not None:
                writer.close(ok)
            if tmp_dir is not None:
                if ok:
                    if out.exists():
                        shutil.rmtree(out)
                    os.replace(tmp_dir, out)
                else:
                    shutil.rmtree(tmp_dir, ignore_errors=True)
    return RenderResult(out, kind, n, int(n_est), writer.codec if writer is not None else None)


def _check_frames_dir(out: Path) -> None:
    """A PNG-frames folder may be replaced only if it holds nothing but PNG frames."""
    if out.exists():
        if not out.is_dir():
            raise InputError(f"{out}: exists and is not a folder")
        other = [p.name for p in out.iterdir() if not (p.name.startswith("frame_") and p.suffix == ".png")]
        if other:
            raise InputError(f"{out}: folder holds other files than frame PNGs ({other[0]}, ...); "
                             "choose another folder")


def default_output(track_csv: str | os.PathLike[str], kind: str) -> Path:
    """Beside the CSV: ``NAME.mp4``, ``NAME_frames/`` or ``NAME.sheet.png`` for ``NAME.csv``."""
    p = Path(track_csv)
    stem = p.name[:-4] if p.name.lower().endswith(".csv") else p.name
    return p.with_name({"video": f"{stem}.mp4", "frames": f"{stem}_frames", "sheet": f"{stem}.sheet.png"}[kind])


__all__ = ["RenderResult", "TrackOutlines", "contact_sheet", "default_output", "default_selection", "draw_frame",
           "load_track_outlines", "render", "sheet_indices"]
