#!/usr/bin/env bash
# Reproduces the HUST results of README "Real data: the HUST motor":
# calibrates host-tests/models/hust_motor.toml on the fit profiles, then
# scores the published baseline, the calibrated model open loop, and the
# calibrated model with endwind_1 fused by the Kalman filter, on every
# profile. Reads the data from ${COIL_THERMAL_HUST_DIR:-../shared/data/hust-ipmsm}
# (relative to the repository root); writes only under target/hust/.
set -euo pipefail
cd "$(dirname "$0")/../.."
DIR="${COIL_THERMAL_HUST_DIR:-../shared/data/hust-ipmsm}"
OUT=target/hust
CT=target/release/coil-thermal
FIT_PROFILES="1 3 5 9 11"
SCORE_PROFILES="2 4 8 10 12 13"
# Profile 0's temperatures are EMA-smoothed (see the data README): it is
# replayed for information only, neither fitted nor scored.
INFO_PROFILES="0"

if [ ! -f "$DIR/id_1.csv" ]; then
  echo "no HUST data in $DIR: set COIL_THERMAL_HUST_DIR" >&2
  exit 1
fi
mkdir -p "$OUT"
cargo build --release -q -p coil-thermal-host

# The calibration: every parameter with physical bounds, listed in params.txt.
PARAMS=$(grep -v '^#' host-tests/hust/params.txt | paste -sd, -)
TRACES=()
for n in $FIT_PROFILES; do TRACES+=(--trace "$DIR/id_$n.csv"); done
start=$(date +%s.%N)
"$CT" calibrate --model host-tests/models/hust_motor.toml "${TRACES[@]}" \
  --sample-period-s 1 \
  --measure activewind_1=active_winding --measure endwind_1=end_winding \
  --measure outer_yoke=stator_yoke --measure rotor=rotor --measure endcap=endcap \
  --params "$PARAMS" --stride 10 --max-iterations 60 --no-progress \
  --out "$OUT/hust_motor_fitted.toml" > "$OUT/calibrate.txt"
end=$(date +%s.%N)
head -1 "$OUT/calibrate.txt"
calib_s=$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }')
echo "calibration wall-clock time: ${calib_s} s (full log: $OUT/calibrate.txt)"
if cmp -s "$OUT/hust_motor_fitted.toml" host-tests/models/hust_motor_fitted.toml; then
  echo "fitted model identical to host-tests/models/hust_motor_fitted.toml"
else
  echo "NOTE: fitted model differs from host-tests/models/hust_motor_fitted.toml"
fi

# First MSE and max error of truth sensor number $2 (0-based) in JSON $1.
field() { grep -o "\"$2\":[-0-9.eE+]*" "$1" | sed -n "$(($3 + 1))p" | cut -d: -f2; }
fmt() { awk -v v="$1" 'BEGIN { printf "%.2f", v }'; }

FUSE=(--measure endwind_1=end_winding --disturbance active_winding,end_winding)
row() {
  local n=$1 tag=$2
  local t="$DIR/id_$n.csv"
  "$CT" replay --model host-tests/models/hust-ipmsm-3node.toml --trace "$t" --sample-period-s 1 \
    --truth activewind_1=winding --truth activewind_2=winding \
    --out "$OUT/baseline_$n.csv" --json > "$OUT/baseline_$n.json"
  "$CT" replay --model "$OUT/hust_motor_fitted.toml" --trace "$t" --sample-period-s 1 \
    --truth activewind_1=active_winding --truth activewind_2=active_winding \
    --out "$OUT/open_loop_$n.csv" --json > "$OUT/open_loop_$n.json"
  "$CT" replay --model "$OUT/hust_motor_fitted.toml" --trace "$t" --sample-period-s 1 \
    --truth activewind_1=active_winding --truth activewind_2=active_winding "${FUSE[@]}" \
    --out "$OUT/fused_$n.csv" --json > "$OUT/fused_$n.json"
  for s in 0 1; do
    local line="| $n | $tag | activewind_$((s + 1))"
    for e in baseline open_loop fused; do
      line="$line | $(fmt "$(field "$OUT/${e}_$n.json" mse_k2 "$s")") / $(fmt "$(field "$OUT/${e}_$n.json" max_abs_error_k "$s")")"
    done
    echo "$line |"
  done
}

echo
echo "MSE [K^2] / max error [K] of the active-winding sensors"
echo
echo "| profile | role | sensor | baseline (published, open loop) | calibrated, open loop | calibrated + endwind_1 fused |"
echo "|---|---|---|---|---|---|"
for n in $FIT_PROFILES; do row "$n" fit; done
for n in $SCORE_PROFILES; do row "$n" scored; done
for n in $INFO_PROFILES; do row "$n" "smoothed, info"; done
echo
echo "calibration runtime: ${calib_s} s"
