#!/usr/bin/env bash
# The seven-node model against its alternatives, each scored against every
# goal of issue 18 side by side (docs/hust-trials.md, "The committed model against
# its alternatives"):
#
#   committed:        host-tests/hust/params_slot.txt and the model file as
#                     they are: the end winding the sensed spot (30 J/K to
#                     6 kJ/K, one link from 0.1 W/K to both slot nodes), the
#                     end caps' capacity set from their materials (3.4 kJ/K);
#   end cap 2.2 kJ/K, the ends of that materials range;
#   end cap 5.2 kJ/K:
#   end cap fitted:   the end caps' capacity fitted instead, within the
#                     earlier 0.9-9 kJ/K (1-10 kg of aluminium);
#   before:           the model as committed before the spot: the end winding
#                     a copper node (0.3-6 kJ/K, axial links from 2 and
#                     1 W/K, each fitted) and the end cap fitted (0.9-9 kJ/K).
#
# The committed one is read from what reproduce.sh wrote; the others are
# calibrated as reproduce.sh calibrates it, then replayed open loop and with
# endwind_1 fused on every profile. Run reproduce.sh first (it also writes
# the published network's scores and the inverted profile 0 this script
# reads). Writes only under target/hust/variants/.
set -euo pipefail
cd "$(dirname "$0")/../.."
source host-tests/hust/common.sh
VAR=$OUT/variants
MODEL=host-tests/models/hust_motor_slot.toml
PARAMS=host-tests/hust/params_slot.txt
need "$OUT/id_0_raw.csv"
mkdir -p "$VAR"

# The model file with node $1's capacity set to $2 J/K (stdin to stdout).
set_capacity() { sed "/^name = \"$1\"/,/^capacity_j_per_k/ s/^capacity_j_per_k = .*/capacity_j_per_k = $2/"; }
# The model file with the conductance between $1 and $2 set to $3 W/K.
set_link() { sed "/^between = \[\"$1\", \"$2\"\]/{n;s/^g_w_per_k = .*/g_w_per_k = $3/;}"; }

set_capacity endcap 2200.0 < "$MODEL" > "$VAR/endcap_2.2.toml"
set_capacity endcap 5200.0 < "$MODEL" > "$VAR/endcap_5.2.toml"
cp "$PARAMS" "$VAR/params_endcap_2.2.txt"
cp "$PARAMS" "$VAR/params_endcap_5.2.txt"
cp "$MODEL" "$VAR/endcap_fitted.toml"
{ cat "$PARAMS"; echo "capacity.endcap=900:9000"; } > "$VAR/params_endcap_fitted.txt"
# Before: the first guesses and bounds of the copper-node end winding.
set_capacity end_winding 1700.0 < "$MODEL" | set_capacity endcap 3000.0 |
  set_link active_winding end_winding 12.0 | set_link slot_centre end_winding 5.0 > "$VAR/before.toml"
sed -e 's/^capacity.end_winding=.*/capacity.end_winding=300:6000/' \
  -e 's/^conductance.active_winding-end_winding|.*/conductance.active_winding-end_winding=2:60\
conductance.slot_centre-end_winding=1:60/' "$PARAMS" > "$VAR/params_before.txt"
echo "capacity.endcap=900:9000" >> "$VAR/params_before.txt"

join() { local IFS=';'; echo "${*:-none}" | sed 's/;/; /g'; }

# Calibrates variant $1 (model $VAR/$1.toml, bounds $VAR/params_$1.txt) as
# reproduce.sh calibrates the committed model and replays it open loop and
# fused on every profile, into $VAR/$1*.
calibrate_and_replay() {
  local v=$1 n
  # shellcheck disable=SC2086 # the profile lists split into words
  calibrate_seven "$VAR/$v.toml" "$VAR/params_$v.txt" "$VAR/${v}_fitted.toml" $FIT_PROFILES
  for n in $FIT_PROFILES $HELD_OUT; do
    replay_seven "$VAR/${v}_fitted.toml" "$n" "$VAR/${v}_open_$n" "$VAR/${v}_fused_$n"
  done
}

# One row of the table: variant $1, its calibration log $2, and its replays
# $3_open_N.json and $3_fused_N.json.
row() {
  local v=$1 log=$2 runs=$3 n s bounds nb open_lost=() fused_over=() sum1=0 sum2=0 rmse
  bounds=$(grep -o '^[a-z_.|0-9-]* .*AT \(LOWER\|UPPER\) BOUND' "$log" | awk '{print $1}' | sed 's/^conductance\.//; s/^capacity\./C /; s/|conductance\./ and /g' | paste -sd';' - | sed 's/;/; /g')
  nb=$(grep -c 'AT \(LOWER\|UPPER\) BOUND' "$log" || true)
  # The fit's cost: the fit profiles' squared RMSEs (each weighs the same).
  rmse=$(awk '/^[^ ].*\.csv  / { s += $(NF - 1) ^ 2 } END { printf "%.2f", s }' "$log")
  for n in $FIT_PROFILES $HELD_OUT; do
    need "$OUT/published_$n.json"
    for s in 0 1; do
      local pub open mse max name
      pub=$(field "$OUT/published_$n.json" mse_k2 "$s")
      open=$(field "${runs}_open_$n.json" mse_k2 "$s")
      mse=$(field "${runs}_fused_$n.json" mse_k2 "$s")
      max=$(field "${runs}_fused_$n.json" max_abs_error_k "$s")
      name="$n aw$((s + 1))"
      if awk -v a="$open" -v b="$pub" 'BEGIN { exit !(a >= b) }'; then
        open_lost+=("$name $(awk -v a="$open" -v b="$pub" 'BEGIN { printf "%.2f vs %.2f", a, b }')")
      fi
      if awk -v m="$mse" -v x="$max" 'BEGIN { exit !(m > 1 || x > 3) }'; then
        fused_over+=("$name $(awk -v m="$mse" -v x="$max" 'BEGIN { printf "%.2f / %.2f", m, x }')")
      fi
      case " $HELD_OUT " in *" $n "*)
        if [ "$s" = 0 ]; then sum1=$(awk -v a="$sum1" -v b="$mse" 'BEGIN { print a + b }')
        else sum2=$(awk -v a="$sum2" -v b="$mse" 'BEGIN { print a + b }'); fi ;;
      esac
    done
  done
  # The calibration's own time, from the first line of its log.
  printf "| %s | %s: %s | %s | %s | %s | %.2f / %.2f | %s |\n" "$v" "$nb" "$bounds" "$rmse" \
    "$(join "${open_lost[@]}")" "$(join "${fused_over[@]}")" "$sum1" "$sum2" \
    "$(head -1 "$log" | grep -o '[0-9.]* s (' | cut -d' ' -f1)"
}

echo "| variant | fitted parameters at a bound | fit cost, sum of squared RMSEs [K^2] | open loop not better than published | fused over 1 K^2 or 3 K | held-out fused MSE sum, activewind_1 / activewind_2 [K^2] | calibration [s] |"
echo "|---|---|---|---|---|---|---|"
# The committed model as reproduce.sh calibrated and replayed it.
need "$OUT/hust_motor_slot_fitted.txt"
row committed "$OUT/hust_motor_slot_fitted.txt" "$OUT/seven"
for v in endcap_2.2 endcap_5.2 endcap_fitted before; do
  calibrate_and_replay "$v"
  row "$v" "$VAR/${v}_fitted.txt" "$VAR/$v"
done
