#!/usr/bin/env bash
# A trained shape run through the engine against the committed default, image by image, on
# the 126 held-out images every checkpoint is judged on since run (18) (docs/eval/hands.md
# section 23: the 7 held-out subjects x 2 poses x 3 views at seeds 100, 200 and 300, 257^3
# from 17^3, pieces apart from the body dropped as the product does). The trainer's own
# validation does not rank runs as the engine does (section 23): this does. Adopt a run only
# where a difference lies beyond two standard errors.
#
#   tools/train/judge.sh RUN OUT
#
# RUN: a `volcap_train.train fourier --out` folder (its ckpt.pt and budget.json; a run still
# going is read at its latest checkpoint). OUT: a new folder for the export (OUT/export), a
# copy of models/ with it (OUT/models), the reports (OUT/eval-{base,run}-SEED) and judge.txt.
# Environment: DATA, a dataset for export's int8 calibration (required; the run's own);
# ASSETS (../shared/data/makehuman), VOLCAP (target/release/volcap; one that knows --colour-res), SEEDS ("100 200 300"),
# NAME (the model's name, fourier-small-seg2), BASE_DIR (a folder of earlier reports of the
# default named eval-base-SEED, reused instead of run again), BASE_NAME (the committed model it
# is judged against, NAME), ISO (the surface level, the committed NAME's; needed for a new name),
# JOBS (evaluations at once, each on one core: the cores, `nproc`; the reports are the same),
# EVAL_ARGS (more `volcap eval` options for both sides, e.g. "--hands varied": the same
# images' people with drawn wrists and fingers; BASE_DIR's reports must have been made so).
set -euo pipefail
if [ $# -ne 2 ]; then
  sed -n '2,21p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
RUN=$(cd "$1" && pwd)
mkdir -p "$2"
OUT=$(cd "$2" && pwd)
: "${DATA:?DATA: the dataset the export calibrates int8 on (e.g. the --data of the run)}"
ASSETS=${ASSETS:-$ROOT/../shared/data/makehuman}
VOLCAP=${VOLCAP:-$ROOT/target/release/volcap}
SEEDS=${SEEDS:-100 200 300}
NAME=${NAME:-fourier-small-seg2}
BASE_NAME=${BASE_NAME:-$NAME}
for f in "$RUN/ckpt.pt" "$RUN/budget.json" "$VOLCAP" "$ASSETS/MANIFEST.md"; do
  [ -e "$f" ] || { echo "judge: $f is missing" >&2; exit 2; }
done

# The export, as the committed model's (f32 and int8, its surface level).
mkdir -p "$OUT/runs/$NAME"
ln -sf "$RUN/ckpt.pt" "$OUT/runs/$NAME/ckpt.pt"
cp "$RUN/budget.json" "$OUT/runs/$NAME/budget.json"
ISO=${ISO:-}
[ -n "$ISO" ] || ISO=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['shape-'+sys.argv[2]]['iso_level'])" \
  "$ROOT/models/models.json" "$NAME")
(cd "$ROOT/tools/train" && PYTHONPATH=. .venv/bin/python -m volcap_train.export \
  --data "$DATA" --runs "$OUT/runs" --out "$OUT/export" --only "$NAME" \
  --iso-level "$ISO" --int8-calib-images 32) > "$OUT/export.log" 2>&1 \
  || { echo "judge: the export failed (see $OUT/export.log)" >&2; exit 1; }
rm -rf "$OUT/models"
cp -r "$ROOT/models" "$OUT/models"
cp "$OUT/export/shape-$NAME".fourier*.onnx "$OUT/models/"

# The reports, the default's and the run's, on the same images; JOBS at once (`volcap eval`
# runs its networks and localization on one thread).
JOBS=${JOBS:-$(nproc 2>/dev/null || echo 1)}
A=() B=()
for s in $SEEDS; do
  for side in base run; do
    dir="$OUT/eval-$side-$s"
    if [ "$side" = base ] && [ -n "${BASE_DIR:-}" ] && [ -e "$BASE_DIR/eval-base-$s/eval.json" ]; then
      dir="$BASE_DIR/eval-base-$s"
    else
      models="$ROOT/models" name="$BASE_NAME"
      [ "$side" = run ] && models="$OUT/models" name="$NAME"
      while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do wait -n || true; done
      echo "judge: $side, seed $s" >&2
      rm -f "$dir.failed"
      # The shape judged (the colour networks are shared: no colour columns).
      ("$VOLCAP" eval --data "$ASSETS" --subjects val --poses 2 --views 3 --res 257 \
        --seed "$s" --coarse-level 4 --model "$name" --models-dir "$models" --out "$dir" --colour-res 0 \
        ${EVAL_ARGS:-} > "$dir.log" 2>&1 || touch "$dir.failed") &
    fi
    if [ "$side" = base ]; then B+=("$dir"); else A+=("$dir"); fi
  done
done
wait
for d in "${A[@]}" "${B[@]}"; do
  [ ! -e "$d.failed" ] || { echo "judge: volcap eval failed (see $d.log)" >&2; exit 1; }
done
(cd "$ROOT/tools/train" && PYTHONPATH=. .venv/bin/python -m volcap_train.compare_evals \
  --a "${A[@]}" --b "${B[@]}" --by-subject) | tee "$OUT/judge.txt"
echo "judge: A = $RUN, B = the committed default; $OUT/judge.txt" >&2
