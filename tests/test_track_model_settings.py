"""``track --model`` measures the outline as the model was learned to.

The model file stores the settings it was learned with; its ``measurement`` section
(:data:`trackcli.dynamics.model.MODEL_SECTIONS`) is used for tracking unless the user sets a key of
it, in a configuration file (``-c``) or by an option.  ``-v`` says where each section came
from.  The effective configuration written beside the track shows what was used.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from conftest import CLIP_ELLIPSE, CLIP_SIZE
from trackcli.cli import cli
from trackcli.settings import load_settings, replace
from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.model import Model, save_model
from trackcli.shapes.shape_space import similarity
from trackcli.shapes.template import Template, save_template


@pytest.fixture
def files(tmp_path):
    cx, cy, a, b = CLIP_ELLIPSE
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    tmpl = Template(np.column_stack([cx + a * np.cos(t), cy + b * np.sin(t)]), frame_size=CLIP_SIZE)
    space = similarity(tmpl.basis(), tmpl.Q)
    dyn = AR2(-0.9 * np.eye(4), 1.85 * np.eye(4), np.diag([1.0, 1.0, 0.005, 0.005]), np.zeros(4), 0.04)
    learned_with = replace(load_settings(), {"measurement.polarity": "dark_to_light", "measurement.n_normals": 30})
    save_model(tmp_path / "m.yaml", Model(tmpl, space, dyn, learned_with))
    save_template(tmp_path / "t.yaml", tmpl)
    (tmp_path / "polarity.yaml").write_text("measurement:\n  polarity: light_to_dark\n")
    (tmp_path / "seed.yaml").write_text("seed: 3\ncondensation:\n  particles: 50\n")
    return tmp_path


def _track(files, clip, *extra):
    out = files / "out"
    args = ["track", "--model", files / "m.yaml", "--template", files / "t.yaml", clip, "-o", out, "--no-rrd",
            "--particles", 50, *extra]
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    used = yaml.safe_load((out / "ellipse.condensation.config.yaml").read_text())
    return used["measurement"]


def test_without_a_config_the_models_measurement_settings_are_used(files, ellipse_clip, caplog):
    with caplog.at_level(logging.INFO, logger="trackcli.run.clips"):
        used = _track(files, ellipse_clip)
    assert used["polarity"] == "dark_to_light" and used["n_normals"] == 30
    assert "measurement settings: from model" in caplog.text


def test_a_config_that_sets_the_polarity_wins_for_that_key(files, ellipse_clip, caplog):
    with caplog.at_level(logging.INFO, logger="trackcli.run.clips"):
        used = _track(files, ellipse_clip, "-c", files / "polarity.yaml")
    assert used["polarity"] == "light_to_dark"
    assert used["n_normals"] == 30  # not set by the config: still the model's
    assert "except polarity from the configuration" in caplog.text


def test_a_config_without_a_measurement_section_keeps_the_models(files, ellipse_clip):
    assert _track(files, ellipse_clip, "-c", files / "seed.yaml")["polarity"] == "dark_to_light"


def test_a_template_alone_uses_the_configs_measurement(files, ellipse_clip):
    out = files / "alone"
    result = CliRunner().invoke(cli, ["track", "--template", str(files / "t.yaml"), str(ellipse_clip), "-o", str(out),
                                      "--no-rrd", "--particles", "50"])
    assert result.exit_code == 0, result.output
    assert yaml.safe_load((out / "ellipse.condensation.config.yaml").read_text())["measurement"]["polarity"] == "any"
