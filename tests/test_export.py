"""Masks, VOT region lines and DAVIS J&F: results in the formats other tools read, and the
checks that a track, a clip and a truth belong together."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from trackcli.errors import DataError, InputError
from trackcli.run.checks import check_track_on_clip, sample_collapse
from trackcli.run.export import MASK_FOLDER_MARK, export_track
from trackcli.run.mask_eval import evaluate_masks, format_mask_table, statistics, write_mask_plot
from trackcli.run.masks import outline_mask, read_mask

W, H, N = 96, 64, 12


def disc(cx: float, cy: float, r: float, n: int = 48) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)])


def centre(i: int) -> tuple[float, float]:
    return 20.0 + 4 * i, 30.0


def write_track(path, outlines, frames=None):
    """A track CSV with outline columns only (what render, export and eval read)."""
    frames = range(len(outlines)) if frames is None else frames
    p = len(outlines[0])
    head = ["frame"] + [f"outline_{a}{k}" for k in range(p) for a in "xy"]
    rows = [",".join(head)]
    for f, o in zip(frames, outlines):
        cells = ["" if not np.isfinite(v) else f"{v:.4f}" for v in np.asarray(o, float).ravel()]
        rows.append(",".join([str(f), *cells]))
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture
def clip(tmp_path):
    """An image folder of N frames named f_000.jpg ..., a disc moving right."""
    d = tmp_path / "seq" / "img"
    d.mkdir(parents=True)
    for i in range(N):
        img = np.full((H, W, 3), 200, np.uint8)
        cv2.fillPoly(img, [np.rint(disc(*centre(i), 10)).astype(np.int32)], (40, 40, 40))
        cv2.imwrite(str(d / f"f_{i:03d}.jpg"), img)
    return d


@pytest.fixture
def truth(tmp_path):
    d = tmp_path / "seq" / "masks"
    d.mkdir(parents=True)
    for i in range(N):
        cv2.imwrite(str(d / f"f_{i:03d}.png"), outline_mask(disc(*centre(i), 10), (H, W)).astype(np.uint8) * 255)
    return d


def test_masks_are_named_as_the_frames_and_filled_0_255(tmp_path, clip):
    outlines = [disc(*centre(i), 10) for i in range(N)]
    outlines[3] = np.full_like(outlines[3], np.nan)  # a frame without an outline: an empty mask
    track = write_track(tmp_path / "t.csv", outlines)
    out = tmp_path / "masks"
    res = export_track(track, clip, masks=out, vot=tmp_path / "t.vot.txt", fps=25)
    assert res.frames == N
    assert sorted(p.name for p in out.iterdir() if p.suffix == ".png") == [f"f_{i:03d}.png" for i in range(N)]
    assert (out / MASK_FOLDER_MARK).is_file()
    for i in range(N):
        raw = cv2.imread(str(out / f"f_{i:03d}.png"), cv2.IMREAD_UNCHANGED)
        assert raw.dtype == np.uint8 and raw.shape == (H, W) and set(np.unique(raw)) <= {0, 255}
        np.testing.assert_array_equal(raw > 0, outline_mask(outlines[i], (H, W)))
    assert not read_mask(out / "f_003.png").any()
    lines = (tmp_path / "t.vot.txt").read_text().splitlines()
    assert len(lines) == N and lines[3] == "0"
    np.testing.assert_allclose(np.array(lines[5].split(","), float).reshape(-1, 2), outlines[5], atol=0.006)
    assert not list(tmp_path.glob(".*part*"))


def test_palette_masks_read_back_the_same_and_carry_the_davis_palette(tmp_path, clip):
    PIL = pytest.importorskip("PIL.Image")
    track = write_track(tmp_path / "t.csv", [disc(*centre(i), 10) for i in range(N)])
    export_track(track, clip, masks=tmp_path / "grey", fps=25)
    export_track(track, clip, masks=tmp_path / "pal", palette=True, fps=25)
    for i in (0, 7):
        name = f"f_{i:03d}.png"
        np.testing.assert_array_equal(read_mask(tmp_path / "pal" / name), read_mask(tmp_path / "grey" / name))
        im = PIL.open(tmp_path / "pal" / name)
        assert im.mode == "P" and im.getpalette()[:6] == [0, 0, 0, 128, 0, 0]
        assert set(np.unique(np.array(im))) == {0, 1}


def test_a_video_clip_names_masks_by_five_digit_index(tmp_path, ellipse_clip):
    from conftest import CLIP_FRAMES, CLIP_SIZE

    track = write_track(tmp_path / "t.csv", [disc(70, 60, 20)] * 3, frames=[0, 2, 4])
    export_track(track, ellipse_clip, masks=tmp_path / "m")
    assert sorted(p.name for p in (tmp_path / "m").glob("*.png")) == ["00000.png", "00002.png", "00004.png"]
    assert read_mask(tmp_path / "m" / "00002.png").shape == (CLIP_SIZE[1], CLIP_SIZE[0])
    assert CLIP_FRAMES > 4


def test_mask_folder_is_replaced_only_when_trackcli_wrote_it(tmp_path, clip, truth):
    track = write_track(tmp_path / "t.csv", [disc(*centre(i), 10) for i in range(N)])
    out = tmp_path / "masks"
    export_track(track, clip, masks=out, fps=25)
    export_track(write_track(tmp_path / "u.csv", [disc(30, 30, 5)] * 2), clip, masks=out, fps=25)
    assert len(list(out.glob("*.png"))) == 2  # replaced, not mixed
    # a folder of annotations (or frames) given by mistake is never replaced
    before = sorted(p.name for p in truth.iterdir())
    with pytest.raises(InputError, match="did not write"):
        export_track(track, clip, masks=truth, fps=25)
    with pytest.raises(InputError, match="did not write"):
        export_track(track, clip, masks=clip, fps=25)
    assert sorted(p.name for p in truth.iterdir()) == before


def test_a_track_that_does_not_fit_the_clip_is_refused_or_warned(tmp_path, clip):
    far = write_track(tmp_path / "far.csv", [disc(30, 30, 5)] * 3, frames=[0, 10, N + 5])
    with pytest.raises(DataError, match=f"up to frame {N + 5} but .* has {N} frames"):
        export_track(far, clip, masks=tmp_path / "m", fps=25)
    assert not (tmp_path / "m").exists()
    notes = []
    out = write_track(tmp_path / "out.csv", [disc(500, 400, 10)] * 4)
    export_track(out, clip, vot=tmp_path / "o.txt", fps=25, warn=notes.append)
    assert len(notes) == 1 and "outside the 96x64 frames" in notes[0]
    # a 128x96 track drawn on a 1280x720 clip: every estimate in the top-left corner
    small = [disc(60 + i, 50, 30) for i in range(10)]
    notes = check_track_on_clip(np.arange(10), np.array(small), width=1280, height=720, n_frames=100,
                                track="t.csv", clip="big.mp4")
    assert len(notes) == 1 and "top-left 99x80 px of the 1280x720 frames" in notes[0]
    assert check_track_on_clip(np.arange(10), np.array(small), width=128, height=96, n_frames=10,
                               track="t.csv", clip="c") == []


def test_collapsed_sample_sets_are_told_apart_from_sharp_ones():
    rng = np.random.default_rng(0)
    tight = np.clip(rng.normal(1.1, 0.2, 80), 1, None)       # -c tight on the sample clip: ESS about 1
    default = rng.gamma(2.0, 5.0, 160)                        # the defaults: ESS 2-25 of N = 500
    note = sample_collapse(tight, 500, name="test")
    assert note is not None and note.startswith("test: the sample set collapsed") and "80 of 80 frames" in note
    assert sample_collapse(default, 500) is None
    assert sample_collapse(np.full(20, np.nan), 500) is None  # the Kalman tracker has no samples


def test_davis_statistics_follow_the_benchmark_definitions():
    v = np.array([0.9, 0.8, 0.7, 0.6, 0.4, 0.3, 0.2, 0.1])
    mean, recall, decay = statistics(v)
    assert mean == pytest.approx(0.5) and recall == pytest.approx(0.5)
    # quarters of 8 frames by DAVIS's bin edges round(linspace(1, 8, 5)) - 1 = 0, 2, 4, 5, 7 (inclusive)
    assert decay == pytest.approx(np.mean([0.9, 0.8, 0.7]) - np.mean([0.3, 0.2, 0.1]))


def test_eval_of_masks_and_of_a_track_give_the_same_j_and_f(tmp_path, clip, truth):
    shifted = [disc(centre(i)[0] + 3, centre(i)[1], 10) for i in range(N)]
    track = write_track(tmp_path / "t.csv", shifted)
    export_track(track, clip, masks=tmp_path / "m", fps=25)
    a = evaluate_masks(tmp_path / "m", truth)
    b = evaluate_masks(track, truth)
    assert a.notes == () and b.notes == ()
    np.testing.assert_allclose(a.scores.J, b.scores.J)
    np.testing.assert_allclose(a.scores.F, b.scores.F)
    # J of two discs of radius 10 three pixels apart, on the pixel grid
    m0, t0 = outline_mask(shifted[1], (H, W)), read_mask(truth / "f_001.png")
    assert a.scores.J[1] == pytest.approx(np.count_nonzero(m0 & t0) / np.count_nonzero(m0 | t0))
    s = a.summary()
    assert s["frames_scored"] == N and s["frames_counted"] == N - 2
    assert s["J_mean"] == pytest.approx(np.mean(a.scores.J[1:-1]))
    assert 0.6 < s["J_mean"] < 0.8 and s["J_recall"] == 1.0
    assert "J (region IoU)" in format_mask_table(a)
    perfect = evaluate_masks(truth, truth).summary()
    assert perfect["J_mean"] == perfect["F_mean"] == perfect["JF_mean"] == 1.0 and perfect["J_decay"] == 0.0
    d = a.to_dict()
    assert d["metric"] == "davis" and len(d["J"]) == len(d["F"]) == len(d["frames"]) == N
    png = write_mask_plot(tmp_path / "jf.png", [("masks", a), ("csv", b)])
    assert cv2.imread(str(png)).shape == (440, 1000, 3)


def test_eval_refuses_or_warns_when_prediction_and_truth_do_not_belong_together(tmp_path, clip, truth):
    big = tmp_path / "big"
    big.mkdir()
    for i in range(N):
        cv2.imwrite(str(big / f"f_{i:03d}.png"), np.zeros((H * 2, W * 2), np.uint8))
    with pytest.raises(DataError, match=f"is {2 * W}x{2 * H} but the truth .* is {W}x{H}"):
        evaluate_masks(big, truth)
    # a track longer than the truth: refused; shorter: the frames in both, said in one line
    with pytest.raises(DataError, match="another clip"):
        evaluate_masks(write_track(tmp_path / "long.csv", [disc(30, 30, 8)] * (N + 3)), truth)
    short = evaluate_masks(write_track(tmp_path / "s.csv", [disc(*centre(i), 10) for i in range(5)]), truth)
    assert len(short.scores.J) == 5 and "scored the 5 in both" in short.notes[-1]
    # another clip's truth: the masks never meet the object
    elsewhere = evaluate_masks(write_track(tmp_path / "e.csv", [disc(80, 10, 6)] * N), truth)
    assert "on any frame" in elsewhere.notes[-1]
