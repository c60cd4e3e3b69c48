"""Tests for trackcli.settings: defaults, key-path errors, overrides, YAML errors, committed configs."""

from __future__ import annotations

import dataclasses
import re

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import CONFIGS
from trackcli.settings import (
    Settings,
    describe_settings,
    dump_yaml,
    load_settings,
    render_commented,
    replace,
    settings_from_dict,
    to_dict,
)
from trackcli.errors import ConfigError


def nested(dotted: str, value) -> dict:
    """``"a.b.c", v`` -> ``{"a": {"b": {"c": v}}}``."""
    keys = dotted.split(".")
    out: dict = {keys[-1]: value}
    for k in reversed(keys[:-1]):
        out = {k: out}
    return out


def write(tmp_path, text: str, name: str = "c.yaml"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# ---------------------------------------------------------------------------------------------
# Defaults


def test_defaults_load_without_a_file():
    s = load_settings()
    assert s == Settings()
    assert s.format == 1
    assert s.shape_space == "similarity"
    assert s.measurement.n_normals == 24
    assert s.kalman.rho_f == 1.0
    assert s.condensation.particles == 500
    # hand-set dynamics in units of the object: a damped velocity with a free position for
    # translation, a deformation that returns to the template
    assert s.dynamics.units == "object"
    assert s.dynamics.translation.rho is None and s.dynamics.translation.gamma0 == 5.0
    assert s.dynamics.deformation.rho == 0.1  # the deformation section has its own defaults
    assert s.observation.likelihood == "discriminant"
    assert s.video.fps is None and s.video.end is None


def test_settings_are_frozen():
    s = load_settings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.seed = 3  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.kalman.rho_f = 1.0  # type: ignore[misc]


def test_empty_file_gives_defaults(tmp_path):
    assert load_settings(write(tmp_path, "")) == Settings()
    assert load_settings(write(tmp_path, "# only a comment\n", "d.yaml")) == Settings()


def test_describe_settings_lists_every_leaf_with_its_default():
    rows = describe_settings()
    keys = [r[0] for r in rows]
    assert len(keys) == len(set(keys))
    flat: dict = {}

    def walk(d, prefix):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}{k}.")
            else:
                flat[f"{prefix}{k}"] = v

    walk(to_dict(Settings()), "")
    assert set(keys) == set(flat)
    for key, accepted, default, meaning in rows:
        assert flat[key] == default, key
        assert accepted and meaning, key


# ---------------------------------------------------------------------------------------------
# Invalid values: the message starts with the dotted key path and says what was expected

INVALID = [
    # (dotted key, bad value, text that must follow "<key>: ")
    ("measurement.n_normals", "abc", "expected an integer in [3, 1000], got 'abc'"),  # wrong type
    ("kalman.rho_f", "5", "expected a number > 0, got '5'"),  # number given as a string
    ("measurement.n_normals", 2, "expected an integer in [3, 1000], got 2"),  # below range
    ("measurement.n_normals", 1001, "expected an integer in [3, 1000], got 1001"),  # above range
    ("kalman.kappa", 0, "expected a number in (0, 10], got 0"),  # open lower bound
    ("kalman.rho_f", 0.0, "expected a number > 0, got 0.0"),
    ("condensation.ess_threshold", 1.5, "expected a number in (0, 1] or null, got 1.5"),
    ("kalman.rho_f", float("inf"), "expected a number > 0, got inf"),  # not finite
    ("kalman.rho_f", float("nan"), "expected a number > 0, got nan"),
    ("seed", 2.5, "expected an integer >= 0, got 2.5"),  # non-integral float for an int
    ("seed", -1, "expected an integer >= 0, got -1"),
    ("shape_space", "rigid", "expected one of 'translation', 'similarity', 'affine', got 'rigid'"),
    ("condensation.resampling", "residual", "expected one of 'multinomial', 'systematic', 'stratified'"),
    ("measurement.channel", 3, "expected one of 'grey', 'b', 'g', 'r', 'skin', got 3"),
    ("seed", None, "expected an integer >= 0, got null"),  # null where not allowed
    ("kalman.init", None, "expected one of 'static', 'unknown', got null"),
    ("seed", True, "expected an integer >= 0, got True"),  # bool for an int
    ("condensation.particles", False, "expected an integer in [1, 1000000], got False"),
    ("kalman.rho_f", True, "expected a number > 0, got True"),  # bool for a float
    ("learning.enforce_stability", 1, "expected true or false, got 1"),  # int for a bool
    ("output.rrd", "yes", "expected true or false, got 'yes'"),
    ("format", 2, "expected an integer in [1, 1], got 2"),  # a future format
    ("dynamics.translation.rho", 0, "expected a number > 0 or null, got 0"),
    ("dynamics.deformation.beta", [1, 2], "expected a number >= 0, got [1, 2]"),
    ("kalman", 3, "expected a mapping of settings, got 3"),  # a section given as a scalar
    ("dynamics.translation", "fast", "expected a mapping of settings, got 'fast'"),
    ("video", None, "expected a mapping of settings, got None"),
    ("condensation", [500], "expected a mapping of settings, got [500]"),
]


@pytest.mark.parametrize(("key", "value", "reason"), INVALID, ids=[f"{k}={v!r}" for k, v, _ in INVALID])
def test_invalid_value_names_key_path_and_expectation(key, value, reason):
    with pytest.raises(ConfigError) as info:
        settings_from_dict(nested(key, value))
    assert str(info.value).startswith(f"{key}: {reason}")


@pytest.mark.parametrize(
    ("data", "path"),
    [
        ({"sede": 1}, "sede"),
        ({"kalman": {"rhof": 1.0}}, "kalman.rhof"),
        ({"dynamics": {"translation": {"foo": 1}}}, "dynamics.translation.foo"),
        ({"dynamics": {"rotation": {}}}, "dynamics.rotation"),
    ],
)
def test_unknown_key_names_path_and_valid_keys(data, path):
    with pytest.raises(ConfigError) as info:
        settings_from_dict(data)
    msg = str(info.value)
    assert msg.startswith(f"{path}: unknown setting (valid here: ")
    parent = path.rpartition(".")[0]
    valid = [r[0].rpartition(".")[2] for r in describe_settings() if r[0].rpartition(".")[0] == parent]
    if parent == "dynamics":
        valid = ["deformation", "translation", "units"]
    elif parent == "":
        valid = [f.name for f in dataclasses.fields(Settings)]
    assert re.search(r"\(valid here: (.*)\)$", msg).group(1) == ", ".join(sorted(valid))


def test_error_on_file_prefixes_the_file_then_the_key_path(tmp_path):
    p = write(tmp_path, "measurement:\n  n_normals: abc\n")
    with pytest.raises(ConfigError) as info:
        load_settings(p)
    assert str(info.value) == f"{p}: measurement.n_normals: expected an integer in [3, 1000], got 'abc'"


@pytest.mark.parametrize("kind", ["trackcli-template", "trackcli-model"])
def test_a_template_or_model_given_as_configuration_is_named_as_such(tmp_path, kind):
    p = tmp_path / "t.yaml"
    p.write_text(f"format: 1\nkind: {kind}\nclosed: true\n")
    with pytest.raises(ConfigError, match=f"a {kind[9:]} file \\(kind: {kind}\\), not a configuration"):
        load_settings(p)


def test_a_model_given_as_template_and_a_template_as_model_are_named_as_such(tmp_path):
    """The message says which file it is; a file of no kind (a configuration, a truth CSV) is
    said not to be a template, with the command that writes one."""
    from trackcli.dynamics.model import load_model
    from trackcli.errors import ModelError, TemplateError
    from trackcli.shapes.template import load_template

    model, template, other = tmp_path / "m.yaml", tmp_path / "t.yaml", tmp_path / "c.yaml"
    model.write_text("format: 1\nkind: trackcli-model\n")
    template.write_text("format: 1\nkind: trackcli-template\nclosed: true\n")
    other.write_text("condensation:\n  n_samples: 300\n")
    with pytest.raises(TemplateError, match=r"a model file \(kind: trackcli-model\), not a template"):
        load_template(model)
    with pytest.raises(ModelError, match=r"a template file \(kind: trackcli-template\), not a model"):
        load_model(template)
    for p in (other, CONFIGS / "default.yaml"):
        with pytest.raises(TemplateError, match="not a trackcli template .*'trackcli draw'"):
            load_template(p)


def test_config_error_is_also_a_value_error():
    with pytest.raises(ValueError):
        settings_from_dict({"seed": -3})


@pytest.mark.parametrize(
    ("key", "value", "stored"),
    [
        ("seed", 3.0, 3),  # an integral float is an integer
        ("video.fps", None, None),  # null where allowed
        ("condensation.ess_threshold", 1, 1.0),  # an int is a number; the closed upper bound
        ("kalman.min_gate", 0, 0.0),  # the closed lower bound
        ("measurement.n_normals", 3, 3),
        ("measurement.n_normals", 1000, 1000),
        ("dynamics.translation.gamma0", 40.0, 40.0),
        ("learning.enforce_stability", False, False),
    ],
)
def test_valid_edge_values_are_accepted(key, value, stored):
    s = settings_from_dict(nested(key, value))
    node = s
    for k in key.split("."):
        node = getattr(node, k)
    assert node == stored
    assert type(node) is type(stored)


# ---------------------------------------------------------------------------------------------
# Overrides


def test_overrides_beat_file_values_and_defaults_fill_the_rest(tmp_path):
    p = write(tmp_path, "seed: 5\ncondensation:\n  particles: 200\n  init_speed: 2.5\n")
    s = load_settings(p, {"condensation.particles": 800, "kalman.rho_f": 7.0})
    assert s.condensation.particles == 800  # override beats the file
    assert s.condensation.init_speed == 2.5  # the file's sibling survives the override
    assert s.seed == 5  # file value kept
    assert s.kalman.rho_f == 7.0  # override into a section the file does not mention
    assert s.kalman.kappa == Settings().kalman.kappa


def test_a_section_given_in_part_keeps_its_own_defaults_for_the_rest(tmp_path):
    """The translation and deformation dynamics share a class whose field defaults are neither's:
    a file that sets one key of a section gets that section's defaults for the others."""
    d = Settings().dynamics
    p = write(tmp_path, "dynamics:\n  deformation:\n    beta: 0.5\n  translation:\n    beta: 1.0\n")
    s = load_settings(p).dynamics
    assert s.deformation == dataclasses.replace(d.deformation, beta=0.5)
    assert s.translation == dataclasses.replace(d.translation, beta=1.0)
    assert s.deformation.rho == 0.1 and s.translation.rho is None and s.translation.gamma0 == 5.0
    # the same through dotted overrides, and from a stored mapping (a model file's settings)
    assert load_settings(None, {"dynamics.deformation.beta": 0.5}).dynamics.deformation.rho == d.deformation.rho
    stored = settings_from_dict({"dynamics": {"translation": {"f": 0.0}}}).dynamics.translation
    assert stored == d.translation


def test_none_overrides_leave_file_values(tmp_path):
    p = write(tmp_path, "seed: 5\n")
    assert load_settings(p, {"seed": None, "video.fps": None}).seed == 5


def test_overrides_are_validated_with_key_paths(tmp_path):
    with pytest.raises(ConfigError, match=r"^condensation\.particles: expected an integer in \[1, 1000000\], got 0$"):
        load_settings(None, {"condensation.particles": 0})
    p = write(tmp_path, "seed: 5\n")
    with pytest.raises(ConfigError) as info:
        load_settings(p, {"condensation.particles": 0})
    assert str(info.value) == f"{p}: condensation.particles: expected an integer in [1, 1000000], got 0"
    with pytest.raises(ConfigError, match=r"^kalman\.bogus: unknown setting"):
        load_settings(None, {"kalman.bogus": 1})


def test_override_into_a_section_given_as_a_scalar_is_a_config_error(tmp_path):
    # e.g. `video: 3` in the file and --fps on the command line
    p = write(tmp_path, "video: 3\n")
    with pytest.raises(ConfigError) as info:
        load_settings(p, {"video.fps": 10.0})
    assert str(info.value) == f"{p}: video: expected a mapping of settings, got 3"


def test_replace_applies_and_validates_overrides():
    s = replace(Settings(), {"dynamics.deformation.rho": 4.0, "seed": 9})
    assert s.dynamics.deformation.rho == 4.0 and s.seed == 9
    assert s.dynamics.translation == Settings().dynamics.translation
    with pytest.raises(ConfigError, match=r"^dynamics\.deformation\.rho: "):
        replace(Settings(), {"dynamics.deformation.rho": -1.0})


# ---------------------------------------------------------------------------------------------
# Files that are not valid YAML, or not a mapping


@pytest.mark.parametrize(
    ("text", "line"),
    [
        ("seed: 1\nkalman:\n  rho_f: 2\n   kappa: 3\nvideo:\n  step: 2\n", 4),  # bad indentation
        ("seed: 1\nkalman: {rho_f: 2\nvideo:\n  step: 2\n", 3),  # unclosed flow mapping
        ("seed: 1\n\tkalman: 2\n", 2),  # a tab
    ],
)
def test_yaml_syntax_error_names_the_line(tmp_path, text, line):
    p = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_settings(p)
    msg = str(info.value)
    assert msg.startswith(f"{p} line {line}: ")
    assert "\n" not in msg


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="no such configuration file"):
        load_settings(tmp_path / "absent.yaml")


@pytest.mark.parametrize("text", ["- 1\n- 2\n", "just a string\n", "42\n"])
def test_top_level_must_be_a_mapping(tmp_path, text):
    with pytest.raises(ConfigError, match="expected a mapping of settings at the top level"):
        load_settings(write(tmp_path, text))


def test_binary_file_is_a_config_error(tmp_path):
    p = tmp_path / "bin.yaml"
    p.write_bytes(b"\xff\xfe\x00\x01")
    with pytest.raises(ConfigError, match=r"cannot read configuration file \(not a text file: configuration files are "
                                          r"UTF-8 YAML\)"):
        load_settings(p)


# ---------------------------------------------------------------------------------------------
# Committed configuration files


COMMITTED = sorted(CONFIGS.glob("*.yaml"))


def test_default_config_is_committed():
    assert (CONFIGS / "default.yaml").is_file()


@pytest.mark.parametrize("path", COMMITTED, ids=[p.name for p in COMMITTED])
def test_committed_configs_validate(path):
    load_settings(path)


def test_default_yaml_is_exactly_the_commented_defaults():
    committed = (CONFIGS / "default.yaml").read_text(encoding="utf-8")
    assert committed == render_commented(), (
        "configs/default.yaml drifted from the code: regenerate it with "
        "`trackcli config show --comments > configs/default.yaml`"
    )


def test_commented_defaults_load_back_to_defaults():
    assert settings_from_dict(yaml.safe_load(render_commented())) == Settings()
    assert settings_from_dict(yaml.safe_load(dump_yaml(Settings()))) == Settings()


def test_every_setting_is_explained_in_the_commented_file():
    text = render_commented()
    for key, accepted, _default, meaning in describe_settings():
        leaf = key.rpartition(".")[2]
        assert re.search(rf"^\s*{leaf}: .*# {re.escape(meaning)}; {re.escape(accepted)}$", text, re.M), key


# ---------------------------------------------------------------------------------------------
# Property: any valid settings survive both YAML renderings unchanged


def _leaf_strategy(spec) -> st.SearchStrategy:
    if spec.choices is not None:
        base = st.sampled_from(spec.choices)
    elif spec.kind == "bool":
        base = st.booleans()
    elif spec.kind == "str":
        base = st.text(min_size=1, max_size=8)
    elif spec.kind == "int":
        lo = int(spec.lo) + (1 if spec.lo_open else 0) if spec.lo is not None else -(10**6)
        hi = int(spec.hi) if spec.hi is not None else 10**6
        base = st.integers(lo, hi)
    else:
        base = st.floats(
            min_value=spec.lo if spec.lo is not None else -1e6,
            max_value=spec.hi if spec.hi is not None else 1e6,
            exclude_min=spec.lo_open,
            allow_nan=False,
            allow_infinity=False,
        )
    return st.one_of(st.none(), base) if spec.nullable else base


def _settings_strategy(cls) -> st.SearchStrategy:
    parts = {}
    for f in dataclasses.fields(cls):
        if "spec" in f.metadata:
            parts[f.name] = _leaf_strategy(f.metadata["spec"])
        else:
            parts[f.name] = _settings_strategy(type(f.default_factory()))
    return st.fixed_dictionaries(parts)


@settings(max_examples=60, deadline=None)
@given(_settings_strategy(Settings))
def test_valid_settings_round_trip_through_yaml(data):
    s = settings_from_dict(data)
    assert to_dict(s) == data
    assert settings_from_dict(yaml.safe_load(render_commented(s))) == s
    assert settings_from_dict(yaml.safe_load(dump_yaml(s))) == s


# ---------------------------------------------------------------------------------------------
# Presets by name


def test_presets_are_the_configs_folder_and_list_their_purpose():
    from click.testing import CliRunner

    from trackcli.cli import cli
    from trackcli.settings import PRESETS_DIR, presets

    assert PRESETS_DIR.resolve() == CONFIGS.resolve()
    names = sorted(p.stem for p in CONFIGS.glob("*.yaml"))
    assert list(presets()) == names and "tight" in names
    result = CliRunner().invoke(cli, ["config", "list"])
    assert result.exit_code == 0
    lines = result.stdout.splitlines()
    assert [ln.split()[0] for ln in lines] == names
    tight = next(ln for ln in lines if ln.startswith("tight"))
    assert "third worked case of Active Contours" in tight


def test_preset_by_name_from_any_folder(tmp_path, monkeypatch):
    from click.testing import CliRunner

    from trackcli.cli import cli

    monkeypatch.chdir(tmp_path)
    for name in ("tight", "tight.yaml"):
        s = load_settings(name)
        assert s.kalman.kappa == 1.2 and s.measurement.polarity == "any"
    result = CliRunner().invoke(cli, ["config", "show", "tight"])
    assert result.exit_code == 0 and "kappa: 1.2" in result.stdout
    # a file of that name here wins over the preset
    (tmp_path / "tight.yaml").write_text("kalman: {kappa: 3.0}\n")
    assert load_settings("tight.yaml").kalman.kappa == 3.0
    with pytest.raises(ConfigError, match=r"nosuch: no such configuration file or preset \(presets: .*tight"):
        load_settings("nosuch")
    with pytest.raises(ConfigError, match="no such configuration file or preset"):
        load_settings("sub/tight.yaml")


# ---------------------------------------------------------------------------------------------
# Settings that moved to sections of their own


def test_a_file_with_the_old_keys_is_read_under_the_new_ones_with_a_warning_each(tmp_path, caplog):
    import logging

    from trackcli.settings import MOVED

    p = write(tmp_path, "condensation:\n  particles: 200\n  likelihood: clutter\n  colour_weight: 1.5\n"
                        "  reacquire: false\n  reacquire_after: 5\n  jump_size: 0.5\n")
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        s = load_settings(p)
    assert s.condensation.particles == 200
    assert (s.observation.likelihood, s.observation.colour_weight) == ("clutter", 1.5)
    assert (s.reacquire.enabled, s.reacquire.after, s.jumps.size) == (False, 5, 0.5)
    assert caplog.messages == [f"{p}: condensation.{old} is now {MOVED['condensation.' + old]}: read as that "
                               "(rename it)" for old in ("likelihood", "colour_weight", "reacquire",
                                                         "reacquire_after", "jump_size")]
    # every old key has a home that exists, and no old key is a setting any more
    keys = {k for k, _, _, _ in describe_settings()}
    assert set(MOVED.values()) <= keys and not set(MOVED) & keys


def test_an_old_key_in_an_override_or_a_stored_model_is_read_under_its_new_name(caplog):
    import logging

    with caplog.at_level(logging.WARNING, logger="trackcli"):
        s = load_settings(None, {"condensation.jump_fraction": 0.0, "condensation.search": 12.0})
    assert (s.jumps.fraction, s.observation.search) == (0.0, 12.0)
    assert "condensation.jump_fraction is now jumps.fraction" in caplog.text
    caplog.clear()
    # the settings stored in a model learned before the move: read quietly (the user cannot fix them)
    stored = to_dict(Settings())
    for section in ("observation", "reacquire", "jumps"):
        del stored[section]
    stored["condensation"].update({"likelihood": "truncated", "still_weight": 0.0, "reacquire_speed": 0.0})
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        s = settings_from_dict(stored)
    assert (s.observation.likelihood, s.observation.still_weight, s.reacquire.speed) == ("truncated", 0.0, 0.0)
    assert caplog.text == ""


def test_a_file_with_both_names_of_a_setting_is_refused(tmp_path):
    p = write(tmp_path, "condensation:\n  likelihood: clutter\nobservation:\n  likelihood: truncated\n")
    with pytest.raises(ConfigError) as info:
        load_settings(p)
    assert str(info.value) == (f"{p}: condensation.likelihood: moved to observation.likelihood, and both are given; "
                               "keep observation.likelihood")


def test_a_model_learned_with_the_old_keys_still_loads(tmp_path):
    """A model file keeps the settings it was learned with, under the names of its day."""
    from trackcli.dynamics.model import load_model, save_model

    model = tmp_path / "m.yaml"
    save_model(model, _tiny_model())
    data = yaml.safe_load(model.read_text())
    for section in ("observation", "reacquire", "jumps"):
        del data["settings"][section]
    data["settings"]["condensation"]["colour_weight"] = 2.0
    model.write_text(yaml.safe_dump(data))
    assert load_model(model).settings.observation.colour_weight == 2.0


def _tiny_model():
    import numpy as np

    from trackcli.dynamics.handset import handset_dynamics
    from trackcli.dynamics.model import Model
    from trackcli.shapes import shape_space as ss
    from trackcli.shapes.spline import SplineBasis
    from trackcli.shapes.template import Template

    t = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ctrl = np.column_stack([50 + 10 * np.cos(t), 40 + 12 * np.sin(t)])
    template = Template(ctrl, degree=2, closed=True)
    space = ss.similarity(SplineBasis(8, degree=2, closed=True), np.concatenate([ctrl[:, 0], ctrl[:, 1]]))
    return Model(template, space, handset_dynamics(space, Settings().dynamics, 0.04), Settings())


def test_config_show_of_an_old_file_prints_the_new_layout_and_warns(tmp_path):
    import os
    import subprocess
    import sys

    p = write(tmp_path, "condensation:\n  reacquire_speed: 0\n")
    env = {**os.environ, "PYTHONPATH": str(CONFIGS.parent)}
    res = subprocess.run([sys.executable, "-m", "trackcli.cli", "config", "show", str(p)], capture_output=True,
                         text=True, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stderr == f"WARNING: {p}: condensation.reacquire_speed is now reacquire.speed: read as that (rename it)\n"
    shown = yaml.safe_load(res.stdout)
    assert shown["reacquire"]["speed"] == 0 and "reacquire_speed" not in shown["condensation"]


def test_a_batch_manifest_setting_under_its_old_name_lands_under_the_new_one():
    """``batch`` sets a job's settings key by key (``set_dotted``) on the full settings."""
    from trackcli.settings import set_dotted

    data = to_dict(Settings())
    set_dotted(data, "condensation.jump_size", 0.7, "clips[0].settings")
    assert "jump_size" not in data["condensation"]
    assert settings_from_dict(data).jumps.size == 0.7
