#!/usr/bin/env bash
# The bouncing-ball experiment of Blake et al. 1998 (§8, Fig 16): one AR(2) model of free
# flight against a mixed-state model with a bounce event, on any clip of a ball bouncing on a
# horizontal floor.
#
# Usage: examples/bouncing_ball.sh CLIP X,Y,W,H FLOOR_Y [OUTDIR]
#   CLIP     the video (or image folder)
#   X,Y,W,H  a box around the ball on frame 0 (its outline is segmented inside it)
#   FLOOR_Y  the image row of the floor the ball bounces on (px, counted from the top)
#   OUTDIR   where everything goes (default runs/bouncing_ball)
#
# Writes OUTDIR/ball.yaml (the template), OUTDIR/ball.mixed.yaml (the model with this floor),
# OUTDIR/single/NAME.condensation.csv (single model) and OUTDIR/mixed/NAME.condensation.csv
# (mixed state, with columns p_flight and p_bounce), each with its .rrd.  When the clip has
# ground truth beside it (CLIP without its extension + .truth.csv), also scores both tracks
# around the bounces and draws OUTDIR/bounces.png.
# Example: examples/bouncing_ball.sh sample_data/bouncing_ball.mp4 22,52,36,36 318
set -euo pipefail
if [ $# -lt 3 ] || [ $# -gt 4 ]; then
    sed -n '6,10p' "$0" >&2
    exit 2
fi
CLIP=$1 BOX=$2 FLOOR=$3 OUT=${4:-runs/bouncing_ball}
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(dirname "$HERE")
if ! [[ $FLOOR =~ ^[0-9]+([.][0-9]+)?$ ]]; then
    echo "error: FLOOR_Y must be a number of pixels, got '$FLOOR'" >&2
    exit 2
fi
(cd "$ROOT" && . ./setup-venv.sh)
T="$ROOT/.venv/bin/trackcli" PY="$ROOT/.venv/bin/python"
mkdir -p "$OUT"
NAME=$(basename "${CLIP%/}"); NAME=${NAME%.*}

echo "== draw: the ball's template from the frame-0 box"
$T draw "$CLIP" --box "$BOX" -o "$OUT/ball.yaml"

echo "== the two-label model for the floor at y = $FLOOR"
sed -E "s/^( *bounce: \{base: flight, floor: )[0-9.]+/\1$FLOOR/" "$HERE/bouncing_ball.mixed.yaml" > "$OUT/ball.mixed.yaml"
grep -q "floor: $FLOOR," "$OUT/ball.mixed.yaml" || { echo "error: could not set the floor in $OUT/ball.mixed.yaml" >&2; exit 1; }
$T inspect "$OUT/ball.mixed.yaml" --template "$OUT/ball.yaml"

echo "== track: the single flight model, then the mixed-state model (both without the jump mixture)"
$T track -c "$HERE/bouncing_ball.flight.yaml" --template "$OUT/ball.yaml" "$CLIP" -o "$OUT/single" --seed 0
$T track -c "$HERE/bouncing_ball.settings.yaml" --model "$OUT/ball.mixed.yaml" --template "$OUT/ball.yaml" "$CLIP" \
    -o "$OUT/mixed" --seed 0

TRUTH="${CLIP%.*}.truth.csv"
if [ -f "$TRUTH" ]; then
    echo "== score against $TRUTH (frames within 3 of a bounce)"
    $PY - "$OUT/single/$NAME.condensation.csv" "$OUT/mixed/$NAME.condensation.csv" "$TRUTH" "$OUT/bounces.png" <<'PY'
import sys
from trackcli.run.bounces import run_experiment
e = run_experiment(sys.argv[1], sys.argv[2], sys.argv[3], png=sys.argv[4])
print("\n".join(e.lines()))
print(f"wrote {sys.argv[4]}")
PY
fi
echo "CSVs: $OUT/single/$NAME.condensation.csv and $OUT/mixed/$NAME.condensation.csv"
