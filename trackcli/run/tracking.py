"""``trackcli track``: one tracker run over each of several clips.

:func:`track_clips` reads the settings (configuration and options), checks the files every
clip shares once, then runs :func:`trackcli.run.clips.track_clip` on each clip in turn and
yields what became of it.  With several clips, a clip that fails is reported in its
:class:`ClipOutcome` and the others still run; a single clip's error is raised.  Each track
may also be written as masks and VOT region lines (:func:`trackcli.run.export.export_sinks`),
and a run whose sample set collapsed is warned about (:func:`trackcli.run.checks.track_warnings`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, ContextManager, Iterator, Sequence

from trackcli.errors import TrackcliError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ClipOutcome:
    """One clip of :func:`track_clips`: its summary, or the one-line error that stopped it."""

    clip: str
    name: str
    summary: Any = None
    error: str | None = None
    exported: Any = None  # the ExportResult of the masks and region lines, when asked for

    def json(self, tracker: str) -> dict[str, Any]:
        """The clip's object of ``track --json`` (:func:`trackcli.run.clips.clip_json`)."""
        from trackcli.run.clips import clip_json

        d = clip_json(self.name, self.clip, tracker, self.summary, error=self.error)
        if self.exported is not None:
            d.update(masks=self.exported.masks and str(self.exported.masks),
                     vot=self.exported.vot and str(self.exported.vot))
        return d


def clip_names(clips: Sequence[str]) -> list[str]:
    """The output prefix of each clip (:func:`trackcli.run.clips.clip_name`)."""
    from trackcli.run.clips import clip_name

    return [clip_name(c) for c in clips]


def track_clips(clips: Sequence[str], *, config: str | None, overrides: dict[str, Any], outdir: str,
                model: str | None = None, template: str | None = None, tracker: str = "condensation",
                rrd: bool = True, smooth: bool = False,
                progress: Callable[[str, int], ContextManager[Any]] | None = None,
                options: dict[str, str] | None = None, masks: str | None = None, palette: bool = False,
                vot: str | None = None) -> Iterator[ClipOutcome]:
    """Track each of ``clips`` into ``outdir`` (named by :func:`clip_names`, which must differ).

    The settings are the configuration ``config`` overridden by ``overrides`` (dotted keys,
    ``None`` for an option not given); with a ``model``, the measurement settings not set
    there are the model's own (see :func:`trackcli.run.clips.track_clip`).  ``options``: the
    command-line options given, by name, with the setting each one sets; one that the tracker
    does not read is refused.  With ``masks``
    (a folder; with several clips, a folder ``masks/NAME`` per clip) and ``vot`` (a file; one
    clip only), each track's outlines are written as mask PNGs (``palette``: palette PNGs)
    and VOT region lines while it is tracked (sinks of the frame loop, committed with the track).
    """
    from trackcli.dynamics.model import load_model
    from trackcli.run.clips import track_clip
    from trackcli.run.options import OptionError, explicit_keys, given, settings_from
    from trackcli.shapes.template import load_template

    settings = settings_from(config, overrides)
    explicit = explicit_keys(config, overrides) if model else None
    shown = [f"{k}={v}" for k, v in given(overrides).items()]
    log.info("settings: %s%s%s", f"config {config}" if config else "the defaults",
             f", options {', '.join(shown)}" if shown else "", f"; dynamics and shape-space from model {model}"
             if model else "")
    names = clip_names(clips)
    if len(set(names)) != len(names):
        raise OptionError("two clips have the same name; run them into different --outdir folders")
    if vot and len(clips) > 1:
        raise OptionError("--vot names one file: give it with one clip (batch --vot writes one per clip)")
    if palette and not masks:
        raise OptionError("--palette goes with --masks")
    mask_dirs = {n: (None if not masks else Path(masks) / n if len(clips) > 1 else Path(masks)) for n in names}
    from trackcli.run.export import ExportResult, export_sinks

    if masks or vot:
        from trackcli.run.export import check_export_outputs

        for clip, name in zip(clips, names):
            check_export_outputs(mask_dirs[name], vot, inputs={"clip": clip, "--template": template,
                                                               "--model": model, "-c/--config": config})
    # files shared by every clip are checked once, before any clip runs
    if model:
        from trackcli.dynamics.mixed import is_mixed_file, load_mixed

        load_mixed(model) if is_mixed_file(model) else load_model(model)
    if template:
        load_template(template)
    for clip, name in zip(clips, names):
        exported = None
        try:
            summary = track_clip(clip, settings=settings, outdir=outdir, model=model, template=template,
                                 tracker=tracker, name=name, rrd=rrd, smooth=smooth, progress=progress,
                                 explicit=explicit, inputs={"-c/--config": config}, options=options,
                                 sinks=export_sinks(mask_dirs[name], vot, palette=palette) if masks or vot else None)
            if masks or vot:
                exported = ExportResult(mask_dirs[name], Path(vot) if vot else None, summary.frames)
        except TrackcliError as exc:
            if len(clips) == 1:
                raise
            message = str(exc)
            yield ClipOutcome(clip, name, error=message if message.startswith(str(clip)) else f"{clip}: {message}")
            continue
        from trackcli.run.checks import track_warnings

        for note in track_warnings(summary.csv, settings.condensation.particles, name=name):
            log.warning("%s", note)
        yield ClipOutcome(clip, name, summary, exported=exported)
