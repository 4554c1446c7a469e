#!/usr/bin/env bash
# Run the training recipe from its bundle (make_bundle.sh): generate the dataset with every
# core, train the Fourier head from the bundled checkpoint (CUDA when present), and leave a
# light checkpoint (<= 16 MiB) and the log in RESULT.
#
#   run.sh RESULT [--subjects 48] [--poses 16] [--views 3] [--steps 6000] [--procs NPROC]
#                 [--minutes-data D] [--minutes-train T] [--variant V] [--init CKPT]
#                 [--hands-every N] [--tiny]
#                 [-- extra `volcap_train.train fourier` options]
#
# budget.json's `time_s` says where the training's wall time went (steps, checkpoints,
# validation).
#
# The data: --poses jobs, each `volcap sim dataset` over every subject (the same identities
# and split, --seed 11) in one pose of its own (--pose-seed 100 + job), --procs of them at
# once, each writing its views on one thread (`--threads 1`: the jobs fill the cores); their
# images are joined in training (`--more-data`). Every finished job holds every
# subject, so a clock that stops the data early costs poses, not subjects (a generator that
# made all its poses per subject before the next subject, as this recipe did first, gave a
# timed run three subjects in all).
#
# --minutes-data: no job starts after D minutes, and the running ones are stopped then (each
# keeps the subjects it finished; the one in progress is dropped); --minutes-train: training
# stops after T minutes with its checkpoint, the rate annealed by then (`train
# --max-minutes`), and without --steps the clock alone decides how many steps (a GPU ran 6000
# steps of 16 in two minutes). Both together fit the recipe into a lent machine's call (10
# minutes a command there).
#
# --variant: the Fourier variant trained (default fourier-small); `fourier-geom` (the surface
# net feeding the series net, issue 34 part 3) starts both of its halves from the bundled
# fourier-small checkpoint and needs `-- --geom-weight W`.
#
# --hands-every N: every Nth pose job draws its people's hands in varied poses (`volcap sim
# dataset --hands varied`: forearm twists, wrist flexions, finger curls; the same bodies as at
# rest); 0 (the default) leaves every hand at rest.
#
# --init: the light checkpoint training starts from (a path from where run.sh is called, e.g.
# models/checkpoints/shape-fourier-small-seg2.pt with `-- --segment-passes 2` to go on with the
# two-pass network) instead of the bundled fourier-small one.
#
# `-- --amp bf16` runs the steps' forward in bfloat16 (train's --amp; float32 losses).
#
# --tiny is the end-to-end check (2 subjects, 2 poses, 2 views, 3 steps). Needs python3 with
# torch, numpy, safetensors, tqdm (onnxruntime for the product's masks; without it the ground
# truth's), no network.
set -euo pipefail
b="$(cd "$(dirname "$0")" && pwd)"
res="${1:?usage: run.sh RESULT [options]}"
shift
subjects=48 poses=16 views=3 steps=6000 procs=$(nproc) points=8000 batch=8 extra=()
minutes_data=0 minutes_train=0 steps_given=0 variant=fourier-small init_given="" hands_every=0
while [ $# -gt 0 ]; do
  case "$1" in
    --subjects) subjects="$2"; shift 2 ;;
    --poses) poses="$2"; shift 2 ;;
    --views) views="$2"; shift 2 ;;
    --steps) steps="$2"; steps_given=1; shift 2 ;;
    --procs) procs="$2"; shift 2 ;;
    --minutes-data) minutes_data="$2"; shift 2 ;;
    --minutes-train) minutes_train="$2"; shift 2 ;;
    --variant) variant="$2"; shift 2 ;;
    --init) init_given="$2"; shift 2 ;;
    --hands-every) hands_every="$2"; shift 2 ;;
    --tiny) subjects=2 poses=2 views=2 steps=3 steps_given=1 procs=2 points=4096 batch=2; shift ;;
    --) shift; extra=("$@"); break ;;
    *) echo "run.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
case "$hands_every" in ''|*[!0-9]*) echo "run.sh: --hands-every $hands_every: not a count" >&2; exit 2 ;; esac
# With a training clock and no --steps, the clock decides (the step count only bounds it).
[ "$minutes_train" != 0 ] && [ "$steps_given" = 0 ] && steps=1000000
# Progress bars into a log (not a terminal): a line every 15 s, not every step.
[ -t 1 ] || export TQDM_MININTERVAL="${TQDM_MININTERVAL:-15}"
py="${PYTHON:-python3}"
# A relative interpreter path stays valid after the cd into the bundle below.
case "$py" in */*) py="$(cd "$(dirname "$py")" && pwd)/$(basename "$py")" ;; esac
mkdir -p "$res"
log="$res/recipe.log"
echo "recipe $(cat "$b/COMMIT") on $(hostname): $subjects subjects x $poses poses x $views views, $procs generators at once, $steps steps at most" | tee "$log"
# A lean bundle (make_bundle.sh --lean) lives in the checkout and takes the Python package,
# the segmentation and the start checkpoint from it; a full bundle carries its own.
if [ -d "$b/volcap_train" ]; then
  pydir="$b" seg_model="$b/models/seg.onnx" init="$b/models/init.pt"
else
  repo="$(cd "$b/.." && pwd)"
  pydir="$repo/tools/train" seg_model="$repo/models/seg.onnx" init="$repo/models/checkpoints/shape-fourier-small.pt"
  [ -d "$pydir/volcap_train" ] || { echo "run.sh: a lean bundle must sit in the checkout's root (no $pydir/volcap_train)" >&2; exit 2; }
fi
if [ -n "$init_given" ]; then
  [ -f "$init_given" ] || { echo "run.sh: --init $init_given: no such checkpoint" | tee -a "$log" >&2; exit 2; }
  init="$(cd "$(dirname "$init_given")" && pwd)/$(basename "$init_given")"
fi
echo "start checkpoint: $init" | tee -a "$log"
if [ -f "$b/volcap.xz" ]; then xz -dc "$b/volcap.xz" > "$res/volcap"; else gunzip -c "$b/volcap.gz" > "$res/volcap"; fi
chmod +x "$res/volcap"
assets=()
[ -f "$b/assets.pack.gz" ] && assets=(--assets "$b/assets.pack.gz")
# A lean bundle's wardrobe travels as xz (make_bundle.sh --lean); the simulator reads gzip packs.
if [ -f "$b/assets.pack.xz" ]; then
  xz -dc "$b/assets.pack.xz" | gzip -1 > "$res/assets.pack.gz"
  assets=(--assets "$res/assets.pack.gz")
fi
t0=$(date +%s)
end=0
[ "$minutes_data" != 0 ] && end=$(( t0 + $(awk -v m="$minutes_data" 'BEGIN { printf "%d", m * 60 }') ))
declare -A running=()
next=0 finished=0
start_job() {
  local j=$1
  rm -rf "$res/ds-$j"
  local hands=()
  [ "$hands_every" -gt 0 ] && [ $(( (j + 1) % hands_every )) -eq 0 ] && hands=(--hands varied)
  "$res/volcap" sim dataset --subjects "$subjects" --poses 1 --views "$views" --points "$points" \
    --val-fraction 0.15 --seed 11 --pose-seed $((100 + j)) --lighting varied --threads 1 "${hands[@]}" "${assets[@]}" --out "$res/ds-$j" \
    > "$res/ds-$j.log" 2>&1 &
  running[$j]=$!
}
while :; do
  for j in "${!running[@]}"; do
    if ! kill -0 "${running[$j]}" 2>/dev/null; then
      # A job that ended by itself must have succeeded.
      wait "${running[$j]}" || { echo "run.sh: generator $j failed:" | tee -a "$log" >&2; tail -5 "$res/ds-$j.log" >&2; exit 1; }
      unset "running[$j]"
      finished=$((finished + 1))
    fi
  done
  late=0
  [ "$end" != 0 ] && [ "$(date +%s)" -ge "$end" ] && late=1
  if [ "$late" = 1 ]; then
    for j in "${!running[@]}"; do
      kill "${running[$j]}" 2>/dev/null || true
      wait "${running[$j]}" 2>/dev/null || true
      # Shards are written beside and renamed: only the image in progress is lost.
      find "$res/ds-$j" -name '*.part' -delete
      find "$res/ds-$j" -mindepth 1 -type d -empty -delete
      echo "generator $j stopped at $minutes_data min: $(ls "$res/ds-$j"/train/*/*.safetensors 2>/dev/null | wc -l) training and $(ls "$res/ds-$j"/val/*/*.safetensors 2>/dev/null | wc -l) validation images kept" | tee -a "$log"
      unset "running[$j]"
    done
    [ "$next" -lt "$poses" ] && echo "$((poses - next)) of $poses poses not started by the $minutes_data min clock" | tee -a "$log"
    break
  fi
  while [ "${#running[@]}" -lt "$procs" ] && [ "$next" -lt "$poses" ]; do
    start_job "$next"
    next=$((next + 1))
  done
  [ "${#running[@]}" = 0 ] && break
  sleep 1
done
echo "dataset: $(( $(date +%s) - t0 )) s, $finished of $poses poses whole" | tee -a "$log"
# Validation from the first generator that reached a validation subject (a clock may stop
# some before theirs); the others' training images join.
first=""
for i in $(seq 0 $((next - 1))); do
  if ls "$res/ds-$i"/val/*/*.safetensors >/dev/null 2>&1; then first=$i; break; fi
done
[ -n "$first" ] || { echo "run.sh: no generator wrote a validation image (give --minutes-data more time)" | tee -a "$log" >&2; exit 1; }
more=()
for i in $(seq 0 $((next - 1))); do
  [ "$i" = "$first" ] || ! ls "$res/ds-$i"/train/*/*.safetensors >/dev/null 2>&1 || more+=("$res/ds-$i")
done
seg=()
if "$py" -c "import onnxruntime" 2>/dev/null; then seg=(--seg "$seg_model"); else echo "no onnxruntime: crops from the ground-truth masks" | tee -a "$log"; fi
t1=$(date +%s)
cd "$pydir"
md=()
mt=()
[ "$minutes_train" != 0 ] && mt=(--max-minutes "$minutes_train")
[ ${#more[@]} -gt 0 ] && md=(--more-data "${more[@]}")
"$py" -m volcap_train.train fourier --data "$res/ds-$first" "${md[@]}" --out "$res/run" \
  --variant "$variant" --steps "$steps" --batch "$batch" --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I \
  --depth-frame body --points 2048 --device auto --init "$init" "${seg[@]}" "${mt[@]}" "${extra[@]}" 2>&1 | tee -a "$log"
echo "training: $(( $(date +%s) - t1 )) s" | tee -a "$log"
# Where the training's wall time went (steps, of them the batches made and the OHEM update,
# checkpoints, validation): a GPU run slower than its GPU says here which part holds it.
"$py" -c 'import json, sys; b = json.load(open(sys.argv[1])); print("steps", b["steps"], "time_s", json.dumps(b.get("time_s")))' \
  "$res/run/budget.json" | tee -a "$log"
"$py" -m volcap_train.light "$res/run" "$res/checkpoint.pt" --variant "$variant" | tee -a "$log"
cp "$res/run/log.csv" "$res/run/budget.json" "$res/"
size=$(stat -c %s "$res/checkpoint.pt")
echo "checkpoint $res/checkpoint.pt: $size bytes" | tee -a "$log"
[ "$size" -le $((16 * 1048576)) ] || { echo "run.sh: the checkpoint is over 16 MiB" >&2; exit 1; }
