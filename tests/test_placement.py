"""Placing a learned model on another clip (``--model M --template T``).

- Placement keeps a stable model stable and keeps its modes (damping, frequency) as
  learned; where a coupling option changes them and pushes a mode out, the model is
  re-stabilised and a warning gives the numbers.
- The size and position of the new template are carried into the dynamics mean: the
  noise-free prediction from a template 1.5 times the training size stays at 1.5 times.
- ``trackcli inspect MODEL --template T`` shows the placed model.

Every placed model built here goes through :func:`conftest.check_placed` (via the autouse
fixture of conftest), which asserts that a stable learned model is placed stable.
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import check_placed
from trackcli.dynamics import model as model_mod
from trackcli.cli import cli
from trackcli.settings import Settings
from trackcli.dynamics.ar2 import AR2
from trackcli.dynamics.learning import stabilise
from trackcli.dynamics.model import Model, place_space, placement_scale, save_model, scale_direction
from trackcli.shapes.shape_space import similarity, translation
from trackcli.shapes.spline import curve_area_centroid
from trackcli.shapes.template import Template, save_template

TAU = 0.04


def _template(scale: float = 1.0, centre=(200.0, 150.0)) -> Template:
    t = np.linspace(0, 2 * np.pi, 10, endpoint=False)
    x = 30 * np.cos(t) + 4 * np.sin(2 * t)
    y = 40 * np.sin(t)
    pts = np.column_stack([centre[0] + scale * x, centre[1] + scale * y])
    return Template(pts, degree=2, closed=True, frame_size=(480, 360))


def _space():
    tmpl = _template(centre=(100.0, 80.0))
    return similarity(tmpl.basis(), tmpl.Q)


def _coupled(rng: np.random.Generator) -> AR2:
    """A stable AR(2) (spectral radius at most 0.97) on a similarity space with every block
    coupled and a learned mean."""
    A1 = 1.8 * np.eye(4) + 0.02 * rng.standard_normal((4, 4))
    A2 = -0.85 * np.eye(4) + 0.02 * rng.standard_normal((4, 4))
    A2, A1, _ = stabilise(A2, A1, 0.97)
    B = 0.3 * rng.standard_normal((4, 4))
    return AR2(A2, A1, B, np.array([5.0, -3.0, 0.01, -0.02]), TAU)


def _held_up_by_coupling() -> AR2:
    """Stable only through the coupling: translation alone would grow by 5 % a frame.

    Per axis ``(t, d)``: ``A1 = [[1.05, -0.3], [0.3, 0.5]]``, ``A2 = 0``; the pair has
    ``|λ| = sqrt(1.05 · 0.5 + 0.09) = 0.784``, the translation block alone ``1.05``.
    """
    A1 = np.zeros((4, 4))
    for t, d in ((0, 2), (1, 3)):
        A1[t, t], A1[t, d], A1[d, t], A1[d, d] = 1.05, -0.3, 0.3, 0.5
    return AR2(np.zeros((4, 4)), A1, 0.5 * np.eye(4), np.zeros(4), TAU)


def _place(dyn, space, X0, **kw):
    report: list = []
    placed = model_mod.place_dynamics(dyn, space, X0, TAU, report=report, **kw)
    return placed, report[0]


def _spectrum(dyn: AR2) -> np.ndarray:
    vals = dyn.eigenvalues()
    return vals[np.lexsort((vals.imag, vals.real))]


# ---------------------------------------------------------------------------------------------
# Stability and modes


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_placement_keeps_the_learned_modes_at_any_size_and_noise(seed):
    space = _space()
    dyn = _coupled(np.random.default_rng(seed))
    assert dyn.is_stable()
    placed_space, X0 = place_space(space, _template(scale=1.5))
    placed, rep = _place(dyn, placed_space, X0, translation_noise=8.0, deformation_noise=5.0)
    np.testing.assert_allclose(_spectrum(placed), _spectrum(dyn), atol=1e-9)
    for got, want in zip(placed.modes(), dyn.modes()):
        assert got.frequency == pytest.approx(want.frequency, abs=1e-9)
        assert got.beta == pytest.approx(want.beta, abs=1e-7)
    assert rep.radius == pytest.approx(dyn.spectral_radius(), abs=1e-12) and not rep.restabilised
    assert rep.scale == pytest.approx(1.5, rel=1e-9)


def test_noise_factors_scale_the_motion_not_its_time_course():
    """A change of units: translation excursions grow by the translation factor exactly."""
    space = _space()
    dyn = _coupled(np.random.default_rng(4))
    one, _ = _place(dyn, space, np.zeros(4))
    four, _ = _place(dyn, space, np.zeros(4), translation_noise=4.0, deformation_noise=2.0)
    P1, P4 = (d.steady_state_covariance()[4:, 4:] for d in (one, four))
    np.testing.assert_allclose(P4[:2, :2], 16.0 * P1[:2, :2], rtol=1e-7)
    np.testing.assert_allclose(P4[2:, 2:], 4.0 * P1[2:, 2:], rtol=1e-7)


def test_cutting_the_coupling_of_a_model_held_up_by_it_is_restabilised_and_said(caplog):
    space = _space()
    dyn = _held_up_by_coupling()
    assert dyn.spectral_radius() == pytest.approx(np.sqrt(1.05 * 0.5 + 0.09))
    kept, rep = _place(dyn, space, np.zeros(4))
    assert rep.radius == pytest.approx(dyn.spectral_radius()) and not rep.restabilised
    for coupling in ("none", "velocity"):
        with caplog.at_level(logging.WARNING, logger="trackcli.dynamics.model"):
            caplog.clear()
            placed, rep = _place(dyn, space, np.zeros(4), coupling=coupling, max_spectral_radius=0.99)
        assert rep.restabilised and rep.limit == 0.99
        assert placed.spectral_radius() <= 0.99 + 1e-9
        # the cut translation block alone would be 1.05: the warning says so, with the numbers
        assert "from 0.7842 to 1.0500" in caplog.text and "0.9900" in caplog.text


def test_coupling_none_keeps_only_the_blocks():
    space = _space()
    dyn = _coupled(np.random.default_rng(3))
    placed, _ = _place(dyn, space, np.zeros(4), coupling="none")
    for A, A_old in ((placed.A1, dyn.A1), (placed.A2, dyn.A2)):
        np.testing.assert_array_equal(A[:2, 2:], 0.0)
        np.testing.assert_array_equal(A[2:, :2], 0.0)
        np.testing.assert_allclose(A[2:, 2:], A_old[2:, 2:])


def test_coupling_velocity_drops_the_position_terms_only():
    space = _space()
    dyn = _coupled(np.random.default_rng(3))
    placed, _ = _place(dyn, space, np.zeros(4), coupling="velocity")
    P = placed.A1 + placed.A2
    np.testing.assert_allclose(P[:2, 2:], 0.0, atol=1e-12)
    np.testing.assert_allclose(P[2:, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(placed.A2, dyn.A2)  # the velocity coupling -A2 is kept


def test_a_bad_coupling_is_refused():
    with pytest.raises(ValueError, match="placement.coupling: expected one of keep, velocity, none"):
        model_mod.place_dynamics(_coupled(np.random.default_rng(5)), _space(), None, TAU, coupling="some")


# ---------------------------------------------------------------------------------------------
# Size and position carried into the mean


def _noise_free(dyn: AR2, X0: np.ndarray, frames: int) -> np.ndarray:
    prev = cur = np.asarray(X0, dtype=float)
    for _ in range(frames):
        prev, cur = cur, dyn.mean + dyn.A2 @ (prev - dyn.mean) + dyn.A1 @ (cur - dyn.mean)
    return cur


@pytest.mark.parametrize("size", [1.5, 0.6])
def test_noise_free_prediction_from_a_larger_template_stays_at_its_size(size):
    space = _space()
    dyn = _coupled(np.random.default_rng(3))
    at_one = place_space(space, _template(1.0))
    at_size = place_space(space, _template(size))
    final = []
    for sp, X0 in (at_one, at_size):
        placed, _ = _place(dyn, sp, X0)
        X = _noise_free(placed, X0, 300)
        final.append((sp.pose(X), sp.origin))
    (pose1, origin1), (pose_s, origin_s) = final
    # the same learned mean outline, at the new size, about the new template's centroid
    assert pose_s[3] / pose1[3] == pytest.approx(size, rel=1e-6)
    assert pose_s[2] == pytest.approx(pose1[2], abs=1e-9)  # rotation kept
    np.testing.assert_allclose(pose_s[:2], 0.0, atol=1e-6)  # translation mean at the template
    new = _template(size)
    np.testing.assert_allclose(origin_s, curve_area_centroid(new.Q, new.basis())[1], atol=1e-9)


def test_the_scale_direction_exists_where_the_space_can_scale():
    tmpl = _template()
    sim = similarity(tmpl.basis(), tmpl.Q)
    np.testing.assert_allclose(scale_direction(sim), [0, 0, 1, 0], atol=1e-9)
    assert scale_direction(translation(tmpl.basis(), tmpl.Q)) is None
    assert placement_scale(sim, np.array([0, 0, 0.5, 0])) == pytest.approx(1.5)
    assert placement_scale(sim, None) == 1.0
    assert placement_scale(sim, np.array([0, 0, 0.5, 0.1])) == 1.0  # not a pure scaling


# ---------------------------------------------------------------------------------------------
# inspect --template


@pytest.fixture
def model_files(tmp_path):
    space = _space()
    tmpl = _template(centre=(100.0, 80.0))
    dyn = _coupled(np.random.default_rng(3))
    save_model(tmp_path / "m.yaml", Model(tmpl, space, dyn, Settings()))
    save_template(tmp_path / "t.yaml", _template(scale=1.5))
    return tmp_path


def test_inspect_shows_the_placed_model(model_files):
    d = model_files
    out = CliRunner().invoke(cli, ["inspect", str(d / "m.yaml"), "--template", str(d / "t.yaml"), "--json"])
    assert out.exit_code == 0, out.output
    info = json.loads(out.output)
    pl = info["placement"]
    assert pl["scale"] == pytest.approx(1.5) and pl["coupling"] == "keep" and not pl["restabilised"]
    new = _template(scale=1.5)
    assert pl["centroid"] == pytest.approx(list(curve_area_centroid(new.Q, new.basis())[1]))
    learned = _coupled(np.random.default_rng(3))
    assert pl["learned_spectral_radius"] == pytest.approx(learned.spectral_radius())
    assert info["spectral_radius"] == pytest.approx(learned.spectral_radius())
    assert [m["frequency_hz"] for m in info["modes"]] == pytest.approx([m.frequency for m in learned.modes()])
    # the mean: translation at the template, the learned deformation mean at 1.5 times the size
    assert info["mean"]["tx"] == 0 and info["mean"]["ty"] == 0
    assert info["mean"]["scos_m1"] == pytest.approx(1.5 * 1.01 - 1)
    text = CliRunner().invoke(cli, ["inspect", str(d / "m.yaml"), "--template", str(d / "t.yaml")])
    assert text.exit_code == 0 and "placed by template" in text.output and "size 1.500" in text.output


def test_inspect_with_a_template_of_another_curve_is_a_one_line_error(model_files, tmp_path):
    """An open template on a closed model's curve cannot be placed (a closed one of any number
    of control points can: only its centroid and area are read)."""
    d = model_files
    pts = _template(1.5).control_points[:8]
    save_template(tmp_path / "eight.yaml", Template(pts, degree=2, closed=False, frame_size=(480, 360)))
    out = CliRunner().invoke(cli, ["inspect", str(d / "m.yaml"), "--template", str(tmp_path / "eight.yaml")])
    assert out.exit_code == 4
    assert out.output.startswith("Error: ") and "--n-ctrl" in out.output and out.output.count("\n") == 1


def test_check_placed_rejects_an_unstable_placement_of_a_stable_model():
    stable = _held_up_by_coupling()
    A1 = np.zeros((4, 4))
    np.fill_diagonal(A1, 1.05)
    with pytest.raises(AssertionError, match="spectral radius"):
        check_placed(stable, AR2(np.zeros((4, 4)), A1, np.eye(4), np.zeros(4), TAU))


def test_a_closed_template_of_other_control_points_is_placed_by_its_centroid_and_area(model_files, tmp_path):
    from trackcli.dynamics.model import load_model
    from trackcli.shapes.fit import fit
    from trackcli.shapes.spline import dense_polygon

    model = load_model(model_files / "m.yaml")
    t = _template(1.5)
    m = 2 * t.n_ctrl  # the same curve with twice the control points
    Qf = fit(dense_polygon(t.Q, t.basis(), 400), m, degree=2, closed=True)
    finer = Template(np.column_stack([Qf[:m], Qf[m:]]), degree=2, closed=True, frame_size=(480, 360))
    placed, X0 = place_space(model.space, finer)
    Q = placed.to_control(X0)
    area, centre = curve_area_centroid(Q, placed.basis)
    area_t, centre_t = curve_area_centroid(finer.Q, finer.basis())
    np.testing.assert_allclose(centre, centre_t, atol=0.5)
    assert abs(area) == pytest.approx(abs(area_t), rel=0.02)
