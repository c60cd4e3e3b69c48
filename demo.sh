#!/usr/bin/env bash
# The whole pipeline on the bundled sample data: draw -> learn -> track -> eval.
# Usage: ./demo.sh [OUTDIR]   (default runs/demo). Creates ./.venv on first use.
set -euo pipefail
cd "$(dirname "$0")"
. ./setup-venv.sh
OUT=${1:-runs/demo}
T=.venv/bin/trackcli
C=configs/sample-clutter.yaml      # settings for the sample clips, each one explained in the file
mkdir -p "$OUT"

echo "== 1/5 draw: a template on frame 0 of the training clip (box segmented by GrabCut)"
$T draw sample_data/train.mp4 --box 172,91,135,155 -o "$OUT/head.yaml" --rrd "$OUT/head.rrd"

echo "== 2/5 learn: Kalman-track the clean training clip, learn AR(2) dynamics by maximum likelihood"
$T learn -c $C --template "$OUT/head.yaml" sample_data/train.mp4 -o "$OUT/head-model.yaml"
$T inspect "$OUT/head-model.yaml"
$T simulate "$OUT/head-model.yaml" --frames 250 --paths 3 --seed 0 -o "$OUT/head-model_sim.rrd"

echo "== 3/5 track: the cluttered test clip with CONDENSATION and, for comparison, Kalman (same model)"
$T draw sample_data/test.mp4 --box 177,117,110,127 -o "$OUT/head-test.yaml"
$T track -c $C --model "$OUT/head-model.yaml" --template "$OUT/head-test.yaml" sample_data/test.mp4 -o "$OUT" --seed 0
$T track -c $C --tracker kalman --model "$OUT/head-model.yaml" --template "$OUT/head-test.yaml" sample_data/test.mp4 -o "$OUT"
echo "-- and with the defaults alone: no model, no config, the template drawn on this clip"
$T track --template "$OUT/head-test.yaml" sample_data/test.mp4 -o "$OUT/defaults" --seed 0

echo "== 4/5 eval: both against the ground truth (lost = centroid more than 8 px off)"
echo "-- CONDENSATION"; $T eval "$OUT/test.condensation.csv" sample_data/test.truth.csv --lost-threshold 8
echo "-- Kalman";        $T eval "$OUT/test.kalman.csv" sample_data/test.truth.csv --lost-threshold 8
echo "-- CONDENSATION with the defaults"; $T eval "$OUT/defaults/test.condensation.csv" sample_data/test.truth.csv --lost-threshold 8
echo "-- both, as precision and success plots; and a contact sheet of the CONDENSATION track"
$T eval "$OUT/test.condensation.csv" "$OUT/test.kalman.csv" sample_data/test.truth.csv --plot "$OUT/test.plots.png" > /dev/null
$T render "$OUT/test.condensation.csv" sample_data/test.mp4 --sheet 8 --tile-width 200 \
    --truth sample_data/test.truth.csv -o "$OUT/test.condensation.sheet.png"

echo "== 5/5 multi-modal: three similar heads; the translation histogram keeps a peak at each"
echo "   (the template comes from the training clip and the samples start spread over the whole frame;"
echo "   the estimate, their weighted mean, lies between the people: the warning about the template"
echo "   on frame 0 and the frames reported lost are expected here)"
$T track -c configs/three-heads.yaml --template "$OUT/head.yaml" sample_data/three_heads.mp4 -o "$OUT" --seed 0

echo
echo "Recordings (open one with 'trackcli view $OUT/test.condensation.rrd'):"
ls -1 "$OUT"/*.rrd "$OUT"/head-model_training/*.rrd
echo "Estimates (CSV): $OUT/*.csv; pictures: $OUT/test.plots.png, $OUT/test.condensation.sheet.png"
