#!/usr/bin/env bash
# The real-GPU bench of issue 33 (docs/bench/pipeline-gpu.md) for a lent GPU machine, which has
# no Rust toolchain and no network. Two steps:
#
#   here:   tools/gpu_bench.sh prepare
#           builds the release `volcap` with the GPU backend, packs it stripped into .gpubench/
#           (xz, ~12 MiB: the working tree that travels is limited to 64 MiB with what a call
#           carries; the tracked tree is 47.9 MiB (2026-12-04; 2026-12-01: the golden vectors gzipped, 47.3 -> 42.4,
#           then fourier-small-k31; 73.3 before 2026-11-29's slimming), and
#           tools/train/tests/test_tree_size.py keeps it under 48)
#           and downloads the Vulkan loader into .gl/ (both git-ignored)
#   there:  device run, carry [".gpubench", ".gl"], command:
#           PACK_TO=$OUT OUT=/tmp/gb tools/gpu_bench.sh run --short
#           (--quick: a tiny version, as CI-free checking here on lavapipe does; --short: the
#           matrix with 4 s windows, the machine's cores only and no rows that another step
#           of the same run measures, some 7 minutes on an H200; PACK_TO: the results packed
#           into one file, since a call brings back at most 8)
#
# `run` unpacks the loader, names the adapter, and writes into $OUT (default /tmp/gpubench):
# pipeline.md/.png (the daemon's pipeline in-process, CPU and GPU backends side by side, 257^3
# and 513^3, fourier-small and fourier-medium, the camera replayed fast enough never to cap
# the rate), localize.md/.png (the localization alone, on the model's field, CPU and adapter,
# the adapter's with a read-back per conflict round and with the rounds predicted),
# rounds/pipeline.md (the GPU backend's pipeline with `compute.round_waits` per-round and
# per-frame), workers/pipeline.md (the segmentation on a thread of its own, x 1
# or 2 render and segment workers, `compute.render_workers`, `compute.segment_workers`;
# pipeline.md's GPU rows at yaw 0 are the baseline, the default split and one worker each),
# track/pipeline.md (`model.segment_full_every` 1 and 8: the segmentation's track), coarse/pipeline.md (from coarse levels 2, 3 and 4), k31/pipeline.md (the
# series' K: the default fourier-small-seg2 against fourier-small-k31, 63 maps), queues.md (the
# localization alone, beside the shape network on one device, and on a second device),
# devices/pipeline.md (the pipeline with `compute.render_device` shared and own) and
# nets.md (the networks, tract and the GPU kernels, each profiled per node or step; the
# convolutions as a GPU plans them, with the split ones, without them (wgpu-rows) and with
# conv4 only (wgpu-conv4), the baselines in the same run), with
# run.log. The device is named in every table; the CPU rows are that machine's cores, not the
# appliance's two.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cd "$repo"
mode="${1:-}"
shift || true
case "$mode" in
  prepare)
    cargo build --release --workspace --features volcapd/rtsp,volcap/wgpu
    rm -rf .gpubench && mkdir -p .gpubench
    cp target/release/volcap .gpubench/volcap
    strip .gpubench/volcap
    xz -9 -T0 -f .gpubench/volcap
    if ! ls .gl/libglvnd0_*.deb >/dev/null 2>&1; then
      # The loader packages of the device README (amd64, whatever this machine is): the
      # Vulkan loader, and GLVND, which NVIDIA's Vulkan driver (libGLX_nvidia) needs: with
      # the loader alone it answers "Could not get 'vkCreateInstance'" and no adapter shows.
      mkdir -p .gl /tmp/amd64/partial
      o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
      # shellcheck disable=SC2086
      apt-get $o update -qq
      # shellcheck disable=SC2086
      (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
    fi
    du -sh .gpubench .gl
    echo "now: device run with carry [\".gpubench\", \".gl\"] and command: PACK_TO=\$OUT OUT=/tmp/gb tools/gpu_bench.sh run --short"
    ;;
  run)
    quick=0
    [ "${1:-}" = "--quick" ] && quick=1
    [ "${1:-}" = "--short" ] && quick=2
    out="${OUT:-/tmp/gpubench}"
    mkdir -p "$out"
    exec > >(tee "$out/run.log") 2>&1
    if ls .gl/*.deb >/dev/null 2>&1 && ! ldconfig -p | grep -q libGLdispatch.so.0; then
      for f in .gl/*.deb; do dpkg -x "$f" /; done
      ldconfig
    fi
    nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$nvidia_icd" ]; then
      export VK_DRIVER_FILES="$nvidia_icd"
    fi
    export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
    # Mesa's Vulkan drivers print "XDG_RUNTIME_DIR is invalid" on every instance without one
    # (their window-system probe; no window is opened): give them an empty one.
    if [ -z "${XDG_RUNTIME_DIR:-}" ] || [ ! -d "$XDG_RUNTIME_DIR" ]; then
      XDG_RUNTIME_DIR="$(mktemp -d)"
      export XDG_RUNTIME_DIR
    fi
    bin=/tmp/volcap-gpubench
    if [ -f .gpubench/volcap.xz ]; then
      xz -dc .gpubench/volcap.xz > "$bin" && chmod +x "$bin"
    else
      bin="$repo/target/release/volcap"
    fi
    nvidia-smi -L 2>/dev/null || true
    if [ "$quick" = 1 ]; then
      # (Windows long enough for lavapipe, whose frames take seconds, to publish some.)
      res=65 models=fourier-small secs=12 warm=8 runs=1 threads=1 loc_backends=cpu,wgpu qres=33
      round_waits=per-round,per-frame k31_backends=cpu,wgpu workers_rows="$models=1,2=workers"
    elif [ "$quick" = 2 ]; then
      # The matrix in about a third of the time (a lent machine's 15 minutes, its start
      # included): shorter windows, the machine's cores only, no row twice.
      res=257,513 models=fourier-small,fourier-medium secs=4 warm=2 runs=3
      threads="$(nproc)" loc_backends=wgpu qres=257
      # (Rows measured elsewhere in the same run left out: the per-round and CPU rows are the
      # main matrix's; the track at 257^3 alone.)
      round_waits=per-frame k31_backends=wgpu track_res=257
      workers_rows="fourier-medium=1,2=workers fourier-small=1=workers-small"
    else
      res=257,513 models=fourier-small,fourier-medium secs=10 warm=5 runs=5
      threads="1,$(nproc)" loc_backends=cpu,wgpu qres=257
      round_waits=per-round,per-frame k31_backends=cpu,wgpu workers_rows="$models=1,2=workers"
    fi
    # A lent machine brings back at most 8 files, two folders down, and only what lies under
    # $OUT when the call ends (at its limit too): with PACK_TO set, the results are packed into
    # PACK_TO/gpubench.tgz every 20 s and at the end (written aside, then renamed: a call
    # stopped at its limit brings back the last whole pack).
    if [ -n "${PACK_TO:-}" ]; then
      pack() { tar czf "$PACK_TO/.gpubench.tgz.part" -C "$(dirname "$out")" "$(basename "$out")" \
        && mv -f "$PACK_TO/.gpubench.tgz.part" "$PACK_TO/gpubench.tgz"; }
      (while sleep 20; do pack 2>/dev/null || true; done) &
      packer=$!
      trap 'kill "$packer" 2>/dev/null || true; pack || true' EXIT
    fi
    step() { echo "== $(date -u +%T) $*"; }
    # Most telling first: a call that runs past its limit still brings back what the
    # finished steps wrote (the networks' kernels, then the main matrix the other rows are
    # measured against, then the levers on it).
    step "networks (and where each spends its time: tract's nodes, the adapter's steps)"
    "$bin" bench nets --model fourier-small-seg2,fourier-medium --runtime tract,wgpu,wgpu-rows,wgpu-conv4 \
      --runs "$((runs * 4))" --profile --top 12 --out "$out"
    step "pipeline ($res; $models; threads $threads; the camera's view and a turned one)"
    # A turned view (yaw 30) runs the colour networks on the surface points (the colour MLP
    # through its row buckets); the camera's own view takes the input pixel's colour.
    # Its GPU rows at yaw 0 (the default split, one worker each, the render stage on a
    # device of its own, `auto`) are the baseline of the levers' rows below, in the same run.
    "$bin" bench pipeline --backend cpu,wgpu --runtime tract --model "$models" --res "$res" \
      --threads "$threads" --seconds "$secs" --warmup "$warm" --fps 1000 --yaw 0,30 --out "$out"
    step "the segmentation on a thread of its own, and the render and segment stages on 1 or 2 workers"
    # The third H200 run (devices/pipeline.md there, fourier-small at 257^3, the render stage
    # on its own device, 78.6 fps = 12.7 ms a frame) had two threads at about 10 ms a frame:
    # the field thread segmented too (segment 4.6 + field 5.3 ms: compute.segment_thread_up_to
    # is 129 by default, set for two CPU cores) and the render stage took 10.6 ms, of which
    # 1.6 ms was its work on the adapter, the rest waiting on its own read-backs. 120 fps needs
    # every thread under 8.3 ms: the segmentation on its own thread (--segment-thread-up-to
    # 513) and a second render worker (compute.render_workers: each its renderer and device,
    # frame N + 1 localized while N waits; frames published in capture order).
    # fourier-medium segments twice (10 ms a frame there): a second segment worker
    # (compute.segment_workers) segments frame N + 1 while N waits on its read-backs.
    # MODELS=SEGMENT_WORKERS=FOLDER per invocation (--short: the second segment worker only
    # where the segmentation runs twice).
    for w in $workers_rows; do
      IFS== read -r w_models w_segment w_dir <<<"$w"
      "$bin" bench pipeline --backend wgpu --model "$w_models" --res "$res" --threads "$threads" \
        --seconds "$secs" --warmup "$warm" --fps 1000 --segment-thread-up-to 513 \
        --render-workers 1,2 --segment-workers "$w_segment" --out "$out/$w_dir"
    done
    step "the segmentation's track: the whole frame every 8th frame, the person's crop alone between"
    # model.segment_full_every: one segmentation a frame instead of two (fourier-medium segments
    # twice: 10 ms a frame of the segment stage on the H200, 1.2 ms each run on the adapter);
    # its accuracy is docs/bench/segment-track/temporal.md (CPU, the same networks).
    "$bin" bench pipeline --backend wgpu --model "$models" --res "${track_res:-$res}" --threads "$threads" \
      --seconds "$secs" --warmup "$warm" --fps 1000 --segment-thread-up-to 513 \
      --segment-passes 2 --segment-full-every 1,8 --out "$out/track"
    step "the GPU backend's pipeline: the levels' conflict rounds read per round or predicted"
    # compute.round_waits: per-round (a read-back per round and level, some ten a frame) or
    # per-frame (each level's rounds predicted from the last frame, one read-back for the
    # levels; a frame the prediction fell short of runs again, its share in the note).
    # (--short: per-frame alone; the main matrix's GPU rows at yaw 0 are per-round, the default.)
    "$bin" bench pipeline --backend wgpu --model "$models" --res "$res" --threads "$threads" \
      --seconds "$secs" --warmup "$warm" --fps 1000 --round-waits "$round_waits" --out "$out/rounds"
    step "the series' K: 15 harmonics (fourier-small-seg2, the default) against 31 (fourier-small-k31, the issue's 'K = 31')"
    # The same encoder but for its last convolution (63 maps instead of 31): the maps' traffic,
    # the temporal filter and every field evaluation twice the terms.
    "$bin" bench pipeline --backend "$k31_backends" --runtime tract --model fourier-small-seg2,fourier-small-k31 --res "$res" \
      --threads "$threads" --seconds "$secs" --warmup "$warm" --fps 1000 --out "$out/k31"
    step "the GPU backend's pipeline from other coarse levels (issue 33 item 4: 'coarse levels')"
    # The default starts the levels at 9^3 (3); 5^3 (2) has fewer points a level and more
    # levels (more waits), 17^3 (4) more points and fewer levels.
    "$bin" bench pipeline --backend wgpu --model fourier-small --res "${res%%,*}" --threads "$threads" \
      --seconds "$secs" --warmup "$warm" --fps 1000 --coarse-level 2,3,4 --out "$out/coarse"
    step "the surface's dead band on the adapter ([temporal] surface_dead_band 0 against 0.06)"
    # A word a grid point read and written by every evaluation (gpu/localize/hold.rs): what
    # holding a still person's grid costs the render stage there (the sim's walk holds
    # stretches of frames; 0 is the renderer of the runs before 2026-12-03).
    "$bin" bench pipeline --backend wgpu --model fourier-medium --res "$res" --threads "$threads" \
      --seconds "$secs" --warmup "$warm" --fps 1000 --surface-dead-band 0,0.06 --out "$out/held"
    step "two stages on one device or two: the render stage on the networks' device or its own"
    # compute.render_device (`auto`, the default, is a second device on a GPU), the maps
    # crossing the host for the second; every model and resolution of the matrix (the third
    # H200 run measured fourier-small at 257^3 only: 49.8 -> 78.6 fps).
    "$bin" bench pipeline --backend wgpu --model "$models" --res "$res" --threads "$threads" \
      --seconds "$secs" --warmup "$warm" --fps 1000 --render-device shared,own --out "$out/devices"
    step "localization on the model's field"
    # The adapter's rows twice: a read-back per conflict round, and the rounds predicted.
    "$bin" bench localize --model fourier-small --backend "$loc_backends" --res "$res" \
      --methods hierarchical,hierarchical-tight --runs "$runs" --round-waits per-round,per-frame --out "$out"
    step "two stages on one device or two, the localization alone (bench queues)"
    # The localization timed alone, beside the shape network on its device, and on a second
    # device of the same adapter: how long a render device's work waits while another
    # device's runs (pipeline-gpu.md item 11; a few seconds a row).
    "$bin" bench queues --res "$qres" --seconds "$secs" --out "$out"
    mv "$out/accuracy-vs-time.md" "$out/localize.md"
    mv "$out/accuracy-vs-time.png" "$out/localize.png"
    ls -la "$out"
    ;;
  *)
    echo "usage: tools/gpu_bench.sh prepare | run [--quick | --short]" >&2
    exit 2
    ;;
esac
