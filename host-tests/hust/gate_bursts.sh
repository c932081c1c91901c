#!/usr/bin/env bash
# Where the seven-node fused filter's gate refuses `endwind_1` readings, and
# what the other thermocouples do there (docs/hust.md, "The gate at load
# steps"). Reads the replays `reproduce.sh` wrote (target/hust/seven_fused_N.json,
# their `rejected_at_s`) and the traces; run reproduce.sh first.
#
# Rejections less than 4 s apart form one burst. For each burst starting at
# row a (the trace is sampled every second, so row = second):
#   transition: the speed moves by more than 300 rpm or the current by more
#     than 80 A within rows a-10..a+5;
#   jump of a column: mean of rows a+3..a+5 minus mean of rows a-6..a-4 [K];
#   channel: outer_yoke and endcap jump by more than 0.25 and 0.2 K, both the
#     way endwind_1 jumps. The yoke (1.6 kJ/K fitted) and the end cap
#     (9 kJ/K) cannot move that far in 6-9 s on their own heat (0.25 K of
#     yoke alone is 60 W net for 6 s, 0.2 K of end cap 300 W) and the water
#     outlet, read by another instrument, does not move: the thermocouple
#     channel shifted, not the motor.
# The last column is the control: the share of all rows (every 5th, 10 s
# from either end) that meet the channel test, bursts or not.
set -euo pipefail
cd "$(dirname "$0")/../.."
DIR="${COIL_THERMAL_HUST_DIR:-../shared/data/hust-ipmsm}"
OUT=target/hust
echo "| profile | rejected readings | bursts | at a speed or load step | with yoke and end cap jumping alike (channel) | of those, at a step | channel test at any row |"
echo "|---|---|---|---|---|---|---|"
for n in 0 1 3 5 9 11 2 4 8 10 12 13; do
  json="$OUT/seven_fused_$n.json"
  if [ ! -f "$json" ]; then
    echo "no $json: run host-tests/hust/reproduce.sh first" >&2
    exit 1
  fi
  trace="$DIR/id_$n.csv"
  [ "$n" = 0 ] && trace="$OUT/id_0_raw.csv"
  times=$(grep -o '"rejected_at_s":\[[^]]*\]' "$json" | sed 's/.*\[//; s/\]//')
  awk -F, -v n="$n" -v times="$times" '
    NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
    {
      k = NR - 2
      sp[k] = $col["speed"]; cur[k] = sqrt($col["IdFbk"]^2 + $col["IqFbk"]^2)
      ew[k] = $col["endwind_1"]; yk[k] = $col["outer_yoke"]; ec[k] = $col["endcap"]
      rows = k + 1
    }
    function jump(a, x,   j, after, before) {
      after = 0; before = 0
      for (j = a + 3; j <= a + 5; j++) after += x[(j < rows) ? j : rows - 1]
      for (j = a - 6; j <= a - 4; j++) before += x[(j > 0) ? j : 0]
      return (after - before) / 3
    }
    function range(a, x,   j, lo, hi) {
      lo = 1e9; hi = -1e9
      for (j = a - 10; j <= a + 5; j++) if (j >= 0 && j < rows) { if (x[j] < lo) lo = x[j]; if (x[j] > hi) hi = x[j] }
      return hi - lo
    }
    function shifted(a,   e, y, c) {
      e = jump(a, ew); y = jump(a, yk); c = jump(a, ec)
      return (y > 0.25 && c > 0.2 && e > 0) || (y < -0.25 && c < -0.2 && e < 0)
    }
    function burst(a,   step) {
      bursts++
      step = range(a, sp) > 300 || range(a, cur) > 80
      steps += step
      if (shifted(a)) { channel++; channel_steps += step }
    }
    END {
      m = split(times, t, ",")
      rejected = (times == "") ? 0 : m
      last = -100
      for (i = 1; i <= rejected; i++) {
        r = int(t[i] + 0.5)
        if (r - last >= 4) burst(r)
        last = r
      }
      for (a = 10; a < rows - 10; a += 5) { tried++; base += shifted(a) }
      printf "| %s | %d | %d | %d | %d | %d | %.1f %% |\n", n, rejected, bursts, steps, channel, channel_steps, 100 * base / tried
    }' "$trace"
done
