"""What a user of a segmentation benchmark runs: draw on the first mask, track --masks, eval J and F,
render to MP4, render --masks from a CSV, batch with a missing clip; and the one-line warnings
when inputs do not belong together."""

from __future__ import annotations

import json
import logging

import cv2
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from conftest import sample_clip
from trackcli.cli import cli
from trackcli.run.masks import outline_mask, read_mask

W, H, N = 160, 120, 12


def run(args, code: int):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert "Traceback" not in result.output
    return result


def disc(i: int, n: int = 64) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([50 + 4 * i + 18 * np.cos(t), 60 + 14 * np.sin(t)])


def write_sequence(root, name: str = "seq", frames: int = N):
    """A DAVIS/OTB-layout sequence: NAME/img/00000.jpg ..., NAME/masks/00000.png ..., NAME/groundtruth_rect.txt."""
    seq = root / name
    (seq / "img").mkdir(parents=True)
    (seq / "masks").mkdir()
    rng = np.random.default_rng(3)
    boxes = []
    for i in range(frames):
        img = np.clip(200 + rng.normal(0, 5, (H, W, 3)), 0, 255).astype(np.uint8)
        cv2.fillPoly(img, [np.rint(disc(i) * 16).astype(np.int32)], (40, 60, 150), cv2.LINE_AA, 4)
        cv2.imwrite(str(seq / "img" / f"{i:05d}.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
        m = outline_mask(disc(i), (H, W))
        cv2.imwrite(str(seq / "masks" / f"{i:05d}.png"), m.astype(np.uint8) * 255)
        ys, xs = np.nonzero(m)
        boxes.append(f"{xs.min()},{ys.min()},{xs.max() - xs.min() + 1},{ys.max() - ys.min() + 1}")
    (seq / "groundtruth_rect.txt").write_text("\n".join(boxes) + "\n")
    return seq


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    """draw on the first mask, then track --masks --vot, as the docs show it."""
    root = tmp_path_factory.mktemp("davis")
    seq = write_sequence(root)
    run(["draw", seq / "img", "--mask", seq / "masks" / "00000.png", "-o", root / "seq.yaml"], 0)
    res = run(["track", seq / "img", "--template", root / "seq.yaml", "--fps", "25", "-o", root / "out",
               "--masks", root / "masks", "--vot", root / "seq.vot.txt"], 0)
    return root, seq, res


def test_track_masks_are_named_as_the_frames_and_outputs_after_the_sequence(tracked):
    """The masks are written by a sink of the frame loop, from each frame's outline as tracked."""
    root, seq, res = tracked
    # NAME/img is named NAME, not img
    assert (root / "out" / "seq.condensation.csv").is_file() and not list((root / "out").glob("img.*"))
    assert f"masks -> {root / 'masks'}" in res.stdout
    names = sorted(p.name for p in (root / "masks").glob("*.png"))
    assert names == [f"{i:05d}.png" for i in range(N)]
    assert read_mask(root / "masks" / "00005.png").shape == (H, W)
    assert len((root / "seq.vot.txt").read_text().splitlines()) == N


def test_eval_of_the_masks_prints_j_and_f_and_agrees_with_the_csv(tracked, tmp_path):
    root, seq, _ = tracked
    res = run(["eval", root / "masks", seq / "masks"], 0)
    assert "J (region IoU)" in res.stdout and "F (boundary)" in res.stdout and "J&F" in res.stdout
    j_masks = float(res.stdout.split("J (region IoU)")[1].split("mean")[1].split()[0])
    assert j_masks > 0.8  # a disc sliding over a plain background is followed
    res = run(["eval", root / "out" / "seq.condensation.csv", root / "masks", seq / "masks", "--json",
               "--plot", tmp_path / "jf.png"], 0)
    csv_score, mask_score = [json.loads(line) for line in res.stdout.splitlines()]
    assert abs(csv_score["J_mean"] - mask_score["J_mean"]) <= 0.02
    assert mask_score["J_mean"] == pytest.approx(j_masks, abs=1e-3)
    assert mask_score["metric"] == "davis" and len(mask_score["J"]) == len(mask_score["F"]) == N
    assert mask_score["counted"] == [False] + [True] * (N - 2) + [False]
    assert cv2.imread(str(tmp_path / "jf.png")).shape == (440, 1000, 3)
    # a folder of masks against a box truth is a usage error
    res = run(["eval", root / "masks", seq], 3)
    assert "folder of true masks" in res.stderr


def test_render_masks_from_the_csv_and_h264_video(tracked, tmp_path):
    root, seq, _ = tracked
    csv = root / "out" / "seq.condensation.csv"
    res = run(["render", csv, seq / "img", "--fps", "25", "--masks", tmp_path / "m", "--palette"], 0)
    assert res.stdout.startswith("wrote masks -> ")
    for i in (0, 7):
        # from the CSV's 64 outline points: the masks track --masks made from each frame's outline, nearly
        a, b = read_mask(tmp_path / "m" / f"{i:05d}.png"), read_mask(root / "masks" / f"{i:05d}.png")
        assert np.count_nonzero(a & b) / np.count_nonzero(a | b) > 0.97
    run(["render", csv, seq / "img", "--masks", tmp_path / "m2", "-o", tmp_path / "x.mp4"], 2)
    run(["render", csv, seq / "img", "--palette"], 2)
    res = run(["render", csv, seq / "img", "--fps", "25", "-o", tmp_path / "v.mp4"], 0)
    assert "video (h264)" in res.stdout
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == N


def test_inputs_that_do_not_belong_together(tracked, tmp_path, caplog):
    root, seq, _ = tracked
    csv = root / "out" / "seq.condensation.csv"
    # another clip's truth, of another length: the track meets its box on no frame
    other = write_sequence(tmp_path, "other", frames=N + 8)
    lines = (other / "groundtruth_rect.txt").read_text().splitlines()
    (other / "groundtruth_rect.txt").write_text("\n".join(f"120,2,{b.split(',')[2]},{b.split(',')[3]}"
                                                          for b in lines) + "\n")
    res = run(["eval", csv, other], 0)
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("Warning: ")
    assert "another clip" in res.stderr and "8 truth frames outside" in res.stderr
    # a track with frames past the truth's sequence: refused
    short = write_sequence(tmp_path, "short", frames=6)
    res = run(["eval", csv, short], 5)
    assert res.stderr.startswith("Error: ") and "has 6 frames" in res.stderr
    res = run(["eval", csv, short / "masks"], 5)
    assert "another clip" in res.stderr
    # masks of another size
    big = tmp_path / "big"
    big.mkdir()
    for i in range(N):
        cv2.imwrite(str(big / f"{i:05d}.png"), np.zeros((2 * H, 2 * W), np.uint8))
    res = run(["eval", root / "masks", big], 5)
    assert f"is {W}x{H} but the truth" in res.stderr
    # a small clip's track rendered on a larger clip: a warning, the video still written
    large = tmp_path / "large"
    large.mkdir()
    for i in range(N):
        cv2.imwrite(str(large / f"{i:05d}.png"), np.zeros((4 * H, 4 * W, 3), np.uint8))
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        run(["render", csv, large, "--fps", "25", "-o", tmp_path / "large.mp4"], 0)
    assert "made on a smaller clip" in caplog.text


def test_several_clips_take_masks_per_clip_and_refuse_one_vot_file(tracked, tmp_path):
    root, seq, _ = tracked
    res = run(["track", seq / "img", root / "out" / "..", "--template", root / "seq.yaml", "--vot", tmp_path / "v.txt"],
              2)
    assert "--vot" in res.stderr
    # the annotations folder is never taken for an output folder
    res = run(["track", seq / "img", "--template", root / "seq.yaml", "--fps", "25", "-o", tmp_path / "o",
               "--masks", seq / "masks"], 4)
    assert "did not write" in res.stderr and not (tmp_path / "o").exists()
    assert len(list((seq / "masks").glob("*.png"))) == N


def test_a_collapsed_sample_set_is_warned_about(tmp_path, caplog):
    clip = sample_clip("test")
    run(["draw", clip, "--box", "166,104,132,153", "-o", tmp_path / "t.yaml"], 0)
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        run(["track", clip, "--template", tmp_path / "t.yaml", "-c", "tight", "--end", "16", "--no-rrd",
             "-o", tmp_path / "tight"], 0)
    notes = [r.getMessage() for r in caplog.records if "collapsed" in r.getMessage()]
    assert len(notes) == 1 and notes[0].startswith("test: the sample set collapsed") and "\n" not in notes[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="trackcli"):
        run(["track", clip, "--template", tmp_path / "t.yaml", "--end", "16", "--no-rrd", "-o", tmp_path / "d"], 0)
    assert "collapsed" not in caplog.text


def test_batch_runs_every_clip_it_can_and_reports_the_missing_at_the_end(tracked, tmp_path):
    root, seq, _ = tracked
    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump({"defaults": {"template": str(root / "seq.yaml"), "fps": 25,
                                                     "settings": {"video.end": 4}},
                                        "clips": [{"clip": str(tmp_path / "absent" / "img")},
                                                  {"clip": str(seq / "img")},
                                                  {"clip": str(seq / "img"), "name": "again",
                                                   "template": str(tmp_path / "absent.yaml")}]}))
    res = run(["batch", manifest, "-o", tmp_path / "out", "--masks", "--vot", "--json"], 1)
    clips = [json.loads(line) for line in res.stdout.splitlines()]
    assert [(c["name"], c["status"], c["missing"]) for c in clips[:-1]] == [
        ("absent", "failed", True), ("seq", "ok", False), ("again", "failed", True)]
    assert clips[-1]["missing"] == 2 and clips[-1]["ok"] == 1
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("Error: 2 of 3 clips did not run") and "absent.yaml" in last and "absent/img" in last
    assert sorted(p.name for p in (tmp_path / "out" / "seq" / "masks").glob("*.png")) == [
        f"{i:05d}.png" for i in range(4)]
    assert len((tmp_path / "out" / "seq" / "seq.condensation.vot.txt").read_text().splitlines()) == 4
    # run again: the complete clip is skipped, the missing ones are still reported
    res = run(["batch", manifest, "-o", tmp_path / "out", "--masks", "--vot"], 1)
    assert "skipped" in res.stdout and "2 of 3 clips did not run" in res.stderr
