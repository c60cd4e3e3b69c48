#!/usr/bin/env bash
# The whole sample set in one batch: draw templates -> learn head dynamics -> track and score
# every sample clip (examples/sample_manifest.yaml), then read the scores from the JSON lines.
#
# Usage: examples/batch_sample.sh [BATCH OPTIONS]     default: --jobs 2
#   e.g. examples/batch_sample.sh --jobs 1 --force
# Outputs go to examples/sample-run/ (templates, model, batch/ with one folder per clip).
# Set TRACKCLI=/path/to/trackcli to use an installed trackcli instead of the repository's .venv.
# Exit status: that of `trackcli batch` (0 all clips succeeded, 1 some failed, 3/4 bad manifest).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here/.."
if [ -z "${TRACKCLI:-}" ]; then
    . ./setup-venv.sh
    TRACKCLI=.venv/bin/trackcli
fi
T=$TRACKCLI
RUN=examples/sample-run
mkdir -p "$RUN"
[ "$#" -gt 0 ] || set -- --jobs 2

# Results of the preparation steps go to stderr: this script's stdout is the score table.
echo "== templates (boxes segmented by GrabCut; an ellipse for the ball)" >&2
$T draw sample_data/train.mp4 --box 172,91,135,155 -o "$RUN/head-train.yaml" >&2
$T draw sample_data/test.mp4 --box 177,117,110,127 -o "$RUN/head-test.yaml" >&2
$T draw sample_data/three_heads.mp4 --box 37,186,117,133 -o "$RUN/three_heads-left.yaml" >&2
$T draw sample_data/three_heads.mp4 --box 358,186,132,150 -o "$RUN/three_heads-walker.yaml" >&2
$T draw sample_data/bouncing_ball.mp4 --ellipse 40,70,16,16 -o "$RUN/ball.yaml" >&2

echo "== learn: head dynamics from the training clip (settings of configs/sample-clutter.yaml)" >&2
$T -q learn -c configs/sample-clutter.yaml --template "$RUN/head-train.yaml" sample_data/train.mp4 -o "$RUN/head-model.yaml" --no-rrd >&2

echo "== batch: $*" >&2
status=0
$T batch examples/sample_manifest.yaml -o "$RUN/batch" --json "$@" > "$RUN/batch.jsonl" || status=$?

# One JSON object per clip (kind: clip), then one summary (kind: summary).
python3 - "$RUN/batch.jsonl" <<'PY'
import json
import sys

lines = [json.loads(line) for line in open(sys.argv[1]) if line.strip()]
if not lines:
    sys.exit("no results (see the error above)")
clips = [x for x in lines if x["kind"] == "clip"]
summary = next(x for x in lines if x["kind"] == "summary")


def fmt(v, spec):
    return "-" if v is None else format(v, spec)


print(f"{'clip':<20} {'status':<8} {'frames':>6} {'precision':>9} {'AUC':>6} {'error px':>8}")
for c in clips:
    print(f"{c['name']:<20} {c['status']:<8} {fmt(c['frames'], 'd'):>6} {fmt(c['precision'], '.3f'):>9} "
          f"{fmt(c['success_auc'], '.3f'):>6} {fmt(c['centre_error_mean'], '.2f'):>8}")
    if c["error"]:
        print(f"    {c['error']}")
print(f"{summary['ok']} ran, {summary['skipped']} skipped, {summary['failed']} failed in "
      f"{summary['seconds']:.1f} s ({summary['executor']}); mean precision "
      f"{fmt(summary['precision_mean'], '.3f')}, mean success AUC {fmt(summary['success_auc_mean'], '.3f')}")
PY
exit "$status"
