#!/usr/bin/env bash
# The whole pipeline on the bundled sample data: draw -> learn -> track -> eval.
# Usage: ./demo.sh [OUTDIR]   (default runs/demo). Creates ./.venv on first use.
set -euo pipefail
cd "$(dirname "$0")"
. ./setup-venv.sh
OUT=${1:-runs/demo}
T=.venv/bin/trackcli
mkdir -p "$OUT"

echo "== 1/4 draw: a template on frame 0 of the training clip (box segmented by GrabCut)"
$T draw sample_data/train.mp4 --box 172,91,135,155 -o "$OUT/head.yaml" --rrd "$OUT/head.rrd"

echo "== 2/4 learn: Kalman-track the training clip, learn AR(2) dynamics, 2 track-learn cycles"
$T learn --template "$OUT/head.yaml" sample_data/train.mp4 -o "$OUT/head-model.yaml" --cycles 2
$T inspect "$OUT/head-model.yaml"
$T simulate "$OUT/head-model.yaml" --frames 250 --paths 3 --seed 0 -o "$OUT/head-model_sim.rrd"

echo "== 3/4 track: the cluttered test clip, with CONDENSATION and (for comparison) Kalman"
$T draw sample_data/test.mp4 --box 166,104,131,153 -o "$OUT/head-test.yaml"
$T track --model "$OUT/head-model.yaml" --template "$OUT/head-test.yaml" sample_data/test.mp4 -o "$OUT" --seed 0
$T track --tracker kalman --model "$OUT/head-model.yaml" --template "$OUT/head-test.yaml" sample_data/test.mp4 -o "$OUT"

echo "== 4/4 eval: both against the ground truth"
echo "-- CONDENSATION"; $T eval "$OUT/test.condensation.csv" sample_data/test.truth.csv
echo "-- Kalman";        $T eval "$OUT/test.kalman.csv" sample_data/test.truth.csv

echo
echo "Recordings (open with the Rerun viewer, e.g. 'rerun $OUT/test.condensation.rrd'):"
ls -1 "$OUT"/*.rrd "$OUT"/head-model_training/*.rrd
