"""``trackcli learn``: dynamics learned from training clips or tracks, written with a report.

:func:`learn_model` runs the track → learn cycles of :func:`trackcli.run.train.train` on
training clips (or learns at once from track CSVs, :func:`trackcli.run.train.learn_from_tracks`),
with label files a mixed-state model (:func:`trackcli.run.train.learn_labelled`), and
writes the model.  :meth:`Learned.report` is the summary ``learn --json`` prints and
:meth:`Learned.lines` the text ``learn`` prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ContextManager, Sequence


@dataclass(frozen=True)
class Learned:
    """What :func:`learn_model` wrote: the model (or mixed-state model) at ``path``, and the
    training cycles behind it (none when learned from tracks)."""

    path: Path
    model: Any
    records: Sequence[Any] = field(default_factory=list)
    mixed: bool = False

    def report(self) -> dict[str, Any]:
        """The JSON summary of ``learn --json``."""
        if self.mixed:
            return {"model": str(self.path), "kind": "mixed-state", "labels": self.model.names,
                    "transitions": self.model.T.tolist(),
                    "learning": self.model.provenance.get("mixed_learning", {})}
        from trackcli.run.model_report import mode_dict

        return {"model": str(self.path), "cycles": self._cycles(), "learning": self.model.provenance.get("learning", {}),
                "modes": [mode_dict(m, self.model.space.H) for m in self.model.dynamics.modes()]}

    def _cycles(self) -> list[dict[str, Any]]:
        return [{"cycle": r.cycle, "seconds": round(r.seconds, 3),
                 "clips": [{"clip": s.clip, "frames": s.frames, "lost": s.frames_lost,
                            "seconds": round(s.wall_seconds, 3)} for s in r.runs]} for r in self.records]

    def lines(self) -> list[str]:
        """The text ``learn`` prints: per cycle its time and clips, EM's progress, the model written."""
        if self.mixed:
            return self._mixed_lines()
        rep = self.model.provenance.get("learning", {})
        out = []
        for c in self._cycles():
            per = ", ".join(f"{Path(x['clip']).name} {x['seconds']:.1f} s ({x['frames']} frames, {x['lost']} lost)"
                            for x in c["clips"])
            out.append(f"cycle {c['cycle']}: {c['seconds']:.1f} s: {per}")
        for r in self.records:
            if "em" in r.report:
                out.append(f"cycle {r.cycle}: {em_line(r.report['em'])}")
        if not self.records and "em" in rep:
            out.append(em_line(rep["em"]))
        rho = rep.get("spectral_radius")
        out.append(f"wrote {self.path}: {self.model.space.kind} shape-space ({self.model.space.Nx} components), "
                   f"spectral radius {rho if rho is None else round(rho, 4)}; see `trackcli inspect {self.path}`")
        return out

    def _mixed_lines(self) -> list[str]:
        mixed = self.model
        out = [f"wrote mixed-state model {self.path}: labels {', '.join(mixed.names)}"]
        for name, r in mixed.provenance.get("mixed_learning", {}).get("labels", {}).items():
            out.append(f"  {name}: {r['triples']} frame triples from {r['runs']} run(s), residual RMS "
                       f"{r['residual_rms']:.3g}, spectral radius {r['spectral_radius']:.4f}")
        out.append("  transitions: " + "; ".join(f"{n} -> " + ", ".join(f"{v:.3f}" for v in row)
                                                 for n, row in zip(mixed.names, mixed.T)))
        return out


def em_line(em: dict[str, Any]) -> str:
    """EM's iterations and the measurements' log-likelihood before and after, on one line."""
    path = em["log_likelihood"]
    state = "converged" if em["converged"] else "not converged (em.max_iterations)"
    return (f"EM {em['iterations']} iteration(s), {state}; log-likelihood of the measurements "
            f"{path[0]:.1f} -> {path[-1]:.1f}")


def learn_model(clips: Sequence[str], *, template: str, output: str, config: str | None = None,
                overrides: dict[str, Any] | None = None, shape_space: str | None = None,
                from_tracks: Sequence[str] = (), tracks_fps: float | None = None, outdir: str | None = None,
                method: str = "mle", label_files: Sequence[str] = (), rrd: bool = True,
                progress: Callable[[str, int], ContextManager[Any]] | None = None) -> Learned:
    """Learn dynamics for ``template`` and write the model to ``output``.

    From ``clips`` (each tracked for ``learning.cycles`` cycles, the tracks and recordings
    kept in ``outdir``, default ``OUTPUT_training/`` beside the model, with the settings
    used) or from the track CSVs ``from_tracks`` (of clips at ``tracks_fps``, default the
    settings' ``video.fps``, else 25), not both.  With ``label_files`` (one per clip or
    track) the model written is a mixed-state model.  The settings are ``config``
    overridden by ``overrides`` (dotted keys, ``None`` for an option not given).

    Raises :class:`~trackcli.run.options.OptionError` for both or neither of ``clips`` and
    ``from_tracks``.
    """
    from trackcli.dynamics.model import save_model
    from trackcli.errors import DataError
    from trackcli.io.outputs import output_dir, refuse_overwriting_inputs, write_text
    from trackcli.run.clips import check_template_frame, template_space
    from trackcli.run.options import OptionError, settings_from
    from trackcli.run.train import learn_from_tracks, parse_shape_space, read_labels, train
    from trackcli.settings import dump_yaml
    from trackcli.shapes.template import load_template

    settings = settings_from(config, overrides or {})
    tmpl = load_template(template)
    # labelled ranges are checked before anything is tracked
    ranges = read_labels(label_files, len(from_tracks or clips)) if label_files else None
    out_model = Path(output)
    inputs = {"--template": template, "-c/--config": config,
              **{f"--from-tracks {t}": t for t in from_tracks}, **{f"CLIP {c}": c for c in clips}}
    if from_tracks:
        if clips:
            raise OptionError("give training CLIPS or --from-tracks, not both")
        refuse_overwriting_inputs({"-o/--output": out_model}, inputs)
        rate = tracks_fps or settings.video.fps or 25.0
        model = learn_from_tracks(from_tracks, tmpl, settings, 1.0 / rate, shape_space, method)
        if label_files:
            mixed = _labelled(from_tracks, label_files, ranges, model, 1.0 / rate, settings,
                              {"tracks": list(from_tracks)})
            return _save_mixed(out_model, mixed)
        save_model(out_model, model)
        return Learned(out_model, model)
    if not clips:
        raise OptionError("give at least one training CLIP (or --from-tracks)")
    kind, _ = parse_shape_space(shape_space, settings.shape_space)
    template_space(tmpl, template, "affine" if kind == "pca" else kind)  # a degenerate outline names its file
    work = Path(outdir or out_model.with_name(out_model.stem + "_training"))
    refuse_overwriting_inputs({"-o/--output": out_model, "the training configuration": work / "config.yaml"}, inputs)
    videos = []
    try:
        for c in clips:
            videos.append(_open(c, settings))
        for v in videos:
            check_template_frame(tmpl, v)
        with output_dir(work):
            try:
                model, records = train(videos, tmpl, settings, cycles=settings.learning.cycles,
                                       shape_space=shape_space, outdir=work, write_rrd=rrd, progress=progress,
                                       method=method)
            except DataError as exc:  # the tracks that could not be learned from are kept to look at
                kept = sorted(p.name for p in work.glob("*.csv"))
                if not kept:
                    raise
                raise DataError(f"{exc} (the training tracks, {', '.join(kept)}, are kept in {work})") from None
            if label_files:
                tracks = [str(r.csv) for r in records[-1].runs]
                mixed = _labelled(tracks, label_files, ranges, model, 1.0 / videos[0].fps, settings,
                                  {"clips": list(clips), "cycles": settings.learning.cycles})
            # written with the results: a run that fails leaves no configuration behind
            write_text(work / "config.yaml", dump_yaml(settings))
            if label_files:
                return _save_mixed(out_model, mixed)
            save_model(out_model, model)
    finally:
        for v in videos:
            v.close()
    return Learned(out_model, model, records)


def _open(clip: str, settings: Any) -> Any:
    from trackcli.io.video import open_video

    v = settings.video
    return open_video(clip, fps=v.fps, start=v.start, end=v.end, step=v.step)


def _labelled(tracks: Sequence[str], label_files: Sequence[str], ranges: Any, model: Any, tau: float,
              settings: Any, provenance: dict[str, Any]) -> Any:
    """``learn --labels``: the mixed-state model from the final tracks (:func:`trackcli.run.train.learn_labelled`)."""
    from trackcli.run.train import learn_labelled

    return learn_labelled(tracks, label_files, model.template, model.space, tau, settings, provenance, ranges=ranges)


def _save_mixed(path: Path, mixed: Any) -> Learned:
    from trackcli.dynamics.mixed import save_mixed

    save_mixed(path, mixed)
    return Learned(path, mixed, mixed=True)
