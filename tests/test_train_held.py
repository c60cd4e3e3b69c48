"""Learning uses only the frames the tracker held.

Frames flagged ``lost`` split a training sequence into segments whose statistics are
pooled (AC §11.2); what the tracker reported while it had lost the object never reaches
the fit.  Simulated sequences of a known AR(2) model get lost stretches of garbage (shape
vectors with a strong spurious coupling between vertical translation and scale, as a
tracker stuck on clutter produces); the model learned must equal the one learned from the
held segments alone, and the spurious coupling must not appear.
"""

from __future__ import annotations

import csv
import logging

import numpy as np
import pytest
from click.testing import CliRunner

from trackcli.cli import cli
from trackcli.settings import Settings
from trackcli.dynamics.ar2 import AR2
from trackcli.errors import DataError
from trackcli.dynamics.learning import fit_ar2
from trackcli.dynamics.model import load_model
from trackcli.shapes.template import Template, save_template
from trackcli.io.tracks import header
from trackcli.run.train import held_segments, learn_from_sequences

TAU = 0.04
TY, SCOS = 1, 2


def _truth() -> AR2:
    """A decoupled, damped oscillator per component of a similarity space."""
    decay, theta = np.exp(-1.0 * TAU), 2 * np.pi * 0.4 * TAU
    A1 = 2 * decay * np.cos(theta) * np.eye(4)
    A2 = -decay**2 * np.eye(4)
    B0 = np.diag([0.8, 0.8, 0.004, 0.004])
    return AR2(A2, A1, B0, np.array([3.0, -2.0, 0.01, 0.0]), TAU)


def _with_garbage(rng, n=400, stretches=((100, 160), (250, 252), (330, 345))):
    """A simulated sequence with lost stretches replaced by garbage: ty = 40 * scos + noise."""
    X = _truth().simulate(n, rng, burn_in=100)
    lost = np.zeros(n, dtype=bool)
    for a, b in stretches:
        lost[a:b] = True
        scos = rng.normal(0.0, 0.3, b - a)
        X[a:b, SCOS] = scos
        X[a:b, TY] = 40.0 * scos + rng.normal(0.0, 1.0, b - a)
        X[a:b, 0] = rng.normal(0.0, 50.0, b - a)
    return X, lost


def test_held_segments_split_at_lost_frames_and_drop_short_pieces():
    X = np.arange(20.0)[:, None]
    lost = np.zeros(20, dtype=bool)
    lost[[5, 6, 9, 17]] = True  # held: 0-4, 7-8 (too short), 10-16, 18-19 (too short)
    segs = held_segments(X, lost)
    assert [s[:, 0].tolist() for s in segs] == [[0, 1, 2, 3, 4], list(range(10, 17))]
    assert [s.shape for s in held_segments(X, None)] == [(20, 1)]


def test_the_model_learned_is_the_one_of_the_held_segments_alone():
    rng = np.random.default_rng(7)
    X, lost = _with_garbage(rng)
    got, report = learn_from_sequences([X], TAU, Settings(), lost=[lost])
    # the held segments, cut by hand: 0-99, 160-249, 252-329, 345-399
    pieces = [X[0:100], X[160:250], X[252:330], X[345:400]]
    want, _ = fit_ar2(pieces, TAU, enforce_stability=True, max_spectral_radius=0.995)
    for name in ("A1", "A2", "B0", "mean"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-10, atol=1e-12)
    assert report["n_sequences"] == 4 and report["n_frames"] == 323
    assert report["frames_dropped"] == 77 and report["frames_total"] == 400


def test_couplings_of_the_garbage_frames_do_not_appear():
    rng = np.random.default_rng(8)
    X, lost = _with_garbage(rng)
    held, _ = learn_from_sequences([X], TAU, Settings(), lost=[lost])
    everything, _ = learn_from_sequences([X], TAU, Settings())
    # learned from every frame, ty follows scale (the garbage); from the held frames it does not
    P_all = everything.A1 + everything.A2
    P_held = held.A1 + held.A2
    assert abs(P_all[TY, SCOS]) > 2.0
    assert abs(P_held[TY, SCOS]) < 0.5


def test_dropping_more_than_a_tenth_is_warned_with_counts(caplog):
    rng = np.random.default_rng(9)
    X, lost = _with_garbage(rng)
    with caplog.at_level(logging.WARNING, logger="trackcli.run.train"):
        learn_from_sequences([X], TAU, Settings(), lost=[lost], labels=["walk.mp4"])
    assert "learning from 323 of 400 training frames: 77 dropped" in caplog.text
    assert "walk.mp4: 77 lost, 0 in pieces shorter than 3 frames, 323 used in 4 segment(s)" in caplog.text
    caplog.clear()
    short = lost.copy()
    short[102] = False  # one held frame inside a lost stretch is no segment
    with caplog.at_level(logging.WARNING, logger="trackcli.run.train"):
        learn_from_sequences([X], TAU, Settings(), lost=[short], labels=["walk.mp4"])
    assert "walk.mp4: 76 lost, 1 in pieces shorter than 3 frames, 323 used in 4 segment(s)" in caplog.text
    caplog.clear()
    few = np.zeros(400, dtype=bool)
    few[100:120] = True  # 5 %: no warning
    with caplog.at_level(logging.WARNING, logger="trackcli.run.train"):
        learn_from_sequences([X], TAU, Settings(), lost=[few])
    assert caplog.text == ""


def test_too_little_held_is_a_clear_error():
    rng = np.random.default_rng(10)
    X = _truth().simulate(60, rng)
    lost = np.ones(60, dtype=bool)
    lost[10:20] = False  # 10 held frames: 8 triples, 4-D AR(2) needs more than 9
    with pytest.raises(DataError, match=r"too few frames held by the tracker to learn from: 10 of 60 frames "
                                        r"in 1 segment\(s\) .* give 8 frame triples, and 4-dimensional AR\(2\) "
                                        r"dynamics need more than 9"):
        learn_from_sequences([X], TAU, Settings(), lost=[lost])


# ---------------------------------------------------------------------------------------------
# learn --from-tracks reads the lost column


def _template() -> Template:
    t = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    pts = np.column_stack([200 + 30 * np.cos(t), 150 + 40 * np.sin(t)])
    return Template(pts, degree=2, closed=True, frame_size=(480, 360))


def _write_track(path, X, lost) -> None:
    names = ["tx", "ty", "scos_m1", "ssin"]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header(names))
        for k, (x, bad) in enumerate(zip(X, lost)):
            w.writerow([k, f"{k * TAU:.6f}", *x, *[0.0] * 4, 200, 150, 170, 110, 60, 80, 24, 24, 3, "", "",
                        int(bad)])


def test_learn_from_tracks_drops_lost_rows(tmp_path, caplog):
    rng = np.random.default_rng(11)
    X, lost = _with_garbage(rng)
    _write_track(tmp_path / "a.csv", X, lost)
    save_template(tmp_path / "t.yaml", _template())
    with caplog.at_level(logging.WARNING, logger="trackcli.run.train"):
        out = CliRunner().invoke(cli, ["learn", "--template", str(tmp_path / "t.yaml"), "--from-tracks",
                                       str(tmp_path / "a.csv"), "-o", str(tmp_path / "m.yaml")])
    assert out.exit_code == 0, out.output
    assert "learning from 323 of 400 training frames: 77 dropped" in caplog.text
    assert "a.csv: 77 lost" in caplog.text
    got = load_model(tmp_path / "m.yaml").dynamics
    want, _ = fit_ar2([X[0:100], X[160:250], X[252:330], X[345:400]], TAU, enforce_stability=True,
                      max_spectral_radius=0.995)
    np.testing.assert_allclose(got.A1, want.A1, rtol=1e-6, atol=1e-6)  # through the CSV's 8 digits
    np.testing.assert_allclose(got.A2, want.A2, rtol=1e-6, atol=1e-6)


def test_learn_from_tracks_with_almost_everything_lost_is_a_one_line_error(tmp_path):
    rng = np.random.default_rng(12)
    X = _truth().simulate(50, rng)
    lost = np.ones(50, dtype=bool)
    lost[:6] = False
    _write_track(tmp_path / "a.csv", X, lost)
    save_template(tmp_path / "t.yaml", _template())
    out = CliRunner().invoke(cli, ["learn", "--template", str(tmp_path / "t.yaml"), "--from-tracks",
                                   str(tmp_path / "a.csv"), "-o", str(tmp_path / "m.yaml")])
    assert out.exit_code == 5
    assert out.output.startswith("Error: too few frames held by the tracker") and out.output.count("\n") == 1
    assert not (tmp_path / "m.yaml").exists()
