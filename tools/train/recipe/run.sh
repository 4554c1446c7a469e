#!/usr/bin/env bash
# Run the training recipe from its bundle (make_bundle.sh): generate the dataset with every
# core, train the Fourier head from the bundled checkpoint (CUDA when present), and leave a
# light checkpoint (<= 16 MiB) and the log in RESULT.
#
#   run.sh RESULT [--subjects 48] [--poses 16] [--views 3] [--steps 6000] [--procs NPROC]
#                 [--tiny] [-- extra `volcap_train.train fourier` options]
#
# --procs generators run at once, each the same subjects and split (--seed 11) in poses of
# its own (--pose-seed 100 + i), their images joined in training (`--more-data`); --tiny is
# the end-to-end check (2 subjects, 1 pose, 2 views, 3 steps). Needs python3 with torch,
# numpy, safetensors, tqdm (onnxruntime for the product's masks; without it the ground
# truth's), no network.
set -euo pipefail
b="$(cd "$(dirname "$0")" && pwd)"
res="${1:?usage: run.sh RESULT [options]}"
shift
subjects=48 poses=16 views=3 steps=6000 procs=$(nproc) points=8000 batch=8 extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --subjects) subjects="$2"; shift 2 ;;
    --poses) poses="$2"; shift 2 ;;
    --views) views="$2"; shift 2 ;;
    --steps) steps="$2"; shift 2 ;;
    --procs) procs="$2"; shift 2 ;;
    --tiny) subjects=2 poses=1 views=2 steps=3 procs=2 points=4096 batch=2; shift ;;
    --) shift; extra=("$@"); break ;;
    *) echo "run.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
py="${PYTHON:-python3}"
# A relative interpreter path stays valid after the cd into the bundle below.
case "$py" in */*) py="$(cd "$(dirname "$py")" && pwd)/$(basename "$py")" ;; esac
mkdir -p "$res"
log="$res/recipe.log"
echo "recipe $(cat "$b/COMMIT") on $(hostname): $subjects subjects x $poses poses x $views views in $procs generators, $steps steps" | tee "$log"
gunzip -c "$b/volcap.gz" > "$res/volcap"
chmod +x "$res/volcap"
assets=()
[ -f "$b/assets.pack.gz" ] && assets=(--assets "$b/assets.pack.gz")
t0=$(date +%s)
pids=()
for i in $(seq 0 $((procs - 1))); do
  rm -rf "$res/ds-$i"
  "$res/volcap" sim dataset --subjects "$subjects" --poses "$poses" --views "$views" --points "$points" \
    --val-fraction 0.15 --seed 11 --pose-seed $((100 + i)) --lighting varied "${assets[@]}" --out "$res/ds-$i" \
    > "$res/ds-$i.log" 2>&1 &
  pids+=($!)
done
for p in "${pids[@]}"; do wait "$p"; done
echo "dataset: $(( $(date +%s) - t0 )) s" | tee -a "$log"
more=()
for i in $(seq 1 $((procs - 1))); do more+=("$res/ds-$i"); done
seg=()
if "$py" -c "import onnxruntime" 2>/dev/null; then seg=(--seg "$b/models/seg.onnx"); else echo "no onnxruntime: crops from the ground-truth masks" | tee -a "$log"; fi
t1=$(date +%s)
cd "$b"
md=()
[ ${#more[@]} -gt 0 ] && md=(--more-data "${more[@]}")
"$py" -m volcap_train.train fourier --data "$res/ds-0" "${md[@]}" --out "$res/run" \
  --variant fourier-small --steps "$steps" --batch "$batch" --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I \
  --depth-frame body --points 2048 --device auto --init "$b/models/init.pt" "${seg[@]}" "${extra[@]}" 2>&1 | tee -a "$log"
echo "training: $(( $(date +%s) - t1 )) s" | tee -a "$log"
"$py" -m volcap_train.light "$res/run" "$res/checkpoint.pt" --variant fourier-small | tee -a "$log"
cp "$res/run/log.csv" "$res/run/budget.json" "$res/"
size=$(stat -c %s "$res/checkpoint.pt")
echo "checkpoint $res/checkpoint.pt: $size bytes" | tee -a "$log"
[ "$size" -le $((16 * 1048576)) ] || { echo "run.sh: the checkpoint is over 16 MiB" >&2; exit 1; }
