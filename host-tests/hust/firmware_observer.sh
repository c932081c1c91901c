#!/usr/bin/env bash
# The firmware's observer on the real motor (docs/hust.md, "The
# firmware's observer"): the committed seven-node model with endwind_1
# fused by the library's NetworkObserver, the firmware's packaged observer
# (steady gain, f32, 1 ms ticks, one heat bias: the model file's
# `[observer] bias_sources`, the copper's on the active winding, at the
# library's default bias noise), not the row-rate Kalman filter of the
# table. Scored like the table, with the sensor noise the table's filter
# declares (0.2 K, the floor of the noise it learns) and the model file's
# `[observer] sensor_sigma_k` (0.5 K, about profile 0's scatter, what the
# row-rate filter learns there, and what `codegen` flashes): the
# firmware's observer has one fixed noise and does not learn it.
#
# Run reproduce.sh first (it writes the inverted profile 0). Writes only
# under target/hust/firmware/.
set -euo pipefail
cd "$(dirname "$0")/../.."
source host-tests/hust/common.sh
F=$OUT/firmware
need "$OUT/id_0_raw.csv"
mkdir -p "$F"
MODEL=host-tests/models/hust_motor_slot_fitted.toml

echo "| profile | sensor | noise 0.2 K: MSE [K^2] / max [K] | noise 0.5 K |"
echo "|---|---|---|---|"
for p in $FIT_PROFILES $HELD_OUT; do
  for noise in 0.2 0.5; do
    replay_seven_with "$MODEL" "$p" "$F/${noise}_$p" --measure endwind_1=end_winding \
      --measurement-noise-k "$noise"
  done
  for s in 0 1; do
    line="| $p | activewind_$((s + 1))"
    for noise in 0.2 0.5; do
      line="$line | $(awk -v m="$(field "$F/${noise}_$p.json" mse_k2 "$s")" \
        -v x="$(field "$F/${noise}_$p.json" max_abs_error_k "$s")" \
        'BEGIN { printf "%.2f / %.2f%s", m, x, (m > 1 || x > 3) ? " (beyond)" : "" }')"
    done
    echo "$line |"
  done
done
