#!/usr/bin/env bash
# The seven-node fused estimates scored against the active-winding
# thermocouples as recorded and against the same readings with their
# channel's fast common-mode shift taken out (docs/hust.md, "The
# thermocouple channel's shifts"). Reads the replays `reproduce.sh` wrote
# (target/hust/seven_fused_N.csv) and the traces; run reproduce.sh first.
#
# The shift at row k is the mean, over `outer_yoke` and `endcap`, of each
# reading's departure from its own 61-row centred mean (30 rows either
# side, fewer at the ends). Those two thermocouples sit on 1.6 and 9 kJ/K
# of iron and aluminium that move by tenths of a kelvin a minute on their
# own heat, so their departures from a one-minute mean are the channel's
# (the water outlet, another instrument, does not share them). The
# corrected reference of an active-winding sensor is its reading minus
# that shift. This is a reading of the instrument, not of the motor: the
# goals in docs/hust.md are scored against the readings as recorded.
set -euo pipefail
cd "$(dirname "$0")/../.."
DIR="${COIL_THERMAL_HUST_DIR:-../shared/data/hust-ipmsm}"
OUT=target/hust
echo "| profile | sensor | as recorded: MSE [K^2] / max [K] | shift taken out: MSE [K^2] / max [K] |"
echo "|---|---|---|---|"
for n in 0 1 3 5 9 11 2 4 8 10 12 13; do
  est="$OUT/seven_fused_$n.csv"
  if [ ! -f "$est" ]; then
    echo "no $est: run host-tests/hust/reproduce.sh first" >&2
    exit 1
  fi
  trace="$DIR/id_$n.csv"
  [ "$n" = 0 ] && trace="$OUT/id_0_raw.csv"
  awk -F, -v n="$n" -v h=30 '
    FNR == 1 { for (i = 1; i <= NF; i++) col[FILENAME, $i] = i; next }
    FILENAME == ARGV[1] {
      k = FNR - 2; rows = k + 1
      aw1[k] = $col[FILENAME, "activewind_1"]; aw2[k] = $col[FILENAME, "activewind_2"]
      yk[k] = $col[FILENAME, "outer_yoke"]; ec[k] = $col[FILENAME, "endcap"]
      next
    }
    { k = FNR - 2; e1[k] = $col[FILENAME, "active_winding"]; e2[k] = $col[FILENAME, "slot_centre"] }
    END {
      for (k = 0; k < rows; k++) { py[k + 1] = py[k] + yk[k]; pe[k + 1] = pe[k] + ec[k] }
      for (k = 0; k < rows; k++) {
        a = (k - h < 0) ? 0 : k - h; b = (k + h + 1 > rows) ? rows : k + h + 1
        shift[k] = ((yk[k] - (py[b] - py[a]) / (b - a)) + (ec[k] - (pe[b] - pe[a]) / (b - a))) / 2
      }
      # Row 0 is the initial state (every node starts at its reading).
      for (s = 1; s <= 2; s++) {
        m = 0; x = 0; mc = 0; xc = 0
        for (k = 1; k < rows; k++) {
          t = (s == 1) ? aw1[k] : aw2[k]; e = (s == 1) ? e1[k] : e2[k]
          d = e - t; dc = e - (t - shift[k])
          m += d * d; mc += dc * dc
          if (d * d > x * x) x = d; if (dc * dc > xc * xc) xc = dc
        }
        printf "| %s | activewind_%d | %.2f / %.2f | %.2f / %.2f |\n", n, s, m / (rows - 1), (x < 0 ? -x : x), mc / (rows - 1), (xc < 0 ? -xc : xc)
      }
    }' "$trace" "$est"
done
