# Sourced by the HUST scripts (reproduce.sh and the analyses it runs): where
# the data and outputs are, and the seven-node model's start states, fit
# and filter options, so that every script calibrates and replays it alike.
# Run from the repository root.
DIR="${COIL_THERMAL_HUST_DIR:-../shared/data/hust-ipmsm}"
OUT=target/hust
CT=target/release/coil-thermal
FIT_PROFILES="0 1 3 5 9 11"
HELD_OUT="2 4 8 10 12 13"

# The trace of profile $1 (profile 0 EMA-inverted by reproduce.sh).
trace() { if [ "$1" = 0 ]; then echo "$OUT/id_0_raw.csv"; else echo "$DIR/id_$1.csv"; fi; }
need() { [ -f "$1" ] || { echo "no $1: run host-tests/hust/reproduce.sh first" >&2; exit 1; }; }
# MSE and max error of truth sensor number $3 (0-based) in JSON $1 ($2 the field).
field() { grep -o "\"$2\":[-0-9.eE+]*" "$1" | sed -n "$(($3 + 1))p" | cut -d: -f2; }

# Nodes without a fitted sensor start at a measured value too: the teeth at
# the authors' stator reading (mean of slot bottom and outer yoke).
INIT6=(--init endwind_1=end_winding --init 'mean(slotbottom,outer_yoke)=stator_teeth'
  --init outer_yoke=stator_yoke --init rotor=rotor --init endcap=endcap)
INIT7=("${INIT6[@]}" --init activewind_2=slot_centre)
# The seven-node filter: endwind_1 fused, one disturbance per loss
# mechanism the model may have wrong: over the copper (at one density, as
# the copper loss), and over the stator iron (teeth and yoke; the model's
# iron losses follow the speed only, while a loaded machine's grow with
# the current too, as the authors' 1151 i f W term of rest losses does).
# Their noise is the same on every profile (not the replay default, which
# scales the disturbance with each trace's peak power). Every node starts
# at a measured reading, so the start is known to about 0.5 K (the teeth,
# started at the mean of slot bottom and yoke, less well than the others),
# not the default 2 K; and the filter learns the sensor's noise from its
# readings (the scatter of each reading about the mean of the 10 rows
# either side, over 600 rows), with the declared 0.2 K as the floor (the
# model file's 0.5 K is the firmware's fixed noise, not this floor):
# profile 0's thermocouples scatter by 0.4-0.6 K, the others' by 0.02-0.3
# K. The disturbances never take heat away
# (--disturbance-floor-share 0, the firmware's default for its heat
# biases): a model that runs hot is corrected by the temperatures, not by
# a negative copper loss that would cool the unmeasured copper too.
# Beside them, an offset on the coolant the links see (first-order
# Gauss-Markov, the flag's 2 K and 7200 s: a few K, hours), never below
# the outlet's reading (--boundary-offset-floor-k 0): the bench's stator
# thermocouples sit up to 3.7 K above the water outlet at rest, where no
# heat explains it (docs/hust-trials.md, "A coolant offset that never cools"),
# which the copper disturbance alone took for heat in the copper; an
# offset may warm the model, like the disturbances, never cool it. The
# temperatures' own process noise is the replay's default, 1e-4 K^2/s,
# given explicitly: the model file's `[observer] node_noise_k2_per_s`
# (1e-3, the firmware observer's, which has no disturbance states to
# carry the model's error) would otherwise be taken as this filter's too.
FUSE7=(--measure endwind_1=end_winding --measurement-noise-k 0.2 --process-noise-k2-per-s 1e-4 --disturbance active_winding,slot_centre,end_winding
  --disturbance stator_teeth,stator_yoke --disturbance-std-w 50 --initial-std-k 0.5 --noise-half-window-rows 10
  --disturbance-floor-share 0 --boundary-offset coolant --boundary-offset-std-k 2 --boundary-offset-tau-s 7200
  --boundary-offset-floor-k 0)

# Calibrates model file $1 within the bounds of params file $2 into fitted
# file $3 (its log beside it, .txt) on the profiles listed in $4, against
# the sensors every HUST model has, with options $5... added.
calibrate_hust() {
  local model=$1 params=$2 out=$3 traces=() n
  for n in $4; do traces+=(--trace "$(trace "$n")"); done
  shift 4
  "$CT" calibrate --model "$model" "${traces[@]}" --sample-period-s 1 \
    --measure activewind_1=active_winding --measure endwind_1=end_winding \
    --measure outer_yoke=stator_yoke --measure rotor=rotor --measure endcap=endcap \
    --params "$(grep -v '^#' "$params" | paste -sd, -)" --stride 10 --no-progress \
    "$@" --out "$out" > "${out%.toml}.txt"
}

# The seven-node fit: calibrate_hust on profiles $4..., with the slot
# centre's sensor, the teeth started at the stator reading, every profile
# weighing the same, run to convergence.
calibrate_seven() {
  local model=$1 params=$2 out=$3
  shift 3
  calibrate_hust "$model" "$params" "$out" "$*" --measure activewind_2=slot_centre \
    --init 'mean(slotbottom,outer_yoke)=stator_teeth' --max-iterations 120 --weighting traces
}

# Replays seven-node model $1 on profile $2 into $3.json, with replay
# options $4... (the fusion, if any, and --out).
replay_seven_with() {
  local model=$1 t out=$3
  t=$(trace "$2")
  shift 3
  "$CT" replay --model "$model" --trace "$t" --sample-period-s 1 \
    --truth activewind_1=active_winding --truth activewind_2=slot_centre "${INIT7[@]}" \
    "$@" --json > "$out.json"
}

# Replays seven-node model $1 on profile $2, open loop into $3.json and
# with endwind_1 fused into $4.json; with a fifth argument `csv`, the
# estimates too, into $3.csv and $4.csv.
replay_seven() {
  local open=() fused=()
  if [ "${5:-}" = csv ]; then open=(--out "$3.csv"); fused=(--out "$4.csv"); fi
  replay_seven_with "$1" "$2" "$3" "${open[@]}"
  replay_seven_with "$1" "$2" "$4" "${FUSE7[@]}" "${fused[@]}"
}

# FUSE7 with option $1's value set to $2, into the array FUSE.
fuse7_with() {
  local i
  FUSE=("${FUSE7[@]}")
  for i in "${!FUSE[@]}"; do
    if [ "${FUSE[$i]}" = "$1" ]; then FUSE[i + 1]=$2; return; fi
  done
  FUSE+=("$1" "$2")
}
