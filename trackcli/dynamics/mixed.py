"""Mixed-state models: a discrete motion label beside the shape (001 §8; SPEC §6).

Every sample carries a label ``y ∈ {0..Ns-1}`` next to its shape.  One prediction step
(001 §8) first draws the new label ``y_k = j`` with probability ``T[i, j]``, ``i`` the
sample's old label, and then draws the continuous state from the model of the *old* label,
``X_k ~ p_i(X_k | X_{k-1}, X_{k-2})``.  A label's model is an AR(2) process (hand-set, as
the configuration's ``dynamics`` section, or learned) or an *event*: the bounce of 001 §8,
the velocity component normal to a reflecting line reversed with a restitution factor in one
step.

A mixed-state model file is YAML::

    format: 1
    kind: trackcli-mixed
    labels:
      - name: flight
        dynamics:                  # hand-set AR(2): the keys of the `dynamics` settings
          translation: {f: 0, beta: 0, rho: null, gamma0: 6}
      - name: bounce
        bounce: {base: flight, floor: 318, restitution: 0.8, noise: 0.03}
    transitions:                   # T[i][j] = P(y_k = j | y_{k-1} = i): rows sum to 1
      - [0.9, 0.1]
      - [1.0, 0.0]
    initial: [1.0, 0.0]            # optional; default: the stationary distribution of T

A learned label has ``ar2: {tau, mean, A2, A1, B0}`` instead of ``dynamics``; the file then
also holds the ``template`` and ``shape_space`` it was learned in (``trackcli learn
--labels``), and is placed on a new clip by a template as a single model is.

This module holds the model (:class:`MixedModel`), its transition matrix, its file and its
learning from labelled frame ranges (:func:`learn_mixed`); the dynamics it makes on a clip's
shape-space, the prediction step and the bounce event (what the keys of ``bounce:`` mean),
are in :mod:`trackcli.dynamics.mixed_dynamics`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from trackcli.dynamics.ar2 import AR2
from trackcli.errors import ConfigError, DataError, ModelError
from trackcli.settings import DynamicsSettings

FORMAT = 1
KIND = "trackcli-mixed"
#: tolerance on a row of T summing to 1
ROW_TOLERANCE = 1e-6
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*\Z")


@dataclass(frozen=True)
class BounceSpec:
    """The bounce event of 001 §8, as written in a model file (see the module docstring)."""

    base: str
    point: tuple[float, float]
    normal: tuple[float, float]
    restitution: float = 0.8
    friction: float = 1.0
    noise: float = 0.1

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"base": self.base}
        if self.normal == (0.0, -1.0):
            d["floor"] = self.point[1]
        else:
            d["line"] = {"point": list(self.point), "normal": list(self.normal)}
        d.update(restitution=self.restitution, friction=self.friction, noise=self.noise)
        return d


@dataclass(frozen=True)
class LabelSpec:
    """One label: its name and exactly one of ``ar2`` (learned), ``handset``, ``bounce``."""

    name: str
    ar2: AR2 | None = None
    handset: DynamicsSettings | None = None
    handset_raw: dict[str, Any] | None = None
    bounce: BounceSpec | None = None

    @property
    def kind(self) -> str:
        return "ar2" if self.ar2 is not None else "handset" if self.handset is not None else "bounce"

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name}
        if self.ar2 is not None:
            d["ar2"] = self.ar2.to_dict()
        elif self.handset is not None:
            d["dynamics"] = self.handset_raw or {}
        else:
            assert self.bounce is not None
            d["bounce"] = self.bounce.to_dict()
        return d


@dataclass(frozen=True, eq=False)
class MixedModel:
    """A mixed-state model file: labels, transition matrix, initial label distribution.

    ``template`` and ``shape_space`` are present when the labels were learned (the AR(2)
    matrices are in that shape-space's coordinates).
    """

    labels: tuple[LabelSpec, ...]
    T: np.ndarray
    initial: np.ndarray | None = None
    template: Any = None
    space: Any = None
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        return [lab.name for lab in self.labels]

    def initial_distribution(self) -> np.ndarray:
        return self.initial if self.initial is not None else stationary_distribution(self.T)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": FORMAT, "kind": KIND}
        if self.template is not None:
            d["template"] = self.template.to_dict()
            d["shape_space"] = self.space.to_dict()
        d["labels"] = [lab.to_dict() for lab in self.labels]
        d["transitions"] = [[float(v) for v in row] for row in self.T]
        if self.initial is not None:
            d["initial"] = [float(v) for v in self.initial]
        if self.provenance:
            d["provenance"] = self.provenance
        return d


# ---------------------------------------------------------------------------------------------
# Transition matrices


def check_transitions(T: Any, n: int | None = None, where: str = "transitions") -> np.ndarray:
    """``T`` as a float array, checked: square (``n × n``), entries in [0, 1], rows summing to 1.

    Raises :class:`~trackcli.errors.ModelError` naming the key path of the first fault.
    """
    if isinstance(T, (str, bytes, Mapping)) or not isinstance(T, Sequence | np.ndarray):
        raise ModelError(f"{where}: expected a list of rows of probabilities, got {T!r}")
    rows = list(T)
    size = len(rows) if n is None else n
    if len(rows) != size:
        raise ModelError(f"{where}: expected {size} rows (one per label), got {len(rows)}")
    out = np.empty((size, size))
    for i, row in enumerate(rows):
        if isinstance(row, (str, bytes, Mapping)) or not isinstance(row, Sequence | np.ndarray) or len(row) != size:
            raise ModelError(f"{where}[{i}]: expected a row of {size} probabilities, got {row!r}")
        for j, v in enumerate(row):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise ModelError(f"{where}[{i}][{j}]: expected a probability, got {v!r}")
            if not 0.0 <= float(v) <= 1.0:
                raise ModelError(f"{where}[{i}][{j}]: a probability must lie in [0, 1], got {v}")
            out[i, j] = float(v)
        total = float(out[i].sum())
        if abs(total - 1.0) > ROW_TOLERANCE:
            raise ModelError(f"{where}[{i}]: the probabilities of leaving label {i} must sum to 1, got {total:.6g}")
    out /= out.sum(axis=1, keepdims=True)
    return out


def stationary_distribution(T: np.ndarray) -> np.ndarray:
    """The distribution ``π`` with ``π T = π`` (least squares with ``Σ π = 1``; clipped at 0)."""
    n = T.shape[0]
    A = np.vstack([T.T - np.eye(n), np.ones((1, n))])
    b = np.zeros(n + 1)
    b[-1] = 1.0
    pi, *_ = np.linalg.lstsq(A, b, rcond=None)
    pi = np.clip(pi, 0.0, None)
    return pi / pi.sum() if pi.sum() > 0 else np.full(n, 1.0 / n)


def transitions_from_labels(sequences: Sequence[np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    """Maximum-likelihood ``T`` from label sequences: the counts of ``i → j`` over consecutive
    frames, each row normalised.  A label never left stays put (``T[i, i] = 1``).

    Returns ``(T, counts)``.
    """
    counts = np.zeros((n, n))
    for seq in sequences:
        s = np.asarray(seq, dtype=np.int64)
        if s.size >= 2:
            np.add.at(counts, (s[:-1], s[1:]), 1.0)
    T = counts.copy()
    for i in range(n):
        total = T[i].sum()
        if total > 0:
            T[i] /= total
        else:
            T[i, i] = 1.0
    return T, counts


# ---------------------------------------------------------------------------------------------
# Files


def is_mixed_file(path: str | Path) -> bool:
    """True when ``path`` is a YAML file of kind ``trackcli-mixed`` (cheap: reads the mapping)."""
    from trackcli.io.outputs import read_yaml_file

    try:
        d = read_yaml_file(Path(path), "model", ModelError)
    except Exception:
        return False
    return isinstance(d, dict) and d.get("kind") == KIND


def _number(where: str, v: Any, *, lo: float | None = None, hi: float | None = None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ModelError(f"{where}: expected a number, got {v!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ModelError(f"{where}: expected a number in [{lo}, {hi}], got {v}")
    return float(v)


def _pair(where: str, v: Any) -> tuple[float, float]:
    if isinstance(v, (str, bytes, Mapping)) or not isinstance(v, Sequence) or len(v) != 2:
        raise ModelError(f"{where}: expected two numbers [x, y], got {v!r}")
    return _number(f"{where}[0]", v[0]), _number(f"{where}[1]", v[1])


def _bounce(d: Any, where: str) -> BounceSpec:
    keys = {"base", "floor", "line", "restitution", "friction", "noise"}
    if not isinstance(d, Mapping):
        raise ModelError(f"{where}: expected a mapping with keys {', '.join(sorted(keys))}, got {d!r}")
    unknown = sorted(str(k) for k in d if k not in keys)
    if unknown:
        raise ModelError(f"{where}: unknown key(s) {', '.join(unknown)} (valid: {', '.join(sorted(keys))})")
    if "base" not in d or not isinstance(d["base"], str):
        raise ModelError(f"{where}.base: name the AR(2) label that moves the other shape components")
    if ("floor" in d) == ("line" in d):
        raise ModelError(f"{where}: give exactly one of floor (y of a horizontal line, px) or "
                         "line ({point: [x, y], normal: [nx, ny]})")
    if "floor" in d:
        point, normal = (0.0, _number(f"{where}.floor", d["floor"])), (0.0, -1.0)
    else:
        line = d["line"]
        if not isinstance(line, Mapping) or set(line) != {"point", "normal"}:
            raise ModelError(f"{where}.line: expected {{point: [x, y], normal: [nx, ny]}}, got {line!r}")
        point = _pair(f"{where}.line.point", line["point"])
        nx, ny = _pair(f"{where}.line.normal", line["normal"])
        norm = math.hypot(nx, ny)
        if norm == 0:
            raise ModelError(f"{where}.line.normal: must not be zero")
        normal = (nx / norm, ny / norm)
    return BounceSpec(base=d["base"], point=point, normal=normal,
                      restitution=_number(f"{where}.restitution", d.get("restitution", 0.8), lo=0, hi=1),
                      friction=_number(f"{where}.friction", d.get("friction", 1.0), lo=0, hi=1),
                      noise=_number(f"{where}.noise", d.get("noise", 0.1), lo=0, hi=10))


def _label(d: Any, where: str) -> LabelSpec:
    from trackcli.settings import _build

    if not isinstance(d, Mapping):
        raise ModelError(f"{where}: expected a mapping with a name and one of dynamics, ar2, bounce; got {d!r}")
    name = d.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        raise ModelError(f"{where}.name: expected a name of letters, digits, _ or - starting with a letter "
                         f"(it becomes the CSV column p_NAME), got {name!r}")
    unknown = sorted(str(k) for k in d if k not in ("name", "dynamics", "ar2", "bounce"))
    if unknown:
        raise ModelError(f"{where}: unknown key(s) {', '.join(unknown)} (valid: name, dynamics, ar2, bounce)")
    given = [k for k in ("dynamics", "ar2", "bounce") if k in d]
    if len(given) != 1:
        raise ModelError(f"{where} ({name}): give exactly one of dynamics (hand-set AR(2)), ar2 (learned) or "
                         f"bounce (event), got {', '.join(given) or 'none'}")
    kind = given[0]
    if kind == "ar2":
        return LabelSpec(name, ar2=AR2.from_dict(d["ar2"], f"{where}.ar2"))
    if kind == "bounce":
        return LabelSpec(name, bounce=_bounce(d["bounce"], f"{where}.bounce"))
    raw = d["dynamics"] if d["dynamics"] is not None else {}
    if not isinstance(raw, Mapping):
        raise ModelError(f"{where}.dynamics: expected a mapping (the keys of the dynamics settings), got {raw!r}")
    try:
        handset = _build(DynamicsSettings, dict(raw), f"{where}.dynamics")
    except ConfigError as exc:
        raise ModelError(str(exc)) from None
    return LabelSpec(name, handset=handset, handset_raw=dict(raw))


def mixed_from_dict(d: Any, where: str = "mixed model") -> MixedModel:
    """Validate a mixed-state model mapping; errors name the key path."""
    from trackcli.shapes.shape_space import ShapeSpace
    from trackcli.shapes.template import Template

    if not isinstance(d, Mapping) or d.get("kind") != KIND:
        raise ModelError(f"{where}: not a mixed-state model (expected kind: {KIND})")
    if d.get("format") != FORMAT:
        raise ModelError(f"{where}: unsupported format {d.get('format')!r} (this version reads {FORMAT})")
    known = {"format", "kind", "labels", "transitions", "initial", "template", "shape_space", "provenance"}
    unknown = sorted(str(k) for k in d if k not in known)
    if unknown:
        raise ModelError(f"{where}: unknown key(s) {', '.join(unknown)} (valid: {', '.join(sorted(known))})")
    raw = d.get("labels")
    if not isinstance(raw, list) or len(raw) < 2:
        raise ModelError(f"{where}: labels: expected a list of at least two labels")
    labels = tuple(_label(item, f"labels[{i}]") for i, item in enumerate(raw))
    names = [lab.name for lab in labels]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ModelError(f"labels: names must be unique, {', '.join(dup)} repeats")
    for i, lab in enumerate(labels):
        if lab.bounce is not None:
            base = lab.bounce.base
            if base not in names or labels[names.index(base)].bounce is not None:
                raise ModelError(f"labels[{i}].bounce.base: {base!r} is not an AR(2) label "
                                 f"(AR(2) labels: {', '.join(n for n, x in zip(names, labels) if x.bounce is None)})")
    if "transitions" not in d:
        raise ModelError(f"{where}: missing transitions (the {len(labels)}x{len(labels)} matrix T)")
    T = check_transitions(d["transitions"], len(labels))
    initial = None
    if d.get("initial") is not None:
        init = d["initial"]
        if isinstance(init, (str, bytes, Mapping)) or not isinstance(init, Sequence) or len(init) != len(labels):
            raise ModelError(f"initial: expected {len(labels)} probabilities (one per label), got {init!r}")
        initial = np.array([_number(f"initial[{i}]", v, lo=0, hi=1) for i, v in enumerate(init)])
        if abs(initial.sum() - 1.0) > ROW_TOLERANCE:
            raise ModelError(f"initial: the probabilities must sum to 1, got {initial.sum():.6g}")
    template = space = None
    learned = [lab.name for lab in labels if lab.ar2 is not None]
    if ("template" in d) != ("shape_space" in d):
        raise ModelError(f"{where}: template and shape_space go together (both or neither)")
    if "template" in d:
        template = Template.from_dict(d["template"])
        space = ShapeSpace.from_dict(d["shape_space"])
        for i, lab in enumerate(labels):
            if lab.ar2 is not None and lab.ar2.nx != space.Nx:
                raise ModelError(f"labels[{i}].ar2: {lab.ar2.nx} components, the shape_space has {space.Nx}")
    elif learned:
        raise ModelError(f"{where}: learned label(s) {', '.join(learned)} need the template and shape_space "
                         "they were learned in")
    prov = d.get("provenance") or {}
    return MixedModel(labels, T, initial, template, space, dict(prov) if isinstance(prov, Mapping) else {})


def load_mixed(path: str | Path) -> MixedModel:
    """Read and validate a mixed-state model file; errors name the file and the key."""
    from trackcli.io.outputs import read_yaml_file

    p = Path(path)
    d = read_yaml_file(p, "model", ModelError)
    try:
        return mixed_from_dict(d, str(p))
    except ModelError as exc:
        msg = str(exc)
        raise ModelError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


def save_mixed(path: str | Path, model: MixedModel) -> Path:
    """Write a mixed-state model file atomically."""
    from trackcli.io.outputs import write_text

    return write_text(path, "# trackcli mixed-state model (see `trackcli inspect`)\n"
                      + yaml.safe_dump(model.to_dict(), sort_keys=False, default_flow_style=None, width=120))


# ---------------------------------------------------------------------------------------------
# Labelled frame ranges and learning


def read_label_ranges(path: str | Path) -> list[tuple[int, int, str]]:
    """``start,end,label`` rows (frames inclusive, counted from 0) of a CSV or YAML file.

    CSV: an optional header ``start,end,label``; YAML: a list of ``{start, end, label}``.
    Ranges must not overlap.
    """
    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: no such labels file")
    text = p.read_text(encoding="utf-8")
    rows: list[tuple[Any, Any, Any]] = []
    if p.suffix.lower() in (".yaml", ".yml"):
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise DataError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None
        if not isinstance(data, list):
            raise DataError(f"{p}: expected a list of {{start, end, label}}")
        for i, item in enumerate(data):
            if not isinstance(item, Mapping) or set(item) != {"start", "end", "label"}:
                raise DataError(f"{p}: item {i}: expected {{start, end, label}}, got {item!r}")
            rows.append((item["start"], item["end"], item["label"]))
    else:
        for ln, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            cells = [c.strip() for c in line.split(",")]
            if cells == ["start", "end", "label"]:
                continue
            if len(cells) != 3:
                raise DataError(f"{p}:{ln}: expected start,end,label, got {line!r}")
            rows.append((cells[0], cells[1], cells[2]))
    out: list[tuple[int, int, str]] = []
    for i, (s, e, lab) in enumerate(rows):
        try:
            a, b = int(s), int(e)
        except (TypeError, ValueError):
            raise DataError(f"{p}: range {i + 1}: start and end must be frame numbers, got {s!r}, {e!r}") from None
        if a < 0 or b < a:
            raise DataError(f"{p}: range {i + 1}: expected 0 <= start <= end, got {a}, {b}")
        if not isinstance(lab, str) or not _NAME.match(lab):
            raise DataError(f"{p}: range {i + 1}: label {lab!r} must be letters, digits, _ or - starting with a letter")
        out.append((a, b, lab))
    if not out:
        raise DataError(f"{p}: no labelled ranges")
    out.sort()
    for (a0, b0, _), (a1, _, _) in zip(out, out[1:]):
        if a1 <= b0:
            raise DataError(f"{p}: ranges {a0}-{b0} and {a1}-... overlap")
    return out


def learn_mixed(sequences: Sequence[np.ndarray], labels: Sequence[np.ndarray], names: Sequence[str], tau: float,
                *, max_spectral_radius: float = 0.99) -> tuple[list[AR2], np.ndarray, dict[str, Any]]:
    """One AR(2) per label (pooled MLE over its runs of frames) and ``T`` from the label sequences.

    ``sequences[c]`` is ``(M_c, Nx)`` shapes, ``labels[c]`` the label index of each frame
    (-1: unlabelled, left out).  A label's runs are its maximal stretches of consecutive
    frames; each run of at least 3 frames gives frame triples.  Returns the models, ``T`` and
    a report (triples and residual RMS per label, transition counts).
    """
    from trackcli.dynamics.learning import fit_ar2

    n = len(names)
    runs: list[list[np.ndarray]] = [[] for _ in range(n)]
    for X, lab in zip(sequences, labels):
        X = np.asarray(X, dtype=float)
        lab = np.asarray(lab, dtype=np.int64)
        if len(lab) != len(X):
            raise DataError(f"labels cover {len(lab)} frames, the track has {len(X)}")
        start = 0
        for k in range(1, len(lab) + 1):
            if k == len(lab) or lab[k] != lab[start]:
                if lab[start] >= 0 and k - start >= 3:
                    runs[lab[start]].append(X[start:k])
                start = k
    models: list[AR2] = []
    report: dict[str, Any] = {"labels": {}}
    for i, name in enumerate(names):
        if not runs[i]:
            raise DataError(f"label {name}: no run of 3 or more consecutive frames to learn AR(2) dynamics from; "
                            "an event label (bounce) is written into the model file by hand")
        try:
            model, rep = fit_ar2(runs[i], tau, enforce_stability=False, max_spectral_radius=max_spectral_radius)
        except DataError as exc:
            raise DataError(f"label {name}: {exc}") from None
        models.append(model)
        report["labels"][name] = {"runs": len(runs[i]), "triples": rep.n_triples,
                                  "residual_rms": rep.residual_rms, "spectral_radius": rep.spectral_radius}
    segments = []
    for lab in labels:
        lab = np.asarray(lab, dtype=np.int64)
        # transitions only between labelled neighbours
        cut = np.flatnonzero(lab < 0)
        for piece in np.split(lab, cut):
            piece = piece[piece >= 0]
            if piece.size:
                segments.append(piece)
    T, counts = transitions_from_labels(segments, n)
    report["transition_counts"] = counts.astype(int).tolist()
    return models, T, report
