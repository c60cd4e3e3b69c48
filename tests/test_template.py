"""Tests for trackcli.shapes.template: the YAML round trip and rejection of malformed template files."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from trackcli.errors import InputError, TemplateError
from trackcli.shapes.template import FORMAT, KIND, Template, load_template, save_template


def square_template(**kw) -> Template:
    cp = np.array([[10.0, 20.0], [60.5, 20.25], [60.0, 70.125], [10.0, 70.0], [5.0, 45.0]])
    return Template(cp, **{"clip": "clip.mp4", "frame": 3, "frame_size": (160, 120), "source": "points", **kw})


def good_dict() -> dict:
    return square_template().to_dict()


def write_yaml(tmp_path, data, name: str = "t.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return p


# ---------------------------------------------------------------------------------------------
# Round trip


def test_save_load_round_trip(tmp_path):
    t = square_template(extra={"note": "drawn by hand"})
    p = save_template(tmp_path / "sub" / "head.yaml", t)
    assert p == tmp_path / "sub" / "head.yaml"
    u = load_template(p)
    np.testing.assert_array_equal(u.control_points, t.control_points)  # exact at 4 decimals
    assert (u.degree, u.closed, u.clip, u.frame, u.frame_size, u.source) == (2, True, "clip.mp4", 3, (160, 120), "points")
    assert u.extra == {"note": "drawn by hand"}  # unknown keys are carried, not dropped
    np.testing.assert_array_equal(u.Q, np.concatenate([t.control_points[:, 0], t.control_points[:, 1]]))
    assert u.n_ctrl == 5


def test_file_states_kind_and_format(tmp_path):
    p = save_template(tmp_path / "t.yaml", square_template())
    d = yaml.safe_load(p.read_text(encoding="utf-8"))
    assert d["kind"] == KIND == "trackcli-template"
    assert d["format"] == FORMAT == 1
    assert d["frame_size"] == [160, 120]
    assert not list(tmp_path.glob(".*.part"))  # the temporary file was renamed into place


def test_open_curve_and_optional_fields_round_trip(tmp_path):
    t = Template(np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 1.0], [4.0, 4.0]]), degree=3, closed=False)
    u = load_template(save_template(tmp_path / "o.yaml", t))
    assert (u.degree, u.closed, u.clip, u.frame_size, u.frame) == (3, False, None, None, 0)
    np.testing.assert_array_equal(u.control_points, t.control_points)


def test_the_drawn_box_round_trips_and_is_absent_by_default(tmp_path):
    t = square_template(source="box 8,18,60,60 (GrabCut)", box=(8, 18.5, 60, 60))
    d = t.to_dict()
    assert d["box"] == [8.0, 18.5, 60.0, 60.0]
    u = load_template(save_template(tmp_path / "b.yaml", t))
    assert u.box == (8.0, 18.5, 60.0, 60.0) and "box" not in u.extra
    assert "box" not in square_template().to_dict()
    assert load_template(save_template(tmp_path / "n.yaml", square_template())).box is None


@pytest.mark.parametrize(
    "box",
    [[1, 2, 3], [1, 2, 3, "4"], "1,2,3,4", [1, 2, 0, 4], [1, 2, 3, -4], [1, 2, True, 4], [1, ".nan", 3, 4]],
    ids=["three", "string-item", "string", "zero-width", "negative-height", "bool", "nan"],
)
def test_a_bad_drawn_box_is_named(tmp_path, box):
    d = good_dict()
    d["box"] = box if box[1] != ".nan" else [1, float("nan"), 3, 4]
    p = write_yaml(tmp_path, d)
    with pytest.raises(TemplateError, match=r"box must be \[x, y, width, height\]"):
        load_template(p)


@settings(max_examples=40, deadline=None)
@given(
    cp=arrays(np.float64, st.tuples(st.integers(3, 30), st.just(2)),
              elements=st.floats(-5000, 5000, allow_nan=False, allow_infinity=False)),
    degree=st.integers(1, 3),
)
def test_round_trip_keeps_points_to_four_decimals(tmp_path_factory, cp, degree):
    if len(cp) < degree + 1:
        return
    t = Template(cp, degree=degree)
    u = load_template(save_template(tmp_path_factory.mktemp("rt") / "t.yaml", t))
    np.testing.assert_allclose(u.control_points, cp, rtol=0, atol=5.001e-5)
    assert u.degree == degree


# ---------------------------------------------------------------------------------------------
# Malformed files


def test_missing_file(tmp_path):
    with pytest.raises(TemplateError, match="no such template file"):
        load_template(tmp_path / "absent.yaml")


def test_template_error_is_an_input_error_and_os_error(tmp_path):
    with pytest.raises(InputError):
        load_template(tmp_path / "absent.yaml")
    with pytest.raises(OSError):
        load_template(tmp_path / "absent.yaml")


@pytest.mark.parametrize(
    "text",
    ["control_points: [[1, 2], [3, 4]\nkind: x\n", "a: b: c\n", "- [1\n"],
    ids=["unclosed", "nested-colon", "unclosed-list"],
)
def test_not_yaml(tmp_path, text):
    p = tmp_path / "t.yaml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(TemplateError, match=r"not valid YAML") as info:
        load_template(p)
    assert "\n" not in str(info.value)
    assert str(info.value).startswith(str(p))


def test_binary_file(tmp_path):
    p = tmp_path / "t.yaml"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\xff\x00\xfe")
    with pytest.raises(TemplateError):
        load_template(p)


@pytest.mark.parametrize("text", ["", "just text\n", "- 1\n- 2\n"], ids=["empty", "scalar", "list"])
def test_not_a_mapping(tmp_path, text):
    p = tmp_path / "t.yaml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(TemplateError, match="not a trackcli template \\(a YAML file written by 'trackcli draw'\\)"):
        load_template(p)


@pytest.mark.parametrize("kind, text", [
    ("trackcli-model", r"a model file \(kind: trackcli-model\), not a template"),
    (None, r"not a trackcli template \(a YAML file written by 'trackcli draw'\)"),
    ("Trackcli-Template", r"not a trackcli template \(kind: 'Trackcli-Template', expected 'trackcli-template'\)"),
])
def test_wrong_kind(tmp_path, kind, text):
    d = good_dict()
    d["kind"] = kind
    with pytest.raises(TemplateError, match=text):
        load_template(write_yaml(tmp_path, d))


@pytest.mark.parametrize("fmt", [2, 0, "1", None])
def test_wrong_format(tmp_path, fmt):
    d = good_dict()
    d["format"] = fmt
    with pytest.raises(TemplateError, match=re.escape(f"unsupported template format {fmt!r}")):
        load_template(write_yaml(tmp_path, d))


def test_missing_control_points(tmp_path):
    d = good_dict()
    del d["control_points"]
    with pytest.raises(TemplateError, match="missing 'control_points'"):
        load_template(write_yaml(tmp_path, d))


@pytest.mark.parametrize(
    "cp",
    [
        "abc",
        [[1, 2], [3]],  # ragged
        [[1, "x"], [3, 4], [5, 6]],  # not numbers
        {"x": 1},
        [[1, 2, 3], [4, 5, 6], [7, 8, 9]],  # triples
        [1, 2, 3, 4, 5, 6],  # flat list
        None,
        [[1, 2], [float("nan"), 4], [5, 6]],  # not finite
        [[1, 2], [float("inf"), 4], [5, 6]],
    ],
    ids=["string", "ragged", "non-numeric", "mapping", "triples", "flat", "null", "nan", "inf"],
)
def test_bad_control_points(tmp_path, cp):
    d = good_dict()
    d["control_points"] = cp
    with pytest.raises(TemplateError, match="control.points"):
        load_template(write_yaml(tmp_path, d))


@pytest.mark.parametrize(
    ("n", "degree", "closed", "need"),
    [(2, 2, True, 3), (0, 2, True, 3), (2, 1, True, 3), (3, 3, False, 4), (5, 5, True, 6)],
)
def test_too_few_control_points(tmp_path, n, degree, closed, need):
    d = good_dict()
    d.update(control_points=[[float(i), float(i * i)] for i in range(n)], degree=degree, closed=closed)
    p = write_yaml(tmp_path, d)
    with pytest.raises(TemplateError) as info:
        load_template(p)
    msg = str(info.value)
    if n:
        assert msg.startswith(f"{p}: a degree-{degree} ")
        assert f"needs at least {need} control points, got {n}" in msg


@pytest.mark.parametrize(
    "size",
    [[480], [480, 360, 3], [0, 360], [-480, 360], [480.5, 360], ["480", "360"], "480x360", [True, 360], 480],
    ids=["one", "three", "zero", "negative", "float", "strings", "string", "bool", "scalar"],
)
def test_bad_frame_size(tmp_path, size):
    d = good_dict()
    d["frame_size"] = size
    p = write_yaml(tmp_path, d)
    with pytest.raises(TemplateError) as info:
        load_template(p)
    assert str(info.value).startswith(f"{p}: frame_size must be [width, height] in pixels, got ")


@pytest.mark.parametrize(
    ("key", "value", "text"),
    [
        ("frame", -1, "frame must be an integer >= 0"),
        ("frame", "0", "frame must be an integer >= 0"),
        ("frame", True, "frame must be an integer >= 0"),
        ("degree", "2", "degree must be an integer"),
        ("degree", 2.0, "degree must be an integer"),
        ("degree", True, "degree must be an integer"),
        ("degree", 0, "degree must be between 1 and 5, got 0"),
        ("degree", 6, "degree must be between 1 and 5, got 6"),
        ("closed", "yes", "closed must be true or false"),
        ("closed", 1, "closed must be true or false"),
    ],
)
def test_bad_scalar_fields(tmp_path, key, value, text):
    d = good_dict()
    d[key] = value
    with pytest.raises(TemplateError, match=text):
        load_template(write_yaml(tmp_path, d))


def test_constructor_validates_too():
    with pytest.raises(TemplateError, match="shape"):
        Template(np.zeros((4, 3)))
    with pytest.raises(TemplateError, match="finite"):
        Template(np.array([[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]]))
    with pytest.raises(TemplateError, match="at least 3"):
        Template(np.zeros((2, 2)))


def test_a_template_read_again_is_a_new_copy_and_a_changed_file_is_read_anew(tmp_path):
    p = tmp_path / "t.yaml"
    cp = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    save_template(p, Template(cp, extra={"note": {"by": "hand"}}))
    first = load_template(p)
    first.control_points[0] = (99, 99)
    first.extra["note"]["by"] = "someone else"
    again = load_template(p)
    np.testing.assert_array_equal(again.control_points, cp)
    assert again.extra == {"note": {"by": "hand"}}
    save_template(p, Template(cp + 5, extra={"note": {"by": "hand"}, "more": 1}))
    changed = load_template(p)  # another size: read anew even within the same clock tick
    np.testing.assert_array_equal(changed.control_points, cp + 5)
    p.unlink()
    with pytest.raises(TemplateError, match="no such template file"):
        load_template(p)
