#!/usr/bin/env bash
# The training recipe as one folder that runs unchanged here and on a GPU machine with
# PyTorch but no Rust toolchain and no network (issue 34, part 4):
#
#   tools/train/recipe/make_bundle.sh OUT [--binary PATH] [--assets auto|embedded|PACK]
#   (copy OUT to the other machine)    OUT/run.sh RESULT [options, see run.sh]
#
#   tools/train/recipe/make_bundle.sh .recipe --lean     (a lent machine, through the device
#   tool: the checkout travels, so the bundle holds only the binary (xz, ~12 MB) and run.sh,
#   and takes the rest from the checkout around it: the checkout (45.5 MiB on 2026-12-01, the golden vectors gzipped; 45.6 MiB after
#   2026-11-29's slimming; tests/test_tree_size.py keeps it under 48) and a full bundle
#   (52 MiB) together are over the tool's 64 MiB; the lean one packs the whole wardrobe on the
#   runtime pack's bodies, `sim pack --wardrobe 256`, 3.6 MB as xz, when ../shared is here, else
#   it uses the binary's embedded assets). There: carry [".recipe"], command `.recipe/run.sh /tmp/res --minutes-data 3
#   --minutes-train 5`, the result copied into $OUT.
#
# OUT holds: the simulator's release binary (`volcap.gz`, stripped and packed), the human assets as one
# pack (`volcap sim pack --everything` from ../shared/data/makehuman when it is here, or the
# binary's embedded runtime pack with `--assets embedded`), the Python package and its
# requirements, the product's segmentation (the training crops use its masks) and the
# checkpoint the run starts from. Refused above 64 MiB.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/../../.." && pwd)"
out="${1:?usage: make_bundle.sh OUT [--binary PATH] [--assets auto|embedded|PACK]}"
shift
binary="$repo/target/release/volcap" assets=auto lean=0
while [ $# -gt 0 ]; do
  case "$1" in
    --lean) lean=1; shift ;;
    --binary) binary="$2"; shift 2 ;;
    --assets) assets="$2"; shift 2 ;;
    *) echo "make_bundle.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -x "$binary" ] || { echo "make_bundle.sh: no simulator binary at $binary (cargo build --release -p volcap)" >&2; exit 2; }
if [ "$lean" = 1 ]; then
  mkdir -p "$out"
  [ "$(cd "$out/.." && pwd)" = "$repo" ] || { echo "make_bundle.sh: a lean bundle goes in the checkout's root (e.g. $repo/.recipe), not $out" >&2; exit 2; }
  rm -rf "$out"/*
  cp "$binary" "$out/volcap"
  strip "$out/volcap" 2>/dev/null || objcopy --strip-debug "$out/volcap" 2>/dev/null || true
  xz -9 -T0 -f "$out/volcap"
  cp "$here/run.sh" "$out/"
  # The whole wardrobe on the runtime pack's bodies (3.6 MB as xz, 6.4 as the pack's gzip; the
  # whole pack, 38 MB, does not fit beside the checkout): without it the sets would hold the
  # runtime pack's 3 of the 9 outfits the held-out evaluation dresses its subjects in
  # (docs/eval/hands.md section 28). run.sh turns it back into a gzip pack.
  if [ -f "$repo/../shared/data/makehuman/3dobjs/base.obj" ]; then
    "$binary" sim pack --wardrobe 256 --from "$repo/../shared/data/makehuman" --out "$out/wardrobe.pack.gz" > /dev/null
    gzip -dc "$out/wardrobe.pack.gz" | xz -9e -T0 > "$out/assets.pack.xz"
    rm "$out/wardrobe.pack.gz"
  else
    echo "make_bundle.sh: ../shared/data/makehuman not here: the lean bundle uses the binary's embedded runtime pack (3 of the 9 outfits)" >&2
  fi
  git -C "$repo" rev-parse HEAD > "$out/COMMIT" 2>/dev/null || echo unknown > "$out/COMMIT"
  echo "lean bundle $out: $(( $(du -sb "$out" | cut -f1) / 1048576 )) MiB; the checkout and it: $(( ( $(git -C "$repo" ls-files -z | xargs -0 du -cb 2>/dev/null | tail -1 | cut -f1) + $(du -sb "$out" | cut -f1) ) / 1048576 )) MiB"
  exit 0
fi
mkdir -p "$out/models"
cp "$binary" "$out/volcap"
# Line tables are most of the binary; the recipe needs none of them.
strip "$out/volcap" 2>/dev/null || objcopy --strip-debug "$out/volcap" 2>/dev/null || true
# Packed (42 -> 16 MB): run.sh unpacks it into the result folder.
gzip -9 -n -f "$out/volcap"
case "$assets" in
  auto)
    if [ -f "$repo/../shared/data/makehuman/3dobjs/base.obj" ]; then
      "$binary" sim pack --everything --from "$repo/../shared/data/makehuman" --out "$out/assets.pack.gz"
    else
      echo "make_bundle.sh: ../shared/data/makehuman not here: the bundle uses the binary's embedded runtime pack (fewer outfits)" >&2
    fi ;;
  embedded) ;;
  *) cp "$assets" "$out/assets.pack.gz" ;;
esac
rm -rf "$out/volcap_train"
cp -r "$repo/tools/train/volcap_train" "$out/volcap_train"
find "$out/volcap_train" -name __pycache__ -prune -exec rm -rf {} +
cp "$repo/tools/train/requirements.txt" "$here/run.sh" "$out/"
cp "$repo/models/seg.onnx" "$out/models/"
cp "$repo/models/checkpoints/shape-fourier-small.pt" "$out/models/init.pt"
git -C "$repo" rev-parse HEAD > "$out/COMMIT" 2>/dev/null || echo unknown > "$out/COMMIT"
bytes=$(du -sb "$out" | cut -f1)
echo "bundle $out: $((bytes / 1048576)) MiB ($(ls "$out" | tr '\n' ' '))"
if [ "$bytes" -gt $((64 * 1048576)) ]; then
  echo "make_bundle.sh: the bundle is over 64 MiB" >&2
  exit 1
fi
