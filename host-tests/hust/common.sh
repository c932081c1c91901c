# Sourced by the HUST scripts (reproduce.sh and the analyses it runs): where
# the data and outputs are, and the seven-node model's start states, fit
# and fusion, so that every script calibrates and replays it alike.
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
# The seven-node fusion: endwind_1 fused by the firmware's observer,
# every setting the model file's `[observer]` table (what `codegen`
# flashes; the file's comment gives each value's reason).
FUSE7=(--measure endwind_1=end_winding)

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
# with endwind_1 fused (FUSE7) into $4.json; with a fifth argument `csv`, the
# estimates too, into $3.csv and $4.csv.
replay_seven() {
  local open=() fused=()
  if [ "${5:-}" = csv ]; then open=(--out "$3.csv"); fused=(--out "$4.csv"); fi
  replay_seven_with "$1" "$2" "$3" "${open[@]}"
  replay_seven_with "$1" "$2" "$4" "${FUSE7[@]}" "${fused[@]}"
}
