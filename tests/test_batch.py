"""Tests for batch runs (`trackcli batch`, trackcli.run.batch) and for shell-script behaviour of the CLI.

The batches run short selections of the sample clips (a dozen frames, 60 particles) so that
local processes, a Dask cluster, failures, re-runs and interruptions can all be exercised
for real in well under a minute.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from conftest import REPO, SAMPLE_DATA, sample_clip
from trackcli.run import batch
from trackcli.cli import cli
from trackcli.errors import ConfigError, InputError
from trackcli.run.evaluate import evaluate, load_truth
from trackcli.trackers import TRACKERS

FRAMES = 12
PARTICLES = 60


def run(args, code: int, **kw):
    """Invoke the CLI in-process; check the exit code and that no traceback escaped."""
    result = CliRunner().invoke(cli, [str(a) for a in args], **kw)
    assert result.exit_code == code, f"exit {result.exit_code}, expected {code}; output:\n{result.output}"
    assert "Traceback" not in result.output
    return result


def json_lines(text: str) -> list[dict]:
    return [json.loads(line) for line in text.splitlines() if line.strip()]


# ---------------------------------------------------------------------------------------------
# Fixtures: templates, a model, manifests


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """Templates on train, test, three_heads (person 0) and bouncing_ball, and a model from train."""
    for name in ("train", "test", "three_heads", "bouncing_ball"):
        sample_clip(name)
    d = tmp_path_factory.mktemp("inputs")
    boxes = {"train": "172,92,136,155", "test": "166,104,132,153", "three_heads": "37,186,117,133"}
    for clip, box in boxes.items():
        run(["draw", SAMPLE_DATA / f"{clip}.mp4", "--box", box, "-o", d / f"{clip}.yaml"], 0)
    run(["draw", SAMPLE_DATA / "bouncing_ball.mp4", "--ellipse", "40,70,16,16", "-o", d / "ball.yaml"], 0)
    run(["learn", "--template", d / "train.yaml", SAMPLE_DATA / "train.mp4", "-o", d / "model.yaml",
         "--cycles", "1", "--no-rrd", "--end", "60"], 0)
    return d


def write_manifest(folder: Path, inputs: Path, clips: list[dict], **defaults) -> Path:
    """A manifest in ``folder`` with paths relative to it, as users write them."""
    folder.mkdir(parents=True, exist_ok=True)
    rel = lambda p: os.path.relpath(p, folder)  # noqa: E731
    d = {"model": rel(inputs / "model.yaml"), "seed": 3,
         "settings": {"condensation": {"particles": PARTICLES}, "video.end": FRAMES}}
    d.update(defaults)
    entries = []
    for c in clips:
        c = dict(c)
        for key in ("clip", "template", "truth", "model", "config"):
            if c.get(key) is not None:
                c[key] = rel(c[key])
        entries.append(c)
    path = folder / "batch.yaml"
    path.write_text(yaml.safe_dump({"format": 1, "defaults": d, "clips": entries}, sort_keys=False))
    return path


def sample_entries(inputs: Path) -> list[dict]:
    return [
        {"clip": SAMPLE_DATA / "test.mp4", "template": inputs / "test.yaml", "truth": SAMPLE_DATA / "test.truth.csv"},
        {"clip": SAMPLE_DATA / "three_heads.mp4", "template": inputs / "three_heads.yaml",
         "truth": SAMPLE_DATA / "three_heads.truth.csv", "name": "person0"},
        {"clip": SAMPLE_DATA / "bouncing_ball.mp4", "model": None, "template": inputs / "ball.yaml",
         "truth": SAMPLE_DATA / "bouncing_ball.truth.csv", "tracker": "kalman"},
    ]


NAMES = ["test", "person0", "bouncing_ball"]


def assert_complete(folder: Path, name: str, tracker: str) -> dict:
    """The job folder holds finished outputs only; returns result.json."""
    assert not list(folder.glob(".*.part")), list(folder.iterdir())
    for suffix in (".csv", ".rrd", ".config.yaml"):
        assert (folder / f"{name}.{tracker}{suffix}").stat().st_size > 0
    result = json.loads((folder / "result.json").read_text())
    assert result["status"] == "ok" and result["frames"] == FRAMES
    return result


def assert_no_partial_output(folder: Path) -> None:
    """An unfinished job: no result, no CSV, no recording, no temporary files."""
    if not folder.exists():
        return
    left = sorted(p.name for p in folder.iterdir())
    assert "result.json" not in left and "score.json" not in left, left
    assert not [n for n in left if n.endswith((".csv", ".rrd", ".part"))], left


# ---------------------------------------------------------------------------------------------
# Running batches


@pytest.fixture(scope="module")
def local_run(inputs, tmp_path_factory):
    """The sample batch run with two local worker processes: (manifest, outdir, JSON lines)."""
    work = tmp_path_factory.mktemp("local")
    manifest = write_manifest(work / "manifests", inputs, sample_entries(inputs))
    out = work / "out"
    result = run(["batch", manifest, "--jobs", "2", "-o", out, "--json"], 0)
    return manifest, out, json_lines(result.stdout)


def test_batch_on_two_local_processes(local_run):
    manifest, out, lines = local_run
    clips, summary = lines[:-1], lines[-1]
    assert [c["kind"] for c in clips] == ["clip"] * 3 and summary["kind"] == "summary"
    assert [c["name"] for c in clips] == NAMES  # manifest order, whatever the order of completion
    assert summary["executor"] == "processes:2"
    assert (summary["clips"], summary["ok"], summary["skipped"], summary["failed"]) == (3, 3, 0, 0)
    pids = set()
    for c, tracker in zip(clips, ["condensation", "condensation", "kalman"]):
        assert c["status"] == "ok" and c["error"] is None and c["frames"] == FRAMES
        stored = assert_complete(out / c["name"], c["name"], tracker)
        assert stored["fingerprint"] and stored["worker"]["pid"] != os.getpid()
        pids.add(stored["worker"]["pid"])
        # the scores are those `evaluate` gives for the written track
        truth = load_truth(SAMPLE_DATA / f"{Path(c['clip']).stem}.truth.csv")
        ref = evaluate(c["outputs"]["csv"], truth)
        assert c["precision"] == pytest.approx(ref.precision)
        assert c["success_auc"] == pytest.approx(ref.success_auc)
        assert c["centre_error_mean"] == pytest.approx(ref.centre_error_mean)
        score = json.loads((out / c["name"] / "score.json").read_text())
        assert score["frames_scored"] == ref.frames_scored == FRAMES
    assert len(pids) == 2, "two jobs should have run in two different worker processes"
    # the effective configuration carries the manifest's settings
    cfg = yaml.safe_load((out / "test" / "test.condensation.config.yaml").read_text())
    assert cfg["condensation"]["particles"] == PARTICLES and cfg["video"]["end"] == FRAMES and cfg["seed"] == 3
    saved = json.loads((out / "summary.json").read_text())
    assert [c["name"] for c in saved["clips"]] == NAMES and saved["summary"]["ok"] == 3


def test_batch_on_a_dask_cluster_gives_the_same_tracks(local_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    manifest, local_out, _ = local_run
    out = tmp_path / "dask"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        result = run(["batch", manifest, "--scheduler", cluster.scheduler_address, "-o", out, "--json"], 0)
    lines = json_lines(result.stdout)
    assert lines[-1]["executor"] == "dask" and lines[-1]["ok"] == 3
    for c in lines[:-1]:
        assert c["status"] == "ok"
        # same seed, same settings: the same numbers, byte for byte, whoever ran the job
        csv = Path(c["outputs"]["csv"])
        assert csv.read_bytes() == (local_out / c["name"] / csv.name).read_bytes()


def test_scheduler_without_dask_says_how_to_install(local_run, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    manifest = local_run[0]
    result = run(["batch", manifest, "--scheduler", "tcp://127.0.0.1:1", "-o", tmp_path], 3)
    assert result.stderr.strip().splitlines() == [
        "Error: running on a Dask scheduler needs dask.distributed: pip install 'trackcli[dask]'"]


def test_jobs_and_scheduler_together_are_a_usage_error(local_run, tmp_path):
    result = run(["batch", local_run[0], "--jobs", "2", "--scheduler", "tcp://x:1", "-o", tmp_path], 2)
    assert "give --jobs (local processes) or --scheduler (Dask), not both" in result.stderr


def test_a_broken_clip_fails_alone(inputs, tmp_path):
    corrupt = tmp_path / "corrupt.mp4"
    corrupt.write_bytes(np.random.default_rng(5).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    entries = [sample_entries(inputs)[2],
               {"clip": corrupt, "template": inputs / "test.yaml"},
               sample_entries(inputs)[0]]
    manifest = write_manifest(tmp_path / "m", inputs, entries)
    out = tmp_path / "out"
    result = run(["-q", "batch", manifest, "-o", out, "--json"], 1)
    lines = json_lines(result.stdout)
    status = {c["name"]: c["status"] for c in lines[:-1]}
    assert status == {"bouncing_ball": "ok", "corrupt": "failed", "test": "ok"}
    failed = lines[1]
    assert str(corrupt) in failed["error"] and "\n" not in failed["error"]
    assert lines[-1]["failed"] == 1 and lines[-1]["ok"] == 2
    # -q: the failure is the only thing on stderr
    assert result.stderr.splitlines() == [f"[2/3] corrupt: FAILED: {failed['error']}"]
    assert_complete(out / "bouncing_ball", "bouncing_ball", "kalman")
    assert_complete(out / "test", "test", "condensation")
    assert_no_partial_output(out / "corrupt")
    assert not (out / "corrupt").exists()  # a job that wrote nothing leaves no empty folder
    # a clip's JSON object starts with the same keys as in `track --json`, failed or not
    from trackcli.run.clips import CLIP_JSON_KEYS

    for c in lines[:-1]:
        assert c["kind"] == "clip" and list(c)[: len(CLIP_JSON_KEYS)] == list(CLIP_JSON_KEYS)
    track = run(["-q", "track", "--template", inputs / "test.yaml", corrupt, SAMPLE_DATA / "test.mp4",
                 "--end", "5", "--no-rrd", "--json", "-o", tmp_path / "track"], 1)
    tracked = json_lines(track.stdout)
    assert [c["status"] for c in tracked] == ["failed", "ok"]
    for c in tracked:
        assert c["kind"] == "clip" and list(c)[: len(CLIP_JSON_KEYS)] == list(CLIP_JSON_KEYS)
    assert str(corrupt) in tracked[0]["error"] and tracked[0]["frames"] is None
    assert tracked[1]["frames"] == 5 and tracked[1]["csv"].endswith("test.condensation.csv")
    # the table names the failed clip
    table = run(["batch", manifest, "-o", out], 1).stdout
    row = next(line for line in table.splitlines() if line.startswith("corrupt"))
    assert row.split()[:2] == ["corrupt", "failed"]


def test_rerun_skips_complete_clips_and_force_runs_them_again(inputs, tmp_path):
    manifest = write_manifest(tmp_path / "m", inputs, [sample_entries(inputs)[2]])
    out = tmp_path / "out"
    first = json_lines(run(["batch", manifest, "-o", out, "--json"], 0).stdout)[0]
    csv = Path(first["outputs"]["csv"])
    stamp, content = csv.stat().st_mtime_ns, csv.read_bytes()

    again = run(["batch", manifest, "-o", out, "--json"], 0)
    second = json_lines(again.stdout)[0]
    assert second["status"] == "skipped" and csv.stat().st_mtime_ns == stamp
    assert second["precision"] == first["precision"] and second["frames"] == FRAMES
    assert "[1/1] bouncing_ball: skipped, outputs complete" in again.stderr

    time.sleep(0.01)
    forced = json_lines(run(["batch", manifest, "-o", out, "--json", "--force"], 0).stdout)[0]
    assert forced["status"] == "ok" and csv.stat().st_mtime_ns != stamp and csv.read_bytes() == content

    # a job whose result.json is gone is not complete
    (out / "bouncing_ball" / "result.json").unlink()
    assert json_lines(run(["batch", manifest, "-o", out, "--json"], 0).stdout)[0]["status"] == "ok"

    # a changed manifest changes the job: it runs again
    data = yaml.safe_load(manifest.read_text())
    data["clips"][0]["settings"] = {"kalman": {"rho_f": 6.0}}
    manifest.write_text(yaml.safe_dump(data))
    changed = json_lines(run(["batch", manifest, "-o", out, "--json"], 0).stdout)[0]
    assert changed["status"] == "ok"
    assert json_lines(run(["batch", manifest, "-o", out, "--json"], 0).stdout)[0]["status"] == "skipped"


def test_an_interrupted_job_leaves_no_partial_output(inputs, tmp_path, monkeypatch):
    from trackcli.trackers.condensation_tracker import CondensationTracker

    real = CondensationTracker.step
    seen = []

    def interrupted(self, frame):
        k = len(seen)
        seen.append(k)
        if k == 4:
            raise KeyboardInterrupt
        return real(self, frame)

    monkeypatch.setattr(CondensationTracker, "step", interrupted)
    manifest = write_manifest(tmp_path / "m", inputs, [sample_entries(inputs)[0]])
    out = tmp_path / "out"
    result = run(["batch", manifest, "-o", out], 130)
    assert seen == [0, 1, 2, 3, 4]
    assert "Interrupted." in result.stderr
    assert_no_partial_output(out / "test")
    assert not (out / "summary.json").exists()


def start_batch(manifest: Path, out: Path, *extra: str) -> subprocess.Popen:
    env = {**os.environ, "CI": "true"}
    return subprocess.Popen([sys.executable, "-m", "trackcli.cli", "batch", str(manifest), "-o", str(out), *extra],
                            cwd=REPO, env=env, start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for_partial_csv(proc: subprocess.Popen, out: Path, timeout: float = 30.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if list(out.glob("*/.*.csv.part")):
            return
        if proc.poll() is not None:
            pytest.fail(f"the batch ended before it was interrupted: {proc.communicate()}")
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    pytest.fail("no clip started within the time limit")


def long_entries(inputs: Path) -> list[dict]:
    return [{**e, "settings": {"video.end": None}} for e in sample_entries(inputs)[:2]]


def test_ctrl_c_on_a_two_process_batch(inputs, tmp_path):
    manifest = write_manifest(tmp_path / "m", inputs, long_entries(inputs))
    out = tmp_path / "out"
    proc = start_batch(manifest, out, "--jobs", "2")
    wait_for_partial_csv(proc, out)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "Interrupted." in stderr
    for name in ("test", "person0"):
        assert_no_partial_output(out / name)


def test_a_killed_batch_leaves_no_result_and_the_next_run_completes(inputs, tmp_path):
    manifest = write_manifest(tmp_path / "m", inputs, long_entries(inputs)[:1])
    out = tmp_path / "out"
    proc = start_batch(manifest, out)
    wait_for_partial_csv(proc, out)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    folder = out / "test"
    names = {p.name for p in folder.iterdir()}
    # killed outright: only temporaries, never a file under its final name that is incomplete
    assert "result.json" not in names and "test.condensation.csv" not in names and "test.condensation.rrd" not in names
    assert ".test.condensation.csv.part" in names
    # the next run cleans up and finishes (shortened so as to stay quick)
    data = yaml.safe_load(manifest.read_text())
    data["clips"][0]["settings"] = {"video.end": FRAMES}
    manifest.write_text(yaml.safe_dump(data))
    line = json_lines(run(["batch", manifest, "-o", out, "--json"], 0).stdout)[0]
    assert line["status"] == "ok"
    assert_complete(folder, "test", "condensation")


# ---------------------------------------------------------------------------------------------
# Manifest validation


def test_manifest_paths_are_relative_to_the_manifest(inputs, tmp_path, monkeypatch):
    manifest = write_manifest(tmp_path / "deep" / "er", inputs, sample_entries(inputs))
    monkeypatch.chdir(tmp_path)
    m = batch.load_manifest(manifest)
    assert [j.name for j in m.jobs] == NAMES
    job = m.jobs[0]
    assert job.clip == str(SAMPLE_DATA / "test.mp4") and job.model == str(inputs / "model.yaml")
    assert job.settings.condensation.particles == PARTICLES and job.settings.seed == 3
    ball = m.jobs[2]
    assert ball.model is None and ball.tracker == "kalman" and ball.template == str(inputs / "ball.yaml")


def test_settings_merge_in_order(inputs, tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("seed: 1\ncondensation: {particles: 10}\nmeasurement: {n_normals: 30}\n")
    entries = [{"clip": SAMPLE_DATA / "test.mp4", "template": inputs / "test.yaml",
                "settings": {"condensation.particles": 20}, "seed": 9},
               {"clip": SAMPLE_DATA / "train.mp4", "template": inputs / "train.yaml", "fps": 12.5}]
    manifest = write_manifest(tmp_path, inputs, entries, config=str(cfg), settings={"measurement": {"n_normals": 40}})
    a, b = batch.load_manifest(manifest).jobs
    assert (a.settings.seed, a.settings.condensation.particles, a.settings.measurement.n_normals) == (9, 20, 40)
    assert (b.settings.seed, b.settings.condensation.particles, b.settings.video.fps) == (3, 10, 12.5)


@pytest.mark.parametrize("change, code, message", [
    (lambda d: d["defaults"].update(model="absent.yaml"), 4, "defaults.model: no such file: "),
    (lambda d: d["clips"][2].update(tracker="meanshift"), 3,
     f"clips[2].tracker: expected one of {', '.join(TRACKERS)}, got 'meanshift'"),
    (lambda d: d["clips"][1].update(settings={"condensation": {"particles": 0}}), 3,
     "clips[1].settings.condensation.particles: expected an integer in [1, 1000000], got 0"),
    (lambda d: d["defaults"].update(settings={"condensation.particlez": 5}), 3,
     "defaults.settings.condensation.particlez: unknown setting"),
    (lambda d: d["defaults"].update(seed=-1), 3, "defaults.seed: expected an integer >= 0, got -1"),
    (lambda d: d["clips"][0].update(fps=0), 3, "clips[0].fps: expected a number > 0, got 0"),
    (lambda d: d["clips"][0].update(colour="red"), 3, "clips[0].colour: unknown key (valid: clip, name, "),
    (lambda d: d["defaults"].update(clip="x.mp4"), 3, "defaults.clip: unknown key"),
    (lambda d: d["clips"][1].update(name="test"), 3, "clips[1].name: 'test' is also the name of clips[0]"),
    (lambda d: d["clips"][1].update(name="../up"), 3, "clips[1].name: expected a folder name"),
    (lambda d: d["clips"][2].update(model=None, template=None), 3, "clips[2]: give a model, a template, or both"),
    (lambda d: d["clips"][0].pop("clip"), 3, "clips[0]: missing 'clip'"),
    (lambda d: d["clips"][1].update(object=-2), 3, "clips[1].object: expected an integer >= 0, got -2"),
    (lambda d: d["clips"][1].update(rrd="no"), 3, "clips[1].rrd: expected true or false, got 'no'"),
    (lambda d: d.update(format=2), 3, "format: this version reads manifest format 1, got 2"),
    (lambda d: d.update(clips=[]), 3, "clips: expected a non-empty list of clips"),
    (lambda d: d.update(jobs=4), 3, "jobs: unknown key (valid at the top level: format, defaults, clips)"),
])
def test_manifest_errors_name_the_entry_and_key(inputs, tmp_path, change, code, message):
    manifest = write_manifest(tmp_path, inputs, sample_entries(inputs))
    data = yaml.safe_load(manifest.read_text())
    change(data)
    manifest.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(InputError if code == 4 else ConfigError) as err:
        batch.load_manifest(manifest)
    assert str(err.value).startswith(f"{manifest}: {message}"), str(err.value)
    result = run(["batch", manifest, "-o", tmp_path / "out"], code)
    assert result.stderr == f"Error: {err.value}\n"
    assert not (tmp_path / "out").exists()


def test_manifest_file_errors(tmp_path):
    run(["batch", tmp_path / "absent.yaml"], 4)
    bad = tmp_path / "bad.yaml"
    bad.write_text("clips:\n  - clip: a.mp4\n    name: [unclosed\n")
    result = run(["batch", bad], 3)
    assert result.stderr.startswith(f"Error: {bad} line ")
    bad.write_text("- just\n- a list\n")
    assert "expected a mapping with 'clips'" in run(["batch", bad], 3).stderr


def test_a_bare_path_entry_takes_everything_from_defaults(inputs, tmp_path):
    manifest = tmp_path / "m.yaml"
    manifest.write_text(yaml.safe_dump({"defaults": {"template": str(inputs / "test.yaml")},
                                        "clips": [str(SAMPLE_DATA / "test.mp4")]}))
    (job,) = batch.load_manifest(manifest).jobs
    assert (job.name, job.template, job.model, job.tracker) == ("test", str(inputs / "test.yaml"), None,
                                                                "condensation")


# ---------------------------------------------------------------------------------------------
# Shell-script behaviour of the other commands


def test_eval_json_gives_known_numbers(tmp_path):
    # truth: a 20x20 box centred on (110, 110) in frames 0-9; frame 10 without the target
    truth = tmp_path / "truth.csv"
    rows = ["frame,object,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,visible"]
    rows += [f"{f},0,110,110,100,100,20,20,1" for f in range(10)] + ["10,0,110,110,100,100,20,20,0"]
    truth.write_text("\n".join(rows) + "\n")
    # predictions: off by (3, 4) px in frames 0-4 (error 5, IoU 272/528), by 30 px in 5-9 (IoU 0)
    pred = tmp_path / "pred.csv"
    rows = ["frame,cx,cy,bbox_x,bbox_y,bbox_w,bbox_h,lost"]
    rows += [f"{f},113,114,103,104,20,20,0" for f in range(5)]
    rows += [f"{f},140,110,130,100,20,20,0" for f in range(5, 11)]
    pred.write_text("\n".join(rows) + "\n")
    result = run(["eval", pred, truth, "--json"], 0)
    assert result.stderr == ""
    (scores,) = json_lines(result.stdout)
    iou = 272 / 528
    assert scores["frames_scored"] == 10 and scores["frames_absent"] == 1
    assert scores["frames_lost"] == 5 and scores["frames_missing"] == 0
    assert scores["precision"] == pytest.approx(0.5)
    assert scores["centre_error_mean"] == pytest.approx(17.5)
    assert scores["centre_error_median"] == pytest.approx(17.5)
    assert scores["centre_error_max"] == pytest.approx(30.0)
    assert scores["mean_iou"] == pytest.approx(iou / 2)
    # IoU 0.515 passes the 11 thresholds 0, 0.05, ..., 0.5 in half the frames
    assert scores["success_auc"] == pytest.approx(0.5 * 11 / 21)


@pytest.mark.parametrize("command", ["track", "learn", "inspect", "eval", "batch"])
def test_result_commands_have_json(command):
    assert "--json" in run([command, "--help"], 0).stdout


def test_track_goes_on_after_a_failing_clip(ellipse_clip, tmp_path):
    template = tmp_path / "t.yaml"
    run(["draw", ellipse_clip, "--ellipse", "70,60,28,36", "-o", template], 0)
    corrupt = tmp_path / "corrupt.avi"
    corrupt.write_bytes(b"not a video" * 100)
    out = tmp_path / "out"
    result = run(["track", corrupt, ellipse_clip, "--template", template, "--tracker", "kalman", "--no-rrd",
                  "-o", out, "--json"], 1)
    failed, summary = json_lines(result.stdout)  # the failed clip has its JSON line too
    assert failed["status"] == "failed" and failed["frames"] is None
    assert summary["status"] == "ok" and summary["frames"] == 6 and Path(summary["csv"]).is_file()
    lines = result.stderr.splitlines()
    assert lines[0].startswith(f"Error: {corrupt}: ") and lines[-1] == "1 of 2 clips failed"
    assert not list(out.glob("corrupt*.csv"))


def test_quiet_batch_prints_nothing_on_stderr(inputs, tmp_path):
    manifest = write_manifest(tmp_path / "m", inputs, [sample_entries(inputs)[2]])
    for args in (["-q", "batch", manifest, "-o", tmp_path / "a"], ["batch", "-q", manifest, "-o", tmp_path / "b"]):
        result = run(args, 0)
        assert result.stderr == ""
        assert result.stdout.splitlines()[0].split() == ["clip", "status", "frames", "fps", "precision", "centre",
                                                         "err", "AUC", "seconds"]


# ---------------------------------------------------------------------------------------------
# The example


def test_example_manifest_is_valid_and_matches_its_script(tmp_path):
    """examples/sample_manifest.yaml loads, and batch_sample.sh makes every file it needs."""
    examples = REPO / "examples"
    script = (examples / "batch_sample.sh").read_text()
    made = set(re.findall(r'-o "\$RUN/([\w.-]+\.yaml)"', script))
    # a copy of the layout it expects: the manifest in examples/, sample_data/ and configs/ beside
    for name in ("sample_data", "configs"):
        (tmp_path / name).symlink_to(REPO / name)
    (tmp_path / "examples" / "sample-run").mkdir(parents=True)
    manifest = tmp_path / "examples" / "sample_manifest.yaml"
    shutil.copy(examples / "sample_manifest.yaml", manifest)
    needed = set()
    for job in yaml.safe_load(manifest.read_text())["clips"]:
        needed.add(Path(job["template"]).name)
    needed.add(Path(yaml.safe_load(manifest.read_text())["defaults"]["model"]).name)
    assert needed <= made, f"the script does not make {sorted(needed - made)}"
    for name in made:
        (tmp_path / "examples" / "sample-run" / name).write_text("stub\n")
    jobs = batch.load_manifest(manifest).jobs
    assert [j.name for j in jobs] == ["train", "test", "three_heads-left", "three_heads-walker", "bouncing_ball"]
    assert all(j.truth is not None for j in jobs)
    assert [j.object_id for j in jobs] == [0, 0, 0, 2, 0]
    assert jobs[-1].model is None and jobs[0].settings.seed == 0


@pytest.mark.parametrize("env, changed", [({"MALLOC_TRIM_THRESHOLD_": "65536"}, True), ({}, False)])
def test_a_dask_workers_allocator_is_restored_only_when_the_trim_threshold_is_set(env, changed):
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_, which switches off glibc's dynamic mmap threshold."""
    import subprocess
    import sys

    import platform

    if not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc":
        pytest.skip("mallopt is glibc's")
    code = "from trackcli.run.batch import _restore_malloc; print(_restore_malloc())"
    base = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
    r = subprocess.run([sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(changed)
