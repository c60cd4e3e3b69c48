"""Batch manifests: the YAML file that lists the clips of a batch and how to track each.

A *manifest* is a YAML file listing clips and how to track them::

    format: 1
    defaults:                      # apply to every clip unless the clip says otherwise
      tracker: condensation
      model: models/head-model.yaml
      config: configs/default.yaml
      settings: {condensation: {particles: 300}, video.end: 100}
      seed: 0
      masks: true                  # also write OUTDIR/NAME/masks/, one PNG per frame
    clips:
      - clip: footage/test.mp4
        template: models/head-test.yaml
        truth: footage/test.truth.csv   # optional: the run is scored against it
        name: test                      # optional; default the clip's stem (a folder's name)
      - clip: footage/crossing          # an image folder
        fps: 25
        template: models/crossing.yaml
      - footage/other.mp4               # a bare path: the defaults say everything else

Every relative path is relative to the manifest's folder.  Keys of a clip entry:

=============  ==============================================================================
``clip``       video file or image folder (required; not in ``defaults``)
``name``       output folder name (default: the clip's name, see
               :func:`trackcli.run.clips.clip_name`; not in ``defaults``)
``truth``      ground truth as ``trackcli eval`` reads it: truth CSV, box file or folder
``object``     object id in a truth CSV with several objects (default 0)
``threshold``  centre-error threshold of precision, px (default 20)
``model``      model learned by ``trackcli learn``
``template``   template drawn on this clip (at least one of ``model`` and ``template``)
``tracker``    ``condensation`` (default) or ``kalman``
``config``     configuration file (YAML)
``settings``   overrides of the configuration: nested mappings or dotted keys
``seed``       shortcut for ``settings: {seed: ...}``
``fps``        shortcut for ``settings: {video.fps: ...}``, for image folders
``rrd``        ``false`` to write no recording (default ``true``)
``masks``      ``true`` (0/255 PNGs) or ``palette``: one mask per frame in ``OUTDIR/NAME/masks/``
``vot``        ``true``: VOT region lines, ``OUTDIR/NAME/NAME.TRACKER.vot.txt``
=============  ==============================================================================

A clip's ``config`` replaces the default one; ``settings`` are applied in the order config
file, ``defaults.settings``, ``defaults`` shortcuts, the clip's ``settings``, the clip's
shortcuts.  :func:`load_manifest` checks everything it can before any clip runs (settings are
valid, names are distinct, shared files exist) and raises one-line errors naming the entry and
key, e.g. ``batch.yaml: clips[2].tracker: expected one of ...``.  A file named by one clip
entry that does not exist (its clip, template, model, truth or config) does not stop the
batch: that job is marked :attr:`Job.missing`, the batch runs every other clip, and reports
the missing ones at the end (``trackcli batch`` then exits with 1).  A missing file named in
``defaults``, which every clip would lack, is an error of the manifest, and so is a manifest
none of whose clips can run (:func:`trackcli.run.batch.check_runnable`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from trackcli.errors import ConfigError, InputError, short_repr
from trackcli.settings import Settings, load_settings, set_dotted, settings_from_dict, to_dict
from trackcli.run.clips import clip_name
from trackcli.trackers import TRACKERS

#: Manifest format version this module reads.
FORMAT = 1

#: Keys of a clip entry, and those ``defaults`` may also give.
CLIP_KEYS = ("clip", "name", "truth", "object", "threshold", "model", "template", "tracker", "config",
             "settings", "seed", "fps", "rrd", "masks", "vot")
DEFAULT_KEYS = tuple(k for k in CLIP_KEYS if k not in ("clip", "name", "truth"))
#: Values of ``masks``: no masks, grey 0/255 PNGs, palette PNGs.
MASK_KINDS = {False: None, True: "grey", "palette": "palette"}


@dataclass(frozen=True)
class Job:
    """One clip to track (and score), fully resolved.

    Attributes
    ----------
    name : str
        Output folder name, unique in the batch.
    clip : str
        Absolute path of the video file or image folder.
    settings : Settings
        Effective settings (seed, frame selection, tracker parameters).
    tracker : {"condensation", "kalman"}
    model, template : str or None
        Absolute paths; at least one is given.
    truth : str or None
        Absolute path of the ground truth, if the run is to be scored.
    object_id : int
        Object of a truth CSV with several objects.
    threshold : float
        Centre-error threshold (px) of precision.
    rrd : bool
        Write a recording.
    masks : {"grey", "palette"} or None
        Write one mask PNG per frame into ``OUTDIR/NAME/masks/``.
    vot : bool
        Write VOT region lines.
    entry : str
        Where the job came from, e.g. ``"clips[2]"`` (for messages).
    missing : str or None
        Why the job cannot run: a file its entry names does not exist (the one-line message).
    """

    name: str
    clip: str
    settings: Settings
    tracker: str = "condensation"
    model: str | None = None
    template: str | None = None
    truth: str | None = None
    object_id: int = 0
    threshold: float = 20.0
    rrd: bool = True
    masks: str | None = None
    vot: bool = False
    entry: str = ""
    missing: str | None = None


@dataclass(frozen=True)
class Manifest:
    """A validated manifest: its path and its jobs, in file order."""

    path: Path
    jobs: tuple[Job, ...]


def load_manifest(path: str | os.PathLike[str]) -> Manifest:
    """Read and validate a batch manifest (format in the module docstring).

    Returns
    -------
    Manifest

    Raises
    ------
    InputError
        The manifest file is missing or unreadable, or a path in ``defaults`` names no file
        (a missing file of one clip's entry marks that job :attr:`Job.missing` instead).
    ConfigError
        Anything else wrong inside it.  Messages start with the manifest's path and name the
        entry and key (``clips[2].template: no such file: ...``).
    """
    from trackcli.io.outputs import read_yaml_file

    path = Path(path)
    data = read_yaml_file(path, "manifest", InputError, invalid=ConfigError)
    try:
        jobs = _parse(data, path.resolve().parent)
    except (ConfigError, InputError) as exc:
        raise type(exc)(f"{path}: {exc}") from None
    return Manifest(path, jobs)


def _parse(data: Any, base: Path) -> tuple[Job, ...]:
    if not isinstance(data, dict):
        raise ConfigError("expected a mapping with 'clips' (and optionally 'format', 'defaults') at the top level")
    unknown = [k for k in data if k not in ("format", "defaults", "clips")]
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown key (valid at the top level: format, defaults, clips)")
    fmt = data.get("format", FORMAT)
    if isinstance(fmt, bool) or fmt != FORMAT:
        raise ConfigError(f"format: this version reads manifest format {FORMAT}, got {short_repr(fmt)}")
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise ConfigError(f"defaults: expected a mapping of clip settings, got {short_repr(defaults)}")
    _check_keys(defaults, DEFAULT_KEYS, "defaults")
    clips = data.get("clips")
    if not isinstance(clips, list) or not clips:
        raise ConfigError(f"clips: expected a non-empty list of clips, got {short_repr(clips)}")
    jobs = [_job(entry, f"clips[{i}]", defaults, base) for i, entry in enumerate(clips)]
    seen: dict[str, str] = {}
    for job in jobs:
        key = job.name.casefold()
        if key in seen:
            raise ConfigError(f"{job.entry}.name: {job.name!r} is also the name of {seen[key]}; "
                              "give one of them a distinct 'name'")
        seen[key] = job.entry
    return tuple(jobs)


def _check_keys(entry: Mapping[str, Any], valid: Sequence[str], where: str) -> None:
    for k in entry:
        if k not in valid:
            raise ConfigError(f"{where}.{k}: unknown key (valid: {', '.join(valid)})")


def _job(entry: Any, where: str, defaults: Mapping[str, Any], base: Path) -> Job:
    if isinstance(entry, str):
        entry = {"clip": entry}
    if not isinstance(entry, dict):
        raise ConfigError(f"{where}: expected a clip path or a mapping with 'clip', got {short_repr(entry)}")
    _check_keys(entry, CLIP_KEYS, where)
    if "clip" not in entry:
        raise ConfigError(f"{where}: missing 'clip' (the video file or image folder)")
    missing: list[str] = []

    def get(key: str) -> tuple[Any, str]:
        """The value of ``key`` and the label naming where it came from."""
        if key in entry:
            return entry[key], f"{where}.{key}"
        return defaults.get(key), f"defaults.{key}"

    def path(key: str, *, folder_ok: bool) -> str | None:
        """A path of the entry; a missing file of the clip's own entry makes the job "missing"."""
        value, label = get(key)
        try:
            return _path(value, label, base, folder_ok=folder_ok)
        except InputError as exc:
            if key not in entry:
                raise
            missing.append(str(exc))
            return _path(value, label, base, folder_ok=folder_ok, must_exist=False)

    clip = path("clip", folder_ok=True)
    paths = {k: path(k, folder_ok=(k == "truth")) for k in ("model", "template", "config", "truth")}
    if not paths["model"] and not paths["template"]:
        raise ConfigError(f"{where}: give a model, a template, or both (here or in defaults)")
    tracker, label = get("tracker")
    tracker = "condensation" if tracker is None else tracker
    if tracker not in TRACKERS:
        raise ConfigError(f"{label}: expected one of {', '.join(TRACKERS)}, got {short_repr(tracker)}")
    object_id = _integer(*get("object"), default=0)
    threshold = _positive(*get("threshold"), default=20.0)
    rrd = _flag(*get("rrd"), default=True)
    masks, label = get("masks")
    if masks is not None and (not isinstance(masks, (bool, str)) or masks not in MASK_KINDS):
        raise ConfigError(f"{label}: expected true, false or palette, got {short_repr(masks)}")
    vot = _flag(*get("vot"), default=False)
    name, label = get("name")
    name = clip_name(clip) if name is None else name
    if (not isinstance(name, str) or name in ("", ".", "..") or name.startswith(".")
            or any(c in name for c in "/\\\0")):
        raise ConfigError(f"{label}: expected a folder name (no '/', not starting with '.'), got {short_repr(name)}")
    settings = _settings(where, entry, defaults, None if "config" in entry and missing else paths["config"])
    return Job(name=name, clip=clip, settings=settings, tracker=tracker, model=paths["model"],
               template=paths["template"], truth=paths["truth"], object_id=object_id, threshold=threshold,
               rrd=rrd, masks=MASK_KINDS.get(masks) if masks is not None else None, vot=vot, entry=where,
               missing="; ".join(missing) or None)


def _flag(value: Any, label: str, *, default: bool) -> bool:
    if value is None:
        return default
    if not isinstance(value, bool):
        raise ConfigError(f"{label}: expected true or false, got {short_repr(value)}")
    return value


def _path(value: Any, label: str, base: Path, *, folder_ok: bool, must_exist: bool = True) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(f"{label}: expected a path, got {short_repr(value)}")
    p = Path(os.path.expanduser(value))
    p = Path(os.path.normpath(p if p.is_absolute() else base / p))
    if not must_exist or (folder_ok and p.exists()):
        return str(p)
    if not p.is_file():
        what = "no such file or folder" if folder_ok else ("is a folder, expected a file" if p.is_dir() else "no such file")
        raise InputError(f"{label}: {what}: {p}")
    return str(p)


def _integer(value: Any, label: str, *, default: int) -> int:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(f"{label}: expected an integer >= 0, got {short_repr(value)}")
    return value


def _positive(value: Any, label: str, *, default: float) -> float:
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{label}: expected a number > 0, got {short_repr(value)}")
    return float(value)


def _flatten(overrides: Any, label: str) -> dict[str, Any]:
    """Nested mappings and dotted keys as one mapping of dotted keys."""
    if not isinstance(overrides, dict):
        raise ConfigError(f"{label}: expected a mapping of settings (nested or dotted keys), got {short_repr(overrides)}")
    flat: dict[str, Any] = {}

    def walk(node: dict, prefix: str) -> None:
        for k, v in node.items():
            if not isinstance(k, str) or not k:
                raise ConfigError(f"{label}: setting names are strings, got {short_repr(k)}")
            key = f"{prefix}{k}"
            if isinstance(v, dict):
                walk(v, key + ".")
            else:
                flat[key] = v

    walk(overrides, "")
    return flat


def _settings(where: str, entry: Mapping[str, Any], defaults: Mapping[str, Any], config: str | None) -> Settings:
    config_label = f"{where}.config" if "config" in entry else "defaults.config"
    try:
        data = to_dict(load_settings(config))
    except ConfigError as exc:
        raise ConfigError(f"{config_label}: {exc}") from None
    for source, label in ((defaults, "defaults"), (entry, where)):
        steps = []
        if source.get("settings") is not None:
            steps.append((f"{label}.settings", _flatten(source["settings"], f"{label}.settings")))
        if source.get("seed") is not None:
            steps.append((label, {"seed": source["seed"]}))
        if source.get("fps") is not None:
            steps.append((label, {"video.fps": _positive(source["fps"], f"{label}.fps", default=0.0)}))
        for step_label, overrides in steps:
            for dotted, value in overrides.items():
                set_dotted(data, dotted, value, step_label)
            try:
                settings_from_dict(data)
            except ConfigError as exc:
                raise ConfigError(f"{step_label}.{exc}") from None
    return settings_from_dict(data)



__all__ = ["CLIP_KEYS", "DEFAULT_KEYS", "FORMAT", "Job", "MASK_KINDS", "Manifest", "load_manifest"]
