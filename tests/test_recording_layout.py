"""Recordings that open with frames everywhere: frame storage, selected frames only, one plot per
unit, no empty views, and `trackcli view`."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from rerun.chunk import RrdReader

import rrd_utils as ru
from conftest import sample_clip
from trackcli.cli import cli
from trackcli.errors import ConfigError, InputError, TrackcliError
from trackcli.io.recording import Recording, frame_storage
from trackcli.io.viewer import check_recording, has_display, viewer_command


def run(args, code: int):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert "Traceback" not in result.output
    return result


def layout(path) -> dict[str, list[str]]:
    """View name -> contents queries (or [origin]) of the blueprint stored in a recording."""
    reader = RrdReader(Path(path))
    stores = reader.blueprints()
    assert len(stores) == 1
    views: dict[str, dict] = {}
    for chunk in reader.store(store=stores[0]).stream().to_chunks():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        entity = str(chunk.entity_path)
        for column, key in (("ViewBlueprint:display_name", "name"), ("ViewBlueprint:space_origin", "origin"),
                            ("ViewContents:query", "query")):
            if column in names:
                cells = [c for c in batch.column(names.index(column)).to_pylist() if c is not None]
                if cells:
                    views.setdefault(entity.rsplit("/", 1)[0] if key == "query" else entity, {})[key] = cells[-1]
    out = {}
    for v in views.values():
        if "name" in v:
            out[str(v["name"][0] if isinstance(v["name"], list) else v["name"])] = v
    return out


def _queries(view) -> list[str]:
    return [q for q in view.get("query", [])]


# ---------------------------------------------------------------------------------------------
# How frames are stored


@pytest.mark.parametrize(("mode", "codec", "embeddable", "whole", "av1", "expected"), [
    ("auto", "vp09", True, True, True, "av1"),     # the native viewer cannot play VP9: encoded as AV1
    ("auto", "vp09", True, True, False, "jpeg"),   # ... or JPEG without the AV1 encoder
    ("auto", "avc1", True, True, False, "jpeg"),   # H.264 needs FFmpeg beside the native viewer
    ("auto", "", False, True, True, "av1"),        # an image folder
    ("auto", "", False, True, False, "jpeg"),
    ("auto", "av01", True, True, True, "asset"),   # AV1 is decoded by every viewer: embedded as it is
    ("auto", "av01", True, True, False, "asset"),
    ("auto", "av01", True, False, True, "av1"),    # a selection: only its frames go in
    ("auto", "av01", True, False, False, "jpeg"),
    ("av1", "av01", True, True, True, "av1"),
    ("av1", "", False, True, False, "jpeg"),
    ("asset", "vp09", True, True, False, "asset"),
    ("asset", "vp09", True, False, True, "av1"),
    ("asset", "vp09", True, False, False, "jpeg"),
    ("asset", "mp4v", False, True, False, "jpeg"),
    ("jpeg", "av01", True, True, True, "jpeg"),
    ("jpeg", "", False, True, True, "jpeg"),
])
def test_frame_storage_choice(mode, codec, embeddable, whole, av1, expected):
    storage, reason = frame_storage(mode, codec=codec, embeddable=embeddable, whole_clip=whole, av1=av1)
    assert storage == expected and reason


def test_frame_storage_rejects_unknown_modes():
    with pytest.raises(ConfigError, match="output.frames"):
        frame_storage("h264", codec="", embeddable=False, whole_clip=True)


def _write_vp9(path, n=4, size=(64, 48)):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"vp09"), 25.0, size)
    if not writer.isOpened():
        return False
    for k in range(n):
        img = np.full((size[1], size[0], 3), 200, np.uint8)
        cv2.circle(img, (20 + 4 * k, 24), 10, (30, 30, 30), -1)
        writer.write(img)
    writer.release()
    return True


def test_sample_clip_is_stored_as_av1_and_only_the_selected_frames(tmp_path):
    clip = sample_clip("test")
    tmpl = tmp_path / "head.yaml"
    run(["draw", clip, "--box", "166,104,131,153", "-o", tmpl], 0)
    run(["track", clip, "--template", tmpl, "--tracker", "kalman", "--end", "5", "-o", tmp_path], 0)
    rrd = tmp_path / "test.kalman.rrd"
    assert ru.count_rows(rrd, "video", "AssetVideo:blob") == 0
    assert ru.read_index(rrd, "video", "VideoStream:sample") == [0, 1, 2, 3, 4]
    # asked for an asset: a selection is still stored as its own frames, not the whole clip
    cfg = tmp_path / "asset.yaml"
    cfg.write_text("output: {frames: asset}\n")
    run(["track", clip, "--template", tmpl, "--tracker", "kalman", "--start", "2", "--end", "5", "-c", cfg,
         "-o", tmp_path / "sel"], 0)
    rrd = tmp_path / "sel" / "test.kalman.rrd"
    assert ru.count_rows(rrd, "video", "AssetVideo:blob") == 0
    assert ru.read_index(rrd, "video", "VideoStream:sample") == [2, 3, 4]
    assert rrd.stat().st_size < clip.stat().st_size
    # asked for JPEG: JPEG frames
    cfg.write_text("output: {frames: jpeg}\n")
    run(["track", clip, "--template", tmpl, "--tracker", "kalman", "--end", "3", "-c", cfg, "-o", tmp_path / "j"], 0)
    rrd = tmp_path / "j" / "test.kalman.rrd"
    assert ru.read_index(rrd, "video", "EncodedImage:blob") == [0, 1, 2]
    assert ru.count_rows(rrd, "video", "VideoStream:sample") == 0


def test_asset_on_request_for_a_whole_vp9_clip(tmp_path):
    clip = tmp_path / "dot.mp4"
    if not _write_vp9(clip):
        pytest.skip("this OpenCV build cannot write VP9")
    tmpl = tmp_path / "dot.yaml"
    run(["draw", clip, "--ellipse", "20,24,10,10", "-o", tmpl], 0)
    cfg = tmp_path / "asset.yaml"
    cfg.write_text("output: {frames: asset}\n")
    run(["track", clip, "--template", tmpl, "--tracker", "kalman", "-c", cfg, "-o", tmp_path / "a"], 0)
    run(["track", clip, "--template", tmpl, "--tracker", "kalman", "-o", tmp_path / "d"], 0)
    asset, default = tmp_path / "a" / "dot.kalman.rrd", tmp_path / "d" / "dot.kalman.rrd"
    assert bytes(ru.read_column(asset, "video", "AssetVideo:blob")[0][0]) == clip.read_bytes()
    assert ru.count_rows(asset, "video", "EncodedImage:blob") == 0
    assert ru.count_rows(default, "video", "AssetVideo:blob") == 0
    assert ru.count_rows(default, "video", "EncodedImage:blob") == 4


# ---------------------------------------------------------------------------------------------
# The saved layout


def test_kalman_layout_plots_one_unit_per_view_and_has_no_empty_views(tmp_path, ellipse_clip):
    tmpl = tmp_path / "e.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    run(["track", ellipse_clip, "--template", tmpl, "--tracker", "kalman", "-o", tmp_path], 0)
    views = layout(tmp_path / "ellipse.kalman.rrd")
    assert set(views) == {"video", "pixels", "count", "parameters"}
    assert _queries(views["pixels"]) == ["/series/translation", "/series/centroid", "/series/gate_rms"]
    assert _queries(views["count"]) == ["/series/normals_with_feature"]


def test_condensation_layout_adds_ess_loglik_and_histograms(tmp_path, ellipse_clip):
    tmpl = tmp_path / "e.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    run(["track", ellipse_clip, "--template", tmpl, "--particles", "50", "-o", tmp_path], 0)
    views = layout(tmp_path / "ellipse.condensation.rrd")
    assert set(views) == {"video", "pixels", "count", "effective sample size", "log-likelihood", "histogram",
                          "histogram over time", "parameters"}
    assert _queries(views["effective sample size"]) == ["/series/ess"]
    assert _queries(views["log-likelihood"]) == ["/series/loglik"]


def test_series_sent_in_chunks_hold_every_frame_once(tmp_path, ellipse_clip, monkeypatch):
    """A run's plots are sent every SERIES_CHUNK frames (memory stays flat in the clip's length):
    the recording holds each frame's values once, as in the CSV, and the whole histogram image."""
    import csv

    from trackcli.settings import Settings
    from trackcli.run import sinks

    monkeypatch.setattr(sinks, "SERIES_CHUNK", 4)
    tmpl = tmp_path / "e.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", tmpl], 0)
    run(["track", ellipse_clip, "--template", tmpl, "--particles", "50", "-o", tmp_path], 0)
    path = tmp_path / "ellipse.condensation.rrd"
    with open(tmp_path / "ellipse.condensation.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) > 4  # at least one chunk sent before the end
    assert ru.read_index(path, "series/translation", "Scalars:scalars") == [int(r["frame"]) for r in rows]
    tx_ty = np.array(ru.read_column(path, "series/translation", "Scalars:scalars"))
    np.testing.assert_allclose(tx_ty, [[float(r["X_tx"]), float(r["X_ty"])] for r in rows], rtol=1e-6, atol=1e-6)
    ess = np.ravel(ru.read_column(path, "series/ess", "Scalars:scalars"))
    np.testing.assert_allclose(ess, [float(r["ess"]) for r in rows], rtol=1e-5)
    assert ru.read_column(path, "series/translation", "SeriesLines:names") == [["tx", "ty"]]
    fmt = ru.read_column(path, "histogram/tx_over_time", "Image:format")[0][0]
    assert (fmt["width"], fmt["height"]) == (Settings().condensation.histogram_bins, len(rows))


def test_series_without_a_unit_get_their_own_view_and_units_do_not_change(tmp_path):
    out = tmp_path / "r.rrd"
    with Recording(out, blueprint="track") as rec:
        rec.set_frame(0, 0.0)
        rec.log_scalar("series/a", 1.0, unit="px")
        rec.log_scalar("series/b", 2.0)
        rec.log_text("log", "hello")
        with pytest.raises(Exception, match="unit"):
            rec.log_scalar("series/a", 1.0, unit="count")
        assert rec.content() == {"series": {"px": ["series/a"], None: ["series/b"]}, "roots": ["log", "series"]}
    views = layout(out)
    assert set(views) == {"video", "pixels", "b", "log"}


# ---------------------------------------------------------------------------------------------
# trackcli view


def test_view_checks_the_file(tmp_path):
    bad = tmp_path / "x.rrd"
    bad.write_text("not a recording")
    err = run(["view", bad], 4)
    assert err.stderr.startswith("Error: ") and "not a Rerun recording" in err.stderr
    err = run(["view", tmp_path / "missing.rrd"], 4)
    assert "no such recording" in err.stderr
    with pytest.raises(InputError):
        check_recording(tmp_path)


def test_view_explains_what_is_missing(tmp_path, monkeypatch):
    rrd = tmp_path / "r.rrd"
    with Recording(rrd) as rec:
        rec.set_frame(0, 0.0)
        rec.log_scalar("series/a", 1.0)
    import trackcli.io.viewer as v

    with monkeypatch.context() as m:
        m.setattr(v, "find_viewer", lambda: None)
        with pytest.raises(TrackcliError, match=r'no Rerun viewer found.*pip install "rerun-sdk==0.41'):
            viewer_command(rrd, display=True)
    with pytest.raises(TrackcliError, match="no screen .*trackcli view --web"):
        viewer_command(rrd, viewer="rerun", display=False)
    assert viewer_command(rrd, viewer="rerun", display=True) == ["rerun", str(rrd)]
    assert viewer_command(rrd, viewer="rerun", web=True, port=9191, display=False) == [
        "rerun", "--web-viewer-port", "9191", "--web-viewer", str(rrd)]
    assert not has_display({}, "linux") and has_display({"DISPLAY": ":0"}, "linux")
    assert has_display({}, "darwin")


def test_view_runs_the_viewer_on_the_file(tmp_path, monkeypatch):
    rrd = tmp_path / "r.rrd"
    with Recording(rrd) as rec:
        rec.set_frame(0, 0.0)
        rec.log_scalar("series/a", 1.0)
    seen = tmp_path / "argv.txt"
    fake = tmp_path / "rerun"
    fake.write_text(f"#!{sys.executable}\nimport sys\nopen({str(seen)!r}, 'w').write(' '.join(sys.argv[1:]))\n")
    fake.chmod(0o755)
    import trackcli.io.viewer as v

    monkeypatch.setattr(v, "find_viewer", lambda: str(fake))
    monkeypatch.setenv("DISPLAY", ":99")
    run(["view", rrd], 0)
    assert seen.read_text() == str(rrd)
    run(["view", "--web", "--port", "9090", rrd], 0)
    assert seen.read_text() == f"--web-viewer-port 9090 --web-viewer {rrd}"
    run(["view", "--port", "9090", rrd], 2)
