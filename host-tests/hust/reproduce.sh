#!/usr/bin/env bash
# Reproduces the HUST results of README ("The real motor") and docs/hust.md: calibrates the two models
# (host-tests/models/hust_motor.toml, six nodes, and hust_motor_slot.toml,
# seven nodes with the slot centre and the end winding's sensed spot, the
# winding one conductor with the electrical copper loss shared by capacity,
# the AC copper loss in the slots only, and the end caps' capacity set
# from their materials), then scores on every profile the authors' full published
# network (hust-published.toml), each calibrated model open loop, and the
# seven-node one with endwind_1 fused by the flashed observer (the
# library's NetworkObserver as `codegen` builds it from the model file's
# `[observer]` table); last, the fused scores against the readings with
# the thermocouple channel's shifts taken out (channel_shifts.sh), the
# committed seven-node model against its alternatives (variants.sh), each
# fit profile left out of the fit in turn (cross_validation.sh), and the
# flashed observer beside variants of its settings (firmware_observer.sh).
# Every run starts every node that has a sensor at its first reading.
# Reads the data from ${COIL_THERMAL_HUST_DIR:-../shared/data/hust-ipmsm}
# (relative to the repository root); writes only under target/hust/.
set -euo pipefail
cd "$(dirname "$0")/../.."
source host-tests/hust/common.sh

if [ ! -f "$DIR/id_1.csv" ]; then
  echo "no HUST data in $DIR: set COIL_THERMAL_HUST_DIR" >&2
  exit 1
fi
mkdir -p "$OUT"
cargo build --release -q -p coil-thermal-host

# Profile 0's temperatures are EMA-smoothed (data README): invert it once.
awk -F, -f host-tests/hust/invert_ema.awk "$DIR/id_0.csv" > "$OUT/id_0_raw.csv"
# Every node without a fitted sensor starts at a measured value too
# (INIT6, INIT7 in common.sh).

# Runs calibration command $2... and prints the first line of its log $1
# and the wall-clock time it took.
timed() {
  local log=$1 start end
  shift
  start=$(date +%s.%N)
  "$@"
  end=$(date +%s.%N)
  head -1 "$log"
  echo "wall-clock: $(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }') s (log: $log)"
}

# The six-node model as before (calibrate_hust in common.sh): fit 1 3 5 9
# 11, no --init (reproduces the committed file), the default weighting, 60
# iterations. The seven-node one (calibrate_seven) fits 0 1 3 5 9 11,
# standstill and low speed included, every profile weighing the same (the
# short low-speed profile 1 is not drowned by the long high-speed ones),
# run to convergence.
timed "$OUT/hust_motor_fitted.txt" calibrate_hust host-tests/models/hust_motor.toml \
  host-tests/hust/params.txt "$OUT/hust_motor_fitted.toml" "1 3 5 9 11" --max-iterations 60
# shellcheck disable=SC2086 # the profile list splits into words
timed "$OUT/hust_motor_slot_fitted.txt" calibrate_seven host-tests/models/hust_motor_slot.toml \
  host-tests/hust/params_slot.txt "$OUT/hust_motor_slot_fitted.toml" $FIT_PROFILES
# The numbers of a model file, in order (comments and layout aside).
numbers() { sed 's/#.*//' "$1" | grep -oE '[-+]?[0-9]+(\.[0-9]+)?([eE][-+]?[0-9]+)?'; }
for m in hust_motor_fitted hust_motor_slot_fitted; do
  # The committed file carries hand-written comments on its bounds and an
  # older layout: compare the numbers, to 1e-6 relative (as the opt-in test
  # `calibration_reproduces_the_committed_fitted_model` does).
  if paste <(numbers "host-tests/models/$m.toml") <(numbers "$OUT/$m.toml") | awk '
      NF != 2 { bad = 1 }
      { d = $1 - $2; s = ($1 < 0 ? -$1 : $1) + ($2 < 0 ? -$2 : $2); if ((d < 0 ? -d : d) > 1e-6 * s) bad = 1 }
      END { exit bad }'; then
    echo "$m: the same numbers as host-tests/models/$m.toml (to 1e-6)"
  else
    echo "NOTE: $m differs from host-tests/models/$m.toml"
  fi
done

fmt() { awk -v v="$1" 'BEGIN { printf "%.2f", v }'; }

row() {
  local n=$1 tag=$2 t
  t=$(trace "$n")
  "$CT" replay --model host-tests/models/hust-published.toml --trace "$t" --sample-period-s 1 \
    --init 'mean(activewind_1,activewind_2)=winding' --init 'mean(slotbottom,outer_yoke)=stator' \
    --init rotor=rotor --truth activewind_1=winding --truth activewind_2=winding \
    --out "$OUT/published_$n.csv" --json > "$OUT/published_$n.json"
  "$CT" replay --model "$OUT/hust_motor_fitted.toml" --trace "$t" --sample-period-s 1 \
    --truth activewind_1=active_winding --truth activewind_2=active_winding "${INIT6[@]}" \
    --out "$OUT/six_open_$n.csv" --json > "$OUT/six_open_$n.json"
  replay_seven "$OUT/hust_motor_slot_fitted.toml" "$n" "$OUT/seven_open_$n" "$OUT/seven_fused_$n" csv
  for s in 0 1; do
    local line="| $n | $tag | activewind_$((s + 1))"
    for e in published six_open seven_open seven_fused; do
      line="$line | $(fmt "$(field "$OUT/${e}_$n.json" mse_k2 "$s")") / $(fmt "$(field "$OUT/${e}_$n.json" max_abs_error_k "$s")")"
    done
    echo "$line |"
  done
}

echo
echo "MSE [K^2] / max error [K] of the active-winding sensors"
echo
echo "| profile | role | sensor | published (full, open loop) | 6-node open loop | 7-node open loop | 7-node, flashed observer, endwind_1 fused |"
echo "|---|---|---|---|---|---|---|"
row 0 "fit (7-node; inverted EMA)"
for n in 1 3 5 9 11; do row "$n" fit; done
for n in $HELD_OUT; do row "$n" scored; done

# The fused estimates against the readings with the channel's shifts taken
# out, and what the thermocouples do at starts, stops and rest
# (docs/hust-trials.md, "The thermocouple channel's shifts").
echo
host-tests/hust/channel_shifts.sh

# The committed seven-node model against its alternatives, each against
# every goal of issue 18 (docs/hust-trials.md, "The committed model against its
# alternatives").
echo
host-tests/hust/variants.sh

# Each fit profile left out of the fit in turn and scored like a held-out
# one (docs/hust-trials.md, "Leave one out").
echo
host-tests/hust/cross_validation.sh

# The flashed observer beside variants of its settings
# (docs/hust-trials.md, "The firmware's observer").
echo
host-tests/hust/firmware_observer.sh
