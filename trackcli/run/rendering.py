"""``trackcli render``: a track drawn on its clip, with the checks that keep the output off its inputs.

:func:`render_track` picks the output (default beside the track), refuses one that would
replace an input or write images into the clip's frames folder, reads the truth, and runs
:func:`trackcli.run.render.render` with a progress bar sized once the clip is open.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any, Callable, ContextManager


def render_track(track: str, clip: str, output: str | None = None, *, kind: str = "video", truth: str | None = None,
                 object_id: int = 0, progress: Callable[[str, int], ContextManager[Any]] | None = None,
                 **options: Any) -> Any:
    """Draw the outlines of ``track`` (a track CSV) on the frames of ``clip`` into ``output``
    (default :func:`trackcli.run.render.default_output`): a video, a folder of PNG frames or a
    contact sheet (``kind``), with the box of ``truth`` (object ``object_id``) in green.

    ``options`` go to :func:`trackcli.run.render.render` (``sheet_frames``, ``tile_width``,
    ``fps``, ``start``, ``end``, ``step``, ``label``, ...).  ``progress(label, n)`` returns the
    progress bar of the ``n`` frames drawn.  Returns its
    :class:`~trackcli.run.render.RenderResult`.
    """
    from trackcli.run.render import default_output, render

    out = Path(output or default_output(track, kind))
    check_render_output(out, kind, track=track, clip=clip, truth=truth)
    gt = None
    if truth:
        from trackcli.run.evaluate import load_truth

        gt = load_truth(truth, object_id=object_id)
    with contextlib.ExitStack() as stack:
        bar: list[Any] = []

        def opened(n: int) -> None:
            if progress is not None:
                bar.append(stack.enter_context(progress("rendering", n)))

        return render(track, clip, out, kind=kind, truth=gt, progress=lambda k: bar and bar[0].update(k),
                      on_open=opened, **options)


def check_render_output(out: Path, kind: str, *, track: str, clip: str, truth: str | None) -> None:
    """Refuse a render output that would write over its inputs, whose name does not fit
    ``kind``, or that would write into the image folder it reads (where a new image would
    become a frame of the clip): one-line errors."""
    from trackcli.errors import ConfigError
    from trackcli.io.outputs import refuse_overwriting_inputs
    from trackcli.io.video import IMAGE_SUFFIXES
    from trackcli.run.options import OptionError
    from trackcli.run.render import VIDEO_SUFFIXES

    refuse_overwriting_inputs({"-o/--output": out}, {"TRACK": track, "CLIP": clip, "--truth": truth})
    if kind == "sheet" and out.suffix.lower() != ".png":
        raise OptionError(f"--sheet writes a PNG image; give an output name ending in .png, not {out.name!r}")
    if kind == "video" and out.suffix.lower() not in VIDEO_SUFFIXES and not out.is_dir():
        raise OptionError(f"a video's name ends in {', '.join(VIDEO_SUFFIXES[:-1])} or {VIDEO_SUFFIXES[-1]}, "
                          f"not {out.name!r} (--png writes a folder of frames, --sheet N one PNG image)")
    folder = Path(clip)
    if not folder.is_dir():
        return
    target = out if kind == "frames" else out.parent
    for f in (folder, folder / "img"):
        with contextlib.suppress(OSError):
            if f.is_dir() and target.exists() and os.path.samefile(target, f) and (
                    kind == "frames" or out.suffix.lower() in IMAGE_SUFFIXES):
                raise ConfigError(f"{out}: would write images into the frames folder of CLIP ({f}); "
                                  "choose another output")
