"""Run settings: YAML files validated into frozen settings objects.

A configuration file is a YAML mapping whose sections mirror :class:`Settings`.  Every key is
optional; missing keys take the defaults documented in ``configs/default.yaml``.  Unknown
keys, wrong types and out-of-range values raise :class:`~trackcli.errors.ConfigError` with the
dotted key path and the reason, e.g.::

    measurement.n_normals: expected an integer >= 3, got 'abc'

Command-line options override file values through :func:`load_settings` ``overrides`` (a
mapping of dotted keys to values), validated by the same rules.

Settings that moved to another section (:data:`MOVED`: the observation model, re-acquisition
and jumps were keys of ``condensation`` before they had sections of their own) are still read
under their old names, in a file, an override or a model's stored settings: the value goes to
the new key, and a file or an override is told so in a one-line warning naming the new key.
A file that gives both the old and the new name of one setting is refused.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from trackcli.errors import ConfigError, short_repr

FORMAT = 1

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------------------------
# Field specifications


@dataclass(frozen=True)
class _Spec:
    kind: str  # "int" | "float" | "str" | "bool"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False  # lo is exclusive
    choices: tuple[str, ...] | None = None
    nullable: bool = False
    doc: str = ""

    def describe(self) -> str:
        if self.choices is not None:
            what = "one of " + ", ".join(repr(c) for c in self.choices)
        else:
            what = {"int": "an integer", "float": "a number", "str": "a string", "bool": "true or false"}[self.kind]
            if self.lo is not None and self.hi is not None:
                what += f" in [{_num(self.lo)}, {_num(self.hi)}]" if not self.lo_open else f" in ({_num(self.lo)}, {_num(self.hi)}]"
            elif self.lo is not None:
                what += f" > {_num(self.lo)}" if self.lo_open else f" >= {_num(self.lo)}"
            elif self.hi is not None:
                what += f" <= {_num(self.hi)}"
        if self.nullable:
            what += " or null"
        return what

    def check(self, path: str, value: Any) -> Any:
        if value is None:
            if self.nullable:
                return None
            raise ConfigError(f"{path}: expected {self.describe()}, got null")
        bad = ConfigError(f"{path}: expected {self.describe()}, got {short_repr(value)}")
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise bad
            return value
        if self.kind == "str":
            if not isinstance(value, str):
                raise bad
            if self.choices is not None and value not in self.choices:
                raise bad
            return value
        if isinstance(value, bool):
            raise bad
        if self.kind == "int":
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            if not isinstance(value, int):
                raise bad
        else:
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise bad
            value = float(value)
        if self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo)):
            raise bad
        if self.hi is not None and value > self.hi:
            raise bad
        return value


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else str(v)


def _f(default: Any, kind: str, doc: str, **kw: Any) -> Any:
    return field(default=default, metadata={"spec": _Spec(kind, doc=doc, **kw)})


def _section(cls: type, doc: str) -> Any:
    return field(default_factory=cls, metadata={"doc": doc})


# ---------------------------------------------------------------------------------------------
# Sections


@dataclass(frozen=True)
class VideoSettings:
    fps: float | None = _f(None, "float", "frame rate for image folders (they carry none); null = 25", lo=0, lo_open=True, nullable=True)
    start: int = _f(0, "int", "first frame index (inclusive)", lo=0)
    end: int | None = _f(None, "int", "last frame index (exclusive); null = to the end", lo=1, nullable=True)
    step: int = _f(1, "int", "use every step-th frame", lo=1)


@dataclass(frozen=True)
class MeasurementSettings:
    n_normals: int = _f(24, "int", "measurement points M along the curve", lo=3, hi=1000)
    channel: str = _f("grey", "str", "image fed to the feature detector", choices=("grey", "b", "g", "r", "skin"))
    smoothing: float = _f(1.0, "float", "Gaussian pre-smoothing of the image, sigma in px (0 = none)", lo=0, hi=20)
    edge_sigma: float = _f(1.5, "float", "width of the derivative-of-Gaussian edge operator along normals, px", lo=0.3, hi=10)
    threshold: float = _f(8.0, "float", "contrast threshold, grey levels per px", lo=0)
    polarity: str = _f("any", "str", "edge polarity accepted, relative to the outward normal (the discriminant learns it per normal instead)", choices=("any", "light_to_dark", "dark_to_light"))
    presence_centre: float = _f(0.3, "float", "fraction of the template's presence score on the first frame (evidence per normal, trackcli.observe.discriminant) at which the confidence is 0.5", lo=0, hi=1)
    reacquired_centre: float = _f(0.5, "float", "presence_centre while the tracker is recovering from a loss (lost on reacquire.after of the last frames): a place found after a loss needs more evidence than one followed from frame to frame; a value below presence_centre counts as presence_centre", lo=0, hi=1)
    lost_below: float = _f(0.5, "float", "a frame is reported lost when its confidence is below this", lo=0, hi=1)


@dataclass(frozen=True)
class KalmanSettings:
    rho_f: float = _f(1.0, "float", "observation uncertainty rho_f in px (AC eq 8.17)", lo=0, lo_open=True)
    kappa: float = _f(2.0, "float", "validation gate width in standard deviations (AC Fig 8.6)", lo=0, lo_open=True, hi=10)
    min_gate: float = _f(3.0, "float", "smallest search half-width along a normal, px", lo=0)
    max_gate: float = _f(40.0, "float", "largest search half-width along a normal, px", lo=1)
    init: str = _f("static", "str", "initial condition (AC section 10.1)", choices=("static", "unknown"))


@dataclass(frozen=True)
class SubspaceDynamics:
    f: float = _f(0.0, "float", "oscillation frequency, Hz", lo=0)
    beta: float = _f(2.0, "float", "damping rate, 1/s (0 with f = 0: constant velocity)", lo=0)
    rho: float | None = _f(500.0, "float", "steady-state RMS displacement (AC eq 9.26), in dynamics.units; null with f = 0 and gamma0: damped velocity, free position", lo=0, lo_open=True, nullable=True)
    gamma0: float | None = _f(None, "float", "noise growth rate, in dynamics.units per s^1.5 (AC eq 9.28); used when f = beta = 0 (constant velocity) or rho is null (damped velocity)", lo=0, lo_open=True, nullable=True)


def _translation_default() -> SubspaceDynamics:
    return SubspaceDynamics(f=0.0, beta=4.0, rho=None, gamma0=5.0)


def _deformation_default() -> SubspaceDynamics:
    return SubspaceDynamics(f=0.0, beta=2.0, rho=0.1)


@dataclass(frozen=True)
class DynamicsSettings:
    units: str = _f("object", "str", "unit of rho and gamma0: 'object' = the template's size (square root of its area), 'px' = pixels", choices=("object", "px"))
    translation: SubspaceDynamics = field(default_factory=_translation_default, metadata={"doc": "hand-set dynamics of translation"})
    deformation: SubspaceDynamics = field(default_factory=_deformation_default, metadata={"doc": "hand-set dynamics of the rest of shape-space"})


@dataclass(frozen=True)
class CondensationSettings:
    particles: int = _f(500, "int", "sample-set size N after the start-up schedule", lo=1, hi=1_000_000)
    initial_particles: int = _f(1500, "int", "sample-set size on the first frame", lo=1, hi=1_000_000)
    schedule_frames: int = _f(4, "int", "frames over which N falls from initial_particles to particles", lo=1)
    resampling: str = _f("multinomial", "str", "selection scheme", choices=("multinomial", "systematic", "stratified"))
    ess_threshold: float | None = _f(None, "float", "resample only when ESS/N falls below this ratio; null = every frame", lo=0, lo_open=True, hi=1, nullable=True)
    init: str = _f("template", "str", "initial sample set", choices=("template", "steady_state"))
    init_translation: float = _f(10.0, "float", "initial spread of translation around the template, px (init: template)", lo=0)
    init_deformation: float = _f(0.02, "float", "initial spread of the other shape components (init: template)", lo=0)
    init_speed: float = _f(0.0, "float", "initial spread of translational velocity, px/frame, for an object already moving on the first frame (init: template)", lo=0)
    histogram_bins: int = _f(64, "int", "bins of the horizontal-translation histogram", lo=2, hi=4096)
    display_particles: int = _f(10, "int", "particle contours drawn per frame in the recording", lo=0, hi=10000)
    flow_fraction: float = _f(0.25, "float", "share of the samples drawn about where the dense optical flow (DIS) says the object moved: the last estimate moved by the median flow over its region, with importance weights that keep the set a fair sample of the motion prior (ICONDENSATION); for motion faster than the AR(2) prior follows; not while re-acquiring; the largest share: after each frame the share moves halfway toward the posterior weight the flow's samples earned, within [flow_least, flow_fraction]; 0: off", lo=0, hi=0.9)
    flow_least: float = _f(0.02, "float", "smallest share of the samples the flow proposal keeps when its samples earn little posterior weight (an unreliable flow); flow_fraction or more: a fixed share", lo=0, hi=0.9)
    threads: int = _f(0, "int", "threads that score the samples (0 = every core from 300 samples up with the discriminant, 2000 with the numpy models, one below); the results do not depend on it", lo=0, hi=256)


@dataclass(frozen=True)
class ObservationSettings:
    likelihood: str = _f("discriminant", "str", "observation model: discriminant (edges and colour learned on the first frame, trackcli.observe.discriminant), clutter (AC eq 12.2) or truncated (Isard & Blake 1996 eqs 10-11)", choices=("discriminant", "clutter", "truncated"))
    miss_probability: float = _f(0.1, "float", "discriminant: probability q that the boundary is not detected on a normal", lo=0, lo_open=True, hi=1)
    colour_weight: float = _f(3.0, "float", "discriminant: weight w_c of the colour term against the edge term", lo=0, hi=100)
    still_weight: float = _f(1.0, "float", "discriminant: a curve on pixels that kept their colour since the first frame (a look-alike standing in the scene, with a still camera) loses this many times the template's own score on its first frame, in proportion to its stillness; 0: off (frames are still compared with the first, to read the colour model in the first frame's light when the light over the whole scene changes)", lo=0, hi=10)
    discriminant_power: float = _f(0.5, "float", "discriminant: exponent on its likelihood in CONDENSATION's sample weights (tempering): the discriminant takes its normals as independent evidence, which they are not, and its posterior is narrower than the estimate's real error (on the dev clips by about four times); below 1 the motion prior and the re-acquisition's importance weights keep their say against a look-alike that scores a little higher; 1: the likelihood as it is", lo=0, lo_open=True, hi=1)
    search: float = _f(20.0, "float", "fixed search half-width h along each normal, px (truncated: also the penalty h^2)", lo=1, hi=200)
    sigma: float = _f(3.0, "float", "feature position noise sigma, px", lo=0, lo_open=True)
    alpha: float = _f(0.02, "float", "clutter density alpha, features per px (clutter model only)", lo=0, lo_open=True)


@dataclass(frozen=True)
class ReacquireSettings:
    enabled: bool = _f(True, "bool", "when lost, draw a share of the samples from the colour map of the frame near where the object was last held (see speed; importance sampling)")
    after: int = _f(3, "int", "the colour proposal is used once the tracker was lost on this many of the last 2*after-1 frames: that many in a row, or a verdict going back and forth between lost and held (a shorter dip, e.g. the object brushing the frame's edge, is left to the motion model)", lo=1, hi=1000)
    fraction: float = _f(0.25, "float", "share of the samples drawn from the colour proposal while lost", lo=0, lo_open=True, hi=1)
    speed: float = _f(2.0, "float", "while lost, the object is looked for within a square about where it was last held, of half-width 2 object sizes growing by this many object sizes per second lost, or by twice the fastest the object was seen to move if that is more (an object hidden or turned away is still near where it was; a look-alike across the frame is not it); 0: anywhere in the frame at once", lo=0)
    scale: float = _f(2.0, "float", "the samples drawn from the colour proposal also take a scale log-uniform within [1/s, s] of the template's (the object may be found again nearer or farther than it was lost); 1: the template's scale only", lo=1, hi=10)
    scale_reference: float = _f(1.0, "float", "scale is used only when the template's presence score on its first frame (evidence per normal) is at least this: where the template is barely more object-like than clutter, other scales find clutter as readily as the object")


@dataclass(frozen=True)
class JumpSettings:
    fraction: float = _f(0.1, "float", "share of the samples given a jump: an impulse that moves the predicted position and changes the velocity by the same amount (the motion prior is a mixture of smooth motion and abrupt moves: kicks, turns, camera shake)", lo=0, hi=1)
    size: float = _f(0.3, "float", "RMS size of such a jump, in object sizes (square root of the template's area)", lo=0, hi=10)
    brake: float = _f(0.02, "float", "share of the samples given a braking jump (besides the jumps of fraction): the velocity v changes by -u*v, u uniform in [0, 2] (slowing, stopping, turning back: a bounce), plus 0.3 of size at random", lo=0, hi=1)


@dataclass(frozen=True)
class MHTSettings:
    modes: int = _f(3, "int", "most modes K kept each frame (mode-based multiple hypotheses, Cham & Rehg 1999)", lo=1, hi=100)
    samples: int = _f(10, "int", "seeds per mode S: each frame starts K*S local searches, the modes' predictions among them", lo=1, hi=10000)
    iterations: int = _f(3, "int", "Gauss-Newton steps (measure along the normals, assimilate) that take a seed to its mode", lo=1, hi=50)
    merge_distance: float = _f(2.0, "float", "hypotheses closer than this (RMS curve displacement, px) are one mode", lo=0, lo_open=True, hi=1000)
    spread: float = _f(2.0, "float", "factor on the predicted standard deviations that seeds are drawn with (wider than the prior: a seed only needs to start in the basin of a mode)", lo=0, lo_open=True, hi=100)
    truncate: bool = _f(True, "bool", "keep a seed only inside the cell of the piecewise-Gaussian prior that its mode owns (the paper's rejection step)")


@dataclass(frozen=True)
class PlacementSettings:
    translation_noise: float = _f(1.0, "float", "factor on a learned model's translational process noise when it tracks a clip: how much more agile the motion is than in training (1 = as learned)", lo=0, lo_open=True, hi=1000)
    deformation_noise: float = _f(1.0, "float", "the same factor for the rest of shape-space (rotation, scale, other deformation)", lo=0, lo_open=True, hi=1000)
    coupling: str = _f("keep", "str", "learned coupling between translation and the rest kept on placing: keep (all, as learned: modes unchanged), velocity (drop the position terms), none (drop all; re-stabilised if needed)", choices=("keep", "velocity", "none"))


@dataclass(frozen=True)
class LearningSettings:
    cycles: int = _f(2, "int", "track-learn cycles (AC Fig 11.1)", lo=1, hi=50)
    enforce_stability: bool = _f(True, "bool", "shrink unstable modes of the learned model")
    max_spectral_radius: float = _f(0.995, "float", "largest eigenvalue modulus kept when enforcing stability", lo=0, lo_open=True, hi=1)


@dataclass(frozen=True)
class EMSettings:
    tolerance: float = _f(1e-4, "float", "learn --method em: stop when an iteration raises the log-likelihood by less than this, nats per frame", lo=0, lo_open=True)
    max_iterations: int = _f(200, "int", "learn --method em: most EM iterations per learning cycle", lo=1, hi=100000)


@dataclass(frozen=True)
class OutlineSettings:
    refine: bool = _f(True, "bool", "fit each frame's outline again in the full image, from pixel-wise colour posteriors with the "
                      "tracker's estimate as the prior (trackcli.observe.region); false: the outline is the estimate's curve")
    prior_width: float = _f(0.5, "float", "how far (in object sizes) the refined outline may leave the prior before the prior's "
                            "log-odds fall by 1", lo=0.01, hi=5)
    flow: bool = _f(True, "bool", "add the last refined outline moved by the dense optical flow (DIS) as a second prior")
    colour_rate: float = _f(0.05, "float", "share of the way the refinement's colour model moves toward a frame's region when "
                            "the frame is held with confidence (tracker's confidence >= 0.7, region and estimate agreeing "
                            "IoU >= 0.6); 0: the first frame's colours throughout", lo=0, hi=1)
    lost_contrast: float = _f(3.0, "float", "a frame the tracker reports lost is reported held when the inside of its refined "
                              "outline stands out from a band about it by at least this in the first frame's colours (mean "
                              "colour log-ratio inside less outside; held frames score 4-5) and the outline still agrees with "
                              "the estimate (IoU >= 0.2); 0: the tracker's verdict as it is",
                              lo=0, hi=8)


@dataclass(frozen=True)
class OutputSettings:
    rrd: bool = _f(True, "bool", "write a Rerun recording (.rrd)")
    jpeg_quality: int = _f(80, "int", "JPEG quality of frames encoded for recordings (frames kept as their source's JPEG are not encoded again)", lo=10, hi=100)
    frames: str = _f("auto", "str", "how recordings store frames: auto (an AV1 MP4 recorded whole embedded as it is; otherwise "
                     "the frames encoded as AV1 video, which the native Rerun viewer decodes by itself, about 5-6 KB a frame "
                     "at 854x480; JPEG when PyAV's AV1 encoder is missing or the frames are under 64x64, the source's own "
                     "JPEGs kept as they are), av1 (always encode AV1), jpeg (every frame encoded as JPEG at jpeg_quality, "
                     "shown by every Rerun viewer), asset (the MP4 clip embedded as a video; the native viewer needs FFmpeg "
                     "for H.264/H.265 and cannot play VP9); a frame selection (--start/--end/--step) is never an asset",
                     choices=("auto", "av1", "jpeg", "asset"))
    outline_points: int = _f(64, "int", "points of the estimated outline written to each row of the track CSV "
                             "(outline_x0, outline_y0, ...); 0 = none, otherwise at least 2", lo=0, hi=1000)
    box: str = _f("drawn", "str", "the box columns of the track CSV (bbox_x, ...): drawn (when the tracker starts at a template "
                  "drawn with draw --box, that box carried along by the estimate, so that it is scored in the convention "
                  "it was given in; otherwise the contour's box) or outline (always the tight box of the estimated contour); "
                  "either clipped to the frame (the part in view, as benchmark annotations give it)",
                  choices=("drawn", "outline"))


@dataclass(frozen=True)
class CoupledSettings:
    particles: int = _f(400, "int", "samples of the structure's state", lo=10, hi=100_000)
    length_spread: float = _f(0.1, "float", "RMS of a ray's length about the drawn one, as a fraction of it (the internal energy)", lo=0, lo_open=True, hi=2)
    angle_spread: float = _f(0.15, "float", "RMS of a ray's angle about the drawn one, radians (the internal energy)", lo=0, lo_open=True, hi=3.2)
    centre_noise: float = _f(0.05, "float", "RMS change of the centre's velocity per frame, in object sizes", lo=0, lo_open=True, hi=2)
    ray_noise: float = _f(0.02, "float", "RMS change per frame of a ray's length (fraction) and angle (radians)", lo=0, hi=1)
    search: float = _f(0.5, "float", "half-width of each part's search window around its predicted position, in object sizes", lo=0.05, hi=5)
    temperature: float = _f(0.05, "float", "scale of the external energy: a sample's log-weight gains NCC / temperature per part", lo=0.001, hi=10)


@dataclass(frozen=True)
class Settings:
    format: int = _f(FORMAT, "int", "configuration format version", lo=FORMAT, hi=FORMAT)
    shape_space: str = _f("similarity", "str", "shape-space built on the template", choices=("translation", "similarity", "affine"))
    seed: int = _f(0, "int", "random seed", lo=0)
    video: VideoSettings = _section(VideoSettings, "frame input")
    measurement: MeasurementSettings = _section(MeasurementSettings, "features along normals")
    kalman: KalmanSettings = _section(KalmanSettings, "Kalman contour tracker")
    dynamics: DynamicsSettings = _section(DynamicsSettings, "hand-set AR(2) dynamics")
    observation: ObservationSettings = _section(ObservationSettings, "the observation model: how curves are scored on a frame (CONDENSATION's and mht's weights; every contour tracker's confidence)")
    condensation: CondensationSettings = _section(CondensationSettings, "CONDENSATION")
    reacquire: ReacquireSettings = _section(ReacquireSettings, "re-acquisition after loss (CONDENSATION's colour proposal; coupled's part votes)")
    jumps: JumpSettings = _section(JumpSettings, "jumps in the motion prior (CONDENSATION and mht; coupled: fraction and size)")
    mht: MHTSettings = _section(MHTSettings, "mode-based multiple hypotheses (--tracker mht; gates from kalman)")
    coupled: CoupledSettings = _section(CoupledSettings, "coupled structures (--tracker coupled; 003): a centre and rays to parts matched by normalised cross-correlation")
    placement: PlacementSettings = _section(PlacementSettings, "a learned model tracking a clip (track --model)")
    learning: LearningSettings = _section(LearningSettings, "learning dynamics")
    outline: OutlineSettings = _section(OutlineSettings, "the drawn outline: refined in the full image after each frame's estimate")
    output: OutputSettings = _section(OutputSettings, "outputs")
    em: EMSettings = _section(EMSettings, "learning dynamics by EM (learn --method em)")


# ---------------------------------------------------------------------------------------------
# Settings that moved

#: old dotted key -> the key it moved to (read under the old name with a warning)
MOVED: dict[str, str] = {
    **{f"condensation.{k}": f"observation.{k}" for k in ("likelihood", "miss_probability", "colour_weight",
                                                         "still_weight", "discriminant_power", "search", "sigma",
                                                         "alpha")},
    "condensation.reacquire": "reacquire.enabled",
    **{f"condensation.reacquire_{k}": f"reacquire.{k}" for k in ("after", "fraction", "speed", "scale",
                                                                 "scale_reference")},
    **{f"condensation.jump_{k}": f"jumps.{k}" for k in ("fraction", "size", "brake")},
}


def moved_key(dotted: str, where: str = "", *, warn: bool = True) -> str:
    """The current name of a dotted setting key (``dotted`` itself unless it moved, :data:`MOVED`);
    a moved key is warned about, ``where`` (e.g. a file's name) leading the message."""
    new = MOVED.get(dotted)
    if new is None:
        return dotted
    if warn:
        log.warning("%s%s is now %s: read as that (rename it)", f"{where}: " if where else "", dotted, new)
    return new


def _move_old_keys(data: Any, where: str = "", *, warn: bool = True) -> Any:
    """A copy of nested settings ``data`` with every moved key (:data:`MOVED`) under its new name.

    A key given under both names is a ConfigError; anything that is not a mapping of sections
    is left for validation to report.
    """
    if not isinstance(data, Mapping):
        return data
    out = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in data.items()}
    for old, new in MOVED.items():
        section, key = old.split(".")
        here = out.get(section)
        if not isinstance(here, dict) or key not in here:
            continue
        new_section, new_key = new.split(".")
        target = out.setdefault(new_section, {})
        if not isinstance(target, dict):
            continue  # validation reports the section that is no mapping
        if new_key in target:
            raise ConfigError(f"{old}: moved to {new}, and both are given; keep {new}")
        target[new_key] = here.pop(key)
        moved_key(old, where, warn=warn)
    return out


# ---------------------------------------------------------------------------------------------
# Parsing


def _build(cls: type, data: Any, path: str, base: Any = None) -> Any:
    """``cls`` from the settings in ``data``; the ones ``data`` leaves out come from ``base``
    (the section's own defaults) or else the class's."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path or 'config'}: expected a mapping of settings, got {short_repr(data)}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        where = f"{path}.{key}" if path else str(key)
        if key not in fields:
            valid = ", ".join(sorted(fields))
            raise ConfigError(f"{where}: unknown setting (valid here: {valid})")
        fld = fields[key]
        if "spec" in fld.metadata:
            kwargs[key] = fld.metadata["spec"].check(where, value)
        else:
            # a section's defaults may differ from its class's (the translation and deformation
            # dynamics share a class): keys left out keep the section's own
            default = fld.default_factory()  # type: ignore[misc]
            kwargs[key] = _build(type(default), value, where, default)
    return cls(**kwargs) if base is None else dataclasses.replace(base, **kwargs)




def to_dict(settings: Any) -> dict[str, Any]:
    """Plain nested dict of a settings object (for YAML output)."""
    return dataclasses.asdict(settings)


def set_dotted(data: dict, dotted: str, value: Any, label: str = "") -> None:
    """Set ``data["a"]["b"]["c"] = value`` for ``dotted = "a.b.c"``, creating sections; a key
    that moved (:data:`MOVED`) is set under its new name, with a warning.

    A key on the way that holds a single setting is a one-line :class:`ConfigError`
    (prefixed by ``label``, e.g. where the override came from).
    """
    keys = moved_key(dotted, label).split(".")
    node = data
    for i, k in enumerate(keys[:-1]):
        nxt = node.setdefault(k, {})
        if not isinstance(nxt, dict):
            where = ".".join(keys[: i + 1])
            raise ConfigError(f"{label + '.' if label else ''}{where}: expected a mapping of settings, "
                              f"got {short_repr(nxt)}")
        node = nxt
    node[keys[-1]] = value


def _merge(base: dict, overrides: Mapping[str, Any]) -> dict:
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in base.items()}
    for dotted, value in overrides.items():
        if value is not None:
            set_dotted(out, dotted, value)
    return out


def _deep_copy(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _deep_copy(v) for k, v in d.items()}
    return d


#: Folder of the preset configurations shipped with the package (``configs/`` of the source tree).
PRESETS_DIR = Path(__file__).resolve().parent / "configs"


def presets() -> dict[str, Path]:
    """The preset configurations by name (``tight`` for ``configs/tight.yaml``), sorted."""
    if not PRESETS_DIR.is_dir():
        return {}
    return {p.stem: p for p in sorted(PRESETS_DIR.glob("*.yaml"))}


def preset_purpose(path: str | Path) -> str:
    """The one-line purpose of a preset: the first sentence of its leading comment."""
    lines = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        text = line.lstrip("#").strip()
        if not text:
            if lines:
                break
            continue
        lines.append(text)
    para = " ".join(lines)
    end = para.find(". ")
    return para if end < 0 else para[: end + 1]


def resolve_config(name: str | Path) -> Path:
    """A configuration file: ``name`` itself when it is a file, else the preset of that name.

    ``-c tight`` and ``-c tight.yaml`` mean the preset ``tight`` unless a file of that name
    exists in the current folder; a missing file that is no preset is a ConfigError listing
    the presets.
    """
    p = Path(name)
    if p.is_file():
        return p
    key = p.name[:-5] if p.name.endswith(".yaml") else p.name
    known = presets()
    if p.parent == Path(".") and key in known:
        return known[key]
    if p.exists():
        return p  # a folder: read_yaml_file says so
    hint = f" (presets: {', '.join(known)}; see `trackcli config list`)" if known else ""
    raise ConfigError(f"{name}: no such configuration file or preset{hint}")


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Read a configuration file (or preset, see :func:`resolve_config`) into a mapping, with one-line errors."""
    from trackcli.io.outputs import read_yaml_file

    p = resolve_config(path)
    data = read_yaml_file(p, "configuration", ConfigError)
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping of settings at the top level")
    return data


def load_settings(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> Settings:
    """Defaults, then the file at ``path`` (if any), then ``overrides`` (dotted keys)."""
    data: dict[str, Any] = {}
    if path is not None:
        from trackcli.io.outputs import other_kind

        data = read_yaml(path)
        other = other_kind(data)  # a template or a model given for settings
        if other:
            raise ConfigError(f"{path}: {other}, not a configuration; a configuration holds settings "
                              "(see 'trackcli config show')")
    try:
        data = _move_old_keys(data, str(path) if path is not None else "")
        return _build(Settings, _merge(_deep_copy(data), overrides or {}), "")
    except ConfigError as exc:
        if path is not None:
            raise ConfigError(f"{path}: {exc}") from None
        raise


def settings_from_dict(data: Mapping[str, Any]) -> Settings:
    """Validate a mapping (e.g. the settings stored in a model file); keys that moved
    (:data:`MOVED`, e.g. in a model learned before they moved) are read under their new names."""
    return _build(Settings, _move_old_keys(dict(data), warn=False), "")


def replace(settings: Settings, overrides: Mapping[str, Any]) -> Settings:
    """A copy of ``settings`` with dotted-key ``overrides`` applied and validated."""
    return _build(Settings, _merge(to_dict(settings), overrides), "")


def dump_yaml(settings: Settings) -> str:
    """The effective settings as YAML text."""
    return yaml.safe_dump(to_dict(settings), sort_keys=False, default_flow_style=False)


def describe_settings() -> list[tuple[str, str, Any, str]]:
    """(dotted key, accepted values, default, meaning) for every setting: used for docs and tests."""
    rows: list[tuple[str, str, Any, str]] = []

    def walk(cls: type, obj: Any, prefix: str) -> None:
        for f in dataclasses.fields(cls):
            key = f"{prefix}{f.name}"
            if "spec" in f.metadata:
                spec: _Spec = f.metadata["spec"]
                rows.append((key, spec.describe(), getattr(obj, f.name), spec.doc))
            else:
                sub = getattr(obj, f.name)
                walk(type(sub), sub, key + ".")

    walk(Settings, Settings(), "")
    return rows


def render_commented(settings: Settings | None = None) -> str:
    """YAML text of ``settings`` (defaults if None) with every setting explained in a comment."""
    settings = settings or Settings()
    lines = [
        "# trackcli configuration. Every key is optional: a missing key takes the value shown here.",
        "# Command-line options (e.g. --particles, --seed) override what a file says.",
    ]

    def scalar(v: Any) -> str:
        return yaml.safe_dump(v, default_flow_style=True).strip().removesuffix("...").strip()

    def walk(cls: type, obj: Any, indent: str) -> None:
        for f in dataclasses.fields(cls):
            if "spec" in f.metadata:
                spec: _Spec = f.metadata["spec"]
                value = scalar(getattr(obj, f.name))
                lines.append(f"{indent}{f.name}: {value}".ljust(34) + f"  # {spec.doc}; {spec.describe()}")
            else:
                lines.append("")
                lines.append(f"{indent}# {f.metadata.get('doc', f.name)}")
                lines.append(f"{indent}{f.name}:")
                sub = getattr(obj, f.name)
                walk(type(sub), sub, indent + "  ")

    walk(Settings, settings, "")
    return "\n".join(lines) + "\n"
