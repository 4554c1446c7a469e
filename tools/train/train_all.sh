#!/usr/bin/env bash
# Trains every committed model from scratch, then exports them (ONNX f32 + int8, golden
# vectors, model cards) into models/. Resumable: rerun after an interruption and each run
# continues from its last checkpoint. Budget per run is fixed below (same steps, batch and
# points for every shape variant of one size class), see models/*.md for the wall times.
#   DATA: a `volcap sim dataset` folder, e.g.
#   cargo run --release -p volcap -- sim dataset --subjects 20 --poses 4 --views 12 --val-fraction 0.2 --seed 6 --out /work/data/ds
#   DATA_POSES: the same identities and split in more poses (fourier-small's stage 6), e.g.
#   cargo run --release -p volcap -- sim dataset --subjects 48 --poses 16 --views 3 --val-fraction 0.15 --seed 11 --out /work/data/ds3
#   (with DATA made by the same command with --poses 4 --views 12)
#   DATA_POSES2: the same again in twice the poses (fourier-small's stage 7), e.g.
#   cargo run --release -p volcap -- sim dataset --subjects 48 --poses 32 --views 3 --val-fraction 0.15 --seed 11 --out /work/data/ds4
#   DATA_LIGHT: the same identities and split in 32 new poses, each under its own light rig
#   (fourier-small's stage 8 trains on it and DATA_POSES2 together), e.g.
#   cargo run --release -p volcap -- sim dataset --subjects 48 --poses 32 --views 3 --val-fraction 0.15 --seed 11 --pose-seed 12 --lighting varied --out /work/data/ds5
#   DATA_LIGHT2: as DATA_LIGHT in 32 more new poses (fourier-small's stage 9 trains on the three), e.g.
#   cargo run --release -p volcap -- sim dataset --subjects 48 --poses 32 --views 3 --val-fraction 0.15 --seed 11 --pose-seed 13 --lighting varied --out /work/data/ds6
#   DATA_SEG2 (optional): three folders, space-separated, of the same identities in 16 new poses each
#   (fourier-small-seg2: fourier-small resumed on two-pass masks), each made by
#   cargo run --release -p volcap -- sim dataset --subjects 48 --poses 16 --views 3 --val-fraction 0.15 --seed 11 --pose-seed P --lighting varied --out DIR
#   with P = 13, 14 and 15.
#   DATA_SEG2_NEW (optional): three more such folders, P = 16, 17 and 18 (fourier-small-seg2's runs
#   (14) and (16)); unset: DATA_SEG2's. Every folder made by the simulator before 2026-11-28 shows
#   people whose left elbow bends backward (docs/eval/hands.md section 17): make them again.
#   The committed runs (1)-(14) were trained on such images, run (16) on DATA_SEG2_NEW made anew.
#   DATA_SEG2_IDS (optional): new identities for fourier-small-seg2's run (17), made by
#   cargo run --release -p volcap -- sim dataset --subjects 128 --poses 6 --views 3 --val-fraction 0.01 --seed 23 --pose-seed 23 --lighting varied --out DIR
#   (another seed: none of DATA_SEG2's held-out identities); unset: run (16) is the last.
#   DATA_SEG2_IDS2 (optional, with DATA_SEG2_IDS): two more such folders for run (18), the same
#   command with --seed 29 --pose-seed 29 and --seed 31 --pose-seed 31; unset: run (17) is the last.
#   DATA_SEG2_WARDROBE (optional, with DATA_SEG2_IDS2): three folders for run (32), the same
#   command with --seed 47 --pose-seed 47 and 53 dressed from the whole wardrobe (`--assets
#   ../shared/data/makehuman`), then 43 without (docs/eval/hands.md section 28); unset: run (18)
#   is the last.
#   DATA_SEG2_WHOLE (optional, with DATA_SEG2_WARDROBE): two folders for run (35) and the
#   fourier-medium runs (34) and (36): DATA_SEG2's first folder's command with `--assets
#   ../shared/data/makehuman` (DS16 in the whole wardrobe: the same identities, split, poses and
#   light rigs), then set 43 with it (docs/eval/hands.md sections 28-29); unset: run (32) is the
#   last, and fourier-medium is the old widened stage 5. The colour networks train on its first
#   folder (DS16W; on DATA without it): made by the simulator of 2026-11-29 or later, whose
#   coloured samples are the surface the views show (section 30; train refuses older folders).
set -euo pipefail
cd "$(dirname "$0")"
if [ -n "${DATA_SEG2_WHOLE:-}" ] && { [ -z "${DATA_SEG2:-}" ] || [ -z "${DATA_SEG2_IDS:-}" ] || [ -z "${DATA_SEG2_IDS2:-}" ] || [ -z "${DATA_SEG2_WARDROBE:-}" ]; }; then
  echo "train_all.sh: DATA_SEG2_WHOLE needs DATA_SEG2, DATA_SEG2_IDS, DATA_SEG2_IDS2 and DATA_SEG2_WARDROBE (runs (17)-(32) come first)" >&2
  exit 2
fi
DATA=${DATA:?set DATA to a volcap sim dataset folder}
DATA_POSES=${DATA_POSES:?set DATA_POSES to a volcap sim dataset folder of the same identities in more poses}
DATA_POSES2=${DATA_POSES2:?set DATA_POSES2 to a volcap sim dataset folder of the same identities in twice DATA_POSES poses}
DATA_LIGHT=${DATA_LIGHT:?set DATA_LIGHT to a volcap sim dataset folder of the same identities in new poses under varied light}
DATA_LIGHT2=${DATA_LIGHT2:?set DATA_LIGHT2 to a volcap sim dataset folder like DATA_LIGHT in other new poses}
RUNS=${RUNS:-runs}
PY=${PY:-python3}
ABL=${ABL_STEPS:-250}
FULL=${FULL_STEPS:-400}
T="$PY -m volcap_train.train"
# The compact default: trained to $ABL steps (the ablation reference), then resumed to $FULL.
$T shape --data "$DATA" --out "$RUNS/compact-$ABL" --variant compact --steps "$ABL"
[ -e "$RUNS/compact/ckpt.pt" ] || { mkdir -p "$RUNS/compact"; cp "$RUNS/compact-$ABL/ckpt.pt" "$RUNS/compact/"; }
$T shape --data "$DATA" --out "$RUNS/compact" --variant compact --steps "$FULL"
$T seg --data "$DATA" --out "$RUNS/seg" --steps "${SEG_STEPS:-600}"
# The larger model, same budget as the compact default.
$T shape --data "$DATA" --out "$RUNS/large" --variant large --steps "$FULL"
# Ablations on the compact size, same budget as compact-$ABL.
$T shape --data "$DATA" --out "$RUNS/compact-plain-z" --variant compact-plain-z --steps "$ABL"
$T shape --data "$DATA" --out "$RUNS/compact-cbn-z" --variant compact-cbn-z --steps "$ABL"
$T shape --data "$DATA" --out "$RUNS/compact-ohem-none" --variant compact --ohem none --steps "$ABL"
$T shape --data "$DATA" --out "$RUNS/compact-ohem-P" --variant compact --ohem P --steps "$ABL"
# The Fourier head: dense ray supervision (needs shards with ray_offsets/ray_z).
$T fourier --data "$DATA" --out "$RUNS/fourier" --variant fourier --steps "${FOURIER_STEPS:-4000}" --point-weight 0.3
# fourier-small, the default shape model, in stages (under stages/, which the export does not
# list as models): (1) the dense ray loss alone in the body depth frame; (2) resumed with 0.1 x
# the point term, OHEM on points and images, and augmentation; (3) the same at a lower rate;
# (4) resumed on the product's segmentation masks (crops and mask channels from models/seg.onnx,
# as the engine makes them; targets from the ground truth); (5) the same, longer.
$T fourier --data "$DATA" --out "$RUNS/stages/fourier-small-dense" --variant fourier-small --steps 8000 --lr 1e-3 --point-weight 0 --moment-weight 1 --ohem none --no-aug --depth-frame body --points 2048
$T fourier --data "$DATA" --out "$RUNS/stages/fourier-small-point" --variant fourier-small --steps 4000 --lr 5e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --init "$RUNS/stages/fourier-small-dense/ckpt.pt"
$T fourier --data "$DATA" --out "$RUNS/stages/fourier-small-gt" --variant fourier-small --steps 3000 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --init "$RUNS/stages/fourier-small-point/ckpt.pt"
$T fourier --data "$DATA" --out "$RUNS/stages/fourier-small-seg" --variant fourier-small --steps 7000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-small-gt/ckpt.pt"
$T fourier --data "$DATA" --out "$RUNS/stages/fourier-small-5" --variant fourier-small --steps 9000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-small-seg/ckpt.pt"
# (6) resumed on more poses of the same identities (the network had learnt pose-views: training
# images 0.82 point IoU, held-out 0.72).
$T fourier --data "$DATA_POSES" --out "$RUNS/stages/fourier-small-6" --variant fourier-small --steps 6000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-small-5/ckpt.pt"
# (7) resumed on twice the poses again (held-out point IoU 0.737 -> 0.752 with the product's masks).
$T fourier --data "$DATA_POSES2" --out "$RUNS/stages/fourier-small-7" --variant fourier-small --steps 10000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-small-6/ckpt.pt"
# (8) resumed on DATA_POSES2 and DATA_LIGHT together (--more-data: 32 new poses under varied
# light; held-out 257^3 Chamfer / P2S / IoU 2.34 / 1.09 / 0.655 -> 2.22 / 0.98 / 0.667).
$T fourier --data "$DATA_POSES2" --more-data "$DATA_LIGHT" --out "$RUNS/stages/fourier-small-8" --variant fourier-small --steps 7000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-small-7/ckpt.pt"
# (9) resumed on the three together (DATA_LIGHT2: 32 more new poses under varied light; peak RAM
# about 21 GB; held-out 257^3 2.22 / 0.98 / 0.667 -> 2.17 / 0.96 / 0.667).
$T fourier --data "$DATA_POSES2" --more-data "$DATA_LIGHT" "$DATA_LIGHT2" --out "$RUNS/fourier-small" --variant fourier-small --steps 10000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-small-8/ckpt.pt"
# fourier-small-seg2 (with DATA_SEG2): (10) fourier-small resumed on the masks of two segmentation
# passes (`--segment-passes 2`, what the boards with `[model] segment_passes = 2` feed it); held-out
# 257^3, segmented twice, 1.99 / 1.15 / 0.669 -> 1.92 / 0.99 / 0.668 (docs/eval/hands.md section 9);
# (11) resumed on the same for 7,390 steps (100 minutes on 2 threads): 1.92 / 0.99 / 0.668 ->
# 1.81 / 0.92 / 0.692 (section 10); (12) resumed in bfloat16 (`--amp bf16`), 5,034 steps at lr 2e-4
# then 13,459 at 1e-4: 1.81 / 0.92 / 0.692 -> 1.79 / 0.89 / 0.688 (section 11); (14) resumed on
# three new 16-pose sets (DATA_SEG2_NEW, else DATA_SEG2's) with a moving average of the weights
# (`--ema 0.9995`, BatchNorm recomputed for it at the end): 1.79 / 0.89 / 0.688 -> 1.78 / 0.89 /
# 0.701 (section 14; the old simulator's images); (16) resumed on the same sets made by the fixed
# simulator (both elbows flex forward), 65 minutes on 2 threads: on the fixed simulator's held-out
# images 3.50 / 2.62 / 0.590 -> 2.38 / 1.51 / 0.645 (section 17); (17) resumed with 127 new
# identities (DATA_SEG2_IDS) and mirrored images (`--flip`), 75 minutes: facing errors 9.8 % ->
# 4.8 % of the held-out images, eval.md's 21 images 3.03 / 1.99 / 0.632 -> 2.15 / 1.17 / 0.676
# (section 18); (18) resumed with 254 more identities (DATA_SEG2_IDS2) beside DS16 and run (17)'s,
# 65 minutes (5,334 steps, the machine shared): 42 images 2.33 / 1.68 / 0.647 -> 2.00 / 1.35 /
# 0.677, localized with the seeds (section 20; the default model).
if [ -n "${DATA_SEG2:-}" ]; then
  read -r -a SEG2 <<< "$DATA_SEG2"
  read -r -a SEG2N <<< "${DATA_SEG2_NEW:-$DATA_SEG2}"
  $T fourier --data "${SEG2[0]}" --more-data "${SEG2[@]:1}" --out "$RUNS/stages/fourier-small-seg2-10" --variant fourier-small --steps 5000 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --init "$RUNS/fourier-small/ckpt.pt"
  $T fourier --data "${SEG2[0]}" --more-data "${SEG2[@]:1}" --out "$RUNS/stages/fourier-small-seg2-11" --variant fourier-small --steps 7390 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --init "$RUNS/stages/fourier-small-seg2-10/ckpt.pt"
  $T fourier --data "${SEG2[0]}" --more-data "${SEG2[@]:1}" --out "$RUNS/stages/fourier-small-seg2-12a" --variant fourier-small --steps 5034 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --init "$RUNS/stages/fourier-small-seg2-11/ckpt.pt"
  $T fourier --data "${SEG2[0]}" --more-data "${SEG2[@]:1}" --out "$RUNS/stages/fourier-small-seg2-12" --variant fourier-small --steps 13459 --lr 1e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 1 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --init "$RUNS/stages/fourier-small-seg2-12a/ckpt.pt"
  $T fourier --data "${SEG2N[0]}" --more-data "${SEG2N[@]:1}" --out "$RUNS/stages/fourier-small-seg2-14" --variant fourier-small --steps 23585 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-small-seg2-12/ckpt.pt"
  $T fourier --data "${SEG2N[0]}" --more-data "${SEG2N[@]:1}" --out "$RUNS/stages/fourier-small-seg2-16" --variant fourier-small --steps 18600 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-small-seg2-14/ckpt.pt"
  if [ -n "${DATA_SEG2_IDS:-}" ]; then
    $T fourier --data "${SEG2N[0]}" --more-data "${SEG2N[@]:1}" "$DATA_SEG2_IDS" --flip --out "$RUNS/stages/fourier-small-seg2-17" --variant fourier-small --steps 19336 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-small-seg2-16/ckpt.pt"
    LAST=17
  else
    LAST=16
  fi
  if [ "$LAST" = 17 ] && [ -n "${DATA_SEG2_IDS2:-}" ]; then
    read -r -a IDS2 <<< "$DATA_SEG2_IDS2"
    OUT18="$RUNS/fourier-small-seg2"
    [ -n "${DATA_SEG2_WARDROBE:-}" ] && OUT18="$RUNS/stages/fourier-small-seg2-18"
    $T fourier --data "${SEG2N[0]}" --more-data "$DATA_SEG2_IDS" "${IDS2[@]}" --flip --out "$OUT18" --variant fourier-small --steps 5334 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-small-seg2-17/ckpt.pt"
    # (32): the whole wardrobe (section 28), run (24)'s recipe and seed, 766 s.
    if [ -n "${DATA_SEG2_WARDROBE:-}" ]; then
      read -r -a WARD <<< "$DATA_SEG2_WARDROBE"
      OUT32="$RUNS/fourier-small-seg2"
      [ -n "${DATA_SEG2_WHOLE:-}" ] && OUT32="$RUNS/stages/fourier-small-seg2-32"
      $T fourier --data "${SEG2N[0]}" --more-data "${WARD[@]}" --flip --out "$OUT32" --variant fourier-small --steps 5334 --seed 4 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$OUT18/ckpt.pt"
      # (35): every set from the whole wardrobe (section 29), run (32) on for 5,334 steps, 684 s.
      if [ -n "${DATA_SEG2_WHOLE:-}" ]; then
        read -r -a WHOLE <<< "$DATA_SEG2_WHOLE"
        ALLW=("${WARD[0]}" "${WARD[1]}" "${WHOLE[1]}")
        $T fourier --data "${WHOLE[0]}" --more-data "${ALLW[@]}" --flip --out "$RUNS/fourier-small-seg2" --variant fourier-small --steps 5334 --seed 4 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$OUT32/ckpt.pt"
      fi
    fi
  else
    mkdir -p "$RUNS/fourier-small-seg2"; cp "$RUNS/stages/fourier-small-seg2-$LAST/"{ckpt.pt,budget.json} "$RUNS/fourier-small-seg2/"
  fi
fi
# fourier-medium: fourier-small widened from c = 8 to 12 without changing its function
# (volcap_train.widen: the new channels start unread), then trained on as fourier-small's last
# stage (more capacity without starting over).
# With DATA_SEG2_WHOLE, the GPU boards' fourier-medium (sections 28-29): run (32) widened, run
# (34) on DS16 and the three whole-wardrobe identity sets (1,033 s), run (36) on every set from
# the whole wardrobe at twice the steps (2,297 s), runs (38) and (39) on as many more each
# (2,385 s and 3,679 s; section 30).
if [ -n "${DATA_SEG2_WHOLE:-}" ]; then
  $PY -m volcap_train.widen --init "$OUT32/ckpt.pt" --from fourier-small --to fourier-medium --out "$RUNS/stages/fourier-medium-init.pt"
  $T fourier --data "${SEG2N[0]}" --more-data "${ALLW[@]}" --flip --out "$RUNS/stages/fourier-medium-34" --variant fourier-medium --steps 5334 --seed 14 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-medium-init.pt"
  $T fourier --data "${WHOLE[0]}" --more-data "${ALLW[@]}" --flip --out "$RUNS/stages/fourier-medium-36" --variant fourier-medium --steps 10668 --seed 14 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-medium-34/ckpt.pt"
  $T fourier --data "${WHOLE[0]}" --more-data "${ALLW[@]}" --flip --out "$RUNS/stages/fourier-medium-38" --variant fourier-medium --steps 10668 --seed 15 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-medium-36/ckpt.pt"
  $T fourier --data "${WHOLE[0]}" --more-data "${ALLW[@]}" --flip --out "$RUNS/fourier-medium" --variant fourier-medium --steps 10668 --seed 16 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --init "$RUNS/stages/fourier-medium-38/ckpt.pt"
else
  $PY -m volcap_train.widen --init "$RUNS/stages/fourier-small-5/ckpt.pt" --from fourier-small --to fourier-medium --out "$RUNS/stages/fourier-medium-init.pt"
  $T fourier --data "$DATA" --out "$RUNS/fourier-medium" --variant fourier-medium --steps 10000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --init "$RUNS/stages/fourier-medium-init.pt"
fi
# The colour networks (section 30): 3,000 steps on the surface the views show, targets at the
# input's exposure; on DS16W when it is given (the committed run), else on DATA (either made by
# a simulator that samples the seen surface: `"surface": "seen"` in its dataset.json).
$T color --data "${WHOLE[0]:-$DATA}" --out "$RUNS/color" --steps "${COLOR_STEPS:-3000}"
# fourier-small-upper: upper bodies (the person cut by the frame's lower edge) added to the
# training images, for close-range framing. With DS16W: the default resumed, every training
# image of DS16W also cut (runs (77)-(79), 2026-12-01: 3 x 4,000 steps; the committed one
# started from the default's light checkpoint, run (54)); without it: stage (3) resumed (runs
# (4), (5) of its first card).
if [ -n "${DATA_SEG2_WHOLE:-}" ]; then
  $T fourier --data "${WHOLE[0]}" --out "$RUNS/stages/fourier-small-upper-77" --variant fourier-small --steps 4000 --seed 35 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --flip --upper-every 1 --init "$RUNS/fourier-small-seg2/ckpt.pt"
  $T fourier --data "${WHOLE[0]}" --out "$RUNS/stages/fourier-small-upper-78" --variant fourier-small --steps 4000 --seed 36 --lr 1e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --flip --upper-every 1 --init "$RUNS/stages/fourier-small-upper-77/ckpt.pt"
  $T fourier --data "${WHOLE[0]}" --out "$RUNS/fourier-small-upper" --variant fourier-small --steps 4000 --seed 37 --lr 1e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --flip --upper-every 1 --init "$RUNS/stages/fourier-small-upper-78/ckpt.pt"
else
  $T fourier --data "$DATA" --out "$RUNS/stages/fourier-small-upper-1" --variant fourier-small --steps 3000 --lr 3e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --upper-every 2 --init "$RUNS/stages/fourier-small-gt/ckpt.pt"
  $T fourier --data "$DATA" --out "$RUNS/fourier-small-upper" --variant fourier-small --steps 2000 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --upper-every 4 --init "$RUNS/stages/fourier-small-upper-1/ckpt.pt"
fi
# fourier-small-k31: the default grown to 31 harmonics (the new ones start at zero) and trained
# on (runs (80), (81), 2026-12-01; docs/eval/hands.md section 46): the series' K as a measured
# knob, not a default. Only with DS16W (it starts from the default's run).
if [ -n "${DATA_SEG2_WHOLE:-}" ]; then
  $PY -m volcap_train.widen --init "$RUNS/fourier-small-seg2/ckpt.pt" --from fourier-small --to fourier-small-k31 --out "$RUNS/stages/fourier-small-k31-init.pt"
  $T fourier --data "${WHOLE[0]}" --out "$RUNS/stages/fourier-small-k31-80" --variant fourier-small-k31 --steps 8000 --seed 38 --lr 2e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --flip --init "$RUNS/stages/fourier-small-k31-init.pt"
  $T fourier --data "${WHOLE[0]}" --out "$RUNS/fourier-small-k31" --variant fourier-small-k31 --steps 4000 --seed 39 --lr 1e-4 --point-weight 0.1 --moment-weight 1 --ohem P+I --depth-frame body --points 2048 --threads 2 --seg ../../models/seg.onnx --segment-passes 2 --amp bf16 --ema 0.9995 --flip --init "$RUNS/stages/fourier-small-k31-80/ckpt.pt"
fi
$PY -m volcap_train.export --data "$DATA" --runs "$RUNS" --out ../../models
# fourier-small's surface level comes from a sweep on training subjects (its model card):
#   volcap eval --subjects train --poses 1 --views 2 --res 129 --seed 7 --model fourier-small --iso-level 0.45,0.5,0.55,0.6
$PY -m volcap_train.export --data "$DATA_POSES2" --runs "$RUNS" --out ../../models --only fourier-small --iso-level "${FOURIER_SMALL_ISO:-0.55}"
if [ -n "${DATA_SEG2_WHOLE:-}" ]; then
  $PY -m volcap_train.export --data "${WHOLE[0]}" --runs "$RUNS" --out ../../models --only fourier-small-seg2 --iso-level 0.55 --int8-calib-images 32 --light-half
  $PY -m volcap_train.export --data "${WHOLE[0]}" --runs "$RUNS" --out ../../models --only fourier-medium --iso-level 0.55 --int8-calib-images 128 --light-half
elif [ -n "${DATA_SEG2:-}" ]; then
  $PY -m volcap_train.export --data "${SEG2N[0]}" --runs "$RUNS" --out ../../models --only fourier-small-seg2 --iso-level 0.55 --int8-calib-images 320
fi
$PY -m volcap_train.export --data "${WHOLE[0]:-$DATA}" --runs "$RUNS" --out ../../models --only fourier-small-upper --iso-level 0.5 --int8-calib-images 256
if [ -n "${DATA_SEG2_WHOLE:-}" ]; then
  $PY -m volcap_train.export --data "${WHOLE[0]}" --runs "$RUNS" --out ../../models --only fourier-small-k31 --iso-level 0.55 --int8-calib-images 256 --light-half
fi
# The product's segmentation is MediaPipe's (pinned PyPI wheel, converted to ONNX); ours is seg-sim.onnx.
$PY -m volcap_train.mediapipe_seg --out ../../models
# ... its weights fine-tuned on the renders and mixed 0.3 of the way from MediaPipe's
# (docs/eval/hands.md section 43; models/seg.md's fine-tuning paragraphs are kept by hand:
# mediapipe_seg writes the original's card). DATA_SEG_TUNE: the sets, e.g. "DS16W DSF67 DSF53".
if [ -n "${DATA_SEG_TUNE:-}" ]; then
  read -r -a SEGSETS <<< "$DATA_SEG_TUNE"
  cp ../../models/seg.onnx "$RUNS/seg-mediapipe.onnx"
  $PY -m volcap_train.seg_tune --seg "$RUNS/seg-mediapipe.onnx" --data "${SEGSETS[0]}" --more-data "${SEGSETS[@]:1}" \
    --out "$RUNS/seg" --steps 1500 --batch 16 --lr 1e-4 --anchor-weight 1 --threads 2 --seed 0 --mix 0.3 --install ../../models
  $PY -m volcap_train.mediapipe_seg --out ../../models --golden-only
fi
