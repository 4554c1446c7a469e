#!/usr/bin/env bash
# Install volcapd as an appliance service: binary, systemd unit, D-Bus policy and
# interface XML, sysusers entry, the board config, scenes and models.
#
#   tools/install.sh [--root DIR] [--board NAME] [--binary PATH] [--features LIST] [--force]
#
#   --root DIR      install under DIR (a staging root, as for packaging and tests); default /
#   --board NAME    board-config/NAME.toml becomes /etc/volcap/volcapd.toml (default: sim)
#   --binary PATH   install this volcapd instead of building one
#   --features L    cargo features for the build (default: appliance, i.e. v4l2, rtsp and wgpu)
#   --force         overwrite an existing /etc/volcap/volcapd.toml
#
# Paths inside the installed config point at the final locations (/usr/share/volcap/...).
# With --root / (as root) it also creates the service user and reloads systemd.
set -euo pipefail
cd "$(dirname "$0")/.."

root=/ board=sim binary= features=appliance force=0
while [ $# -gt 0 ]; do
  case "$1" in
    --root) root="$2"; shift 2 ;;
    --board) board="$2"; shift 2 ;;
    --binary) binary="$2"; shift 2 ;;
    --features) features="$2"; shift 2 ;;
    --force) force=1; shift ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *) echo "install.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
[ -f "board-config/$board.toml" ] || { echo "install.sh: no board-config/$board.toml" >&2; exit 2; }

# The packages the features need: to build (headers) and to run (GStreamer's encoders,
# RTSP server and client plugins); installed on a real root with apt, named otherwise.
pkgs=
case ",$features," in *,appliance,*|*,v4l2,*) pkgs="$pkgs libclang-dev" ;; esac
case ",$features," in
  *,appliance,*|*,rtsp,*)
    pkgs="$pkgs libgstreamer1.0-dev libgstreamer-plugins-base1.0-dev libgstrtspserver-1.0-dev \
      gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-ugly \
      gstreamer1.0-plugins-bad gstreamer1.0-rtsp" ;;
esac
# The GPU backend loads Vulkan at run time (the board's driver provides the adapter).
case ",$features," in *,appliance,*|*,wgpu,*) pkgs="$pkgs libvulkan1" ;; esac
if [ -n "$pkgs" ]; then
  if [ "$root" = / ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $pkgs >/dev/null
  else
    echo "install.sh: features $features need these Debian packages:$pkgs" >&2
  fi
fi

if [ -z "$binary" ]; then
  cargo build --release -p volcapd --features "$features"
  binary=target/release/volcapd
fi
[ -x "$binary" ] || { echo "install.sh: $binary is not an executable" >&2; exit 2; }

share="$root/usr/share/volcap"
install -D -m 0755 "$binary" "$root/usr/bin/volcapd"
install -D -m 0644 systemd/volcapd.service "$root/usr/lib/systemd/system/volcapd.service"
install -D -m 0644 systemd/org.volcap.Capture1.conf "$root/usr/share/dbus-1/system.d/org.volcap.Capture1.conf"
install -D -m 0644 systemd/org.volcap.Capture1.xml "$root/usr/share/dbus-1/interfaces/org.volcap.Capture1.xml"
install -D -m 0644 systemd/volcap.sysusers "$root/usr/lib/sysusers.d/volcap.conf"
install -d -m 0755 "$share/board-config" "$share/scenes" "$share/models"
install -m 0644 board-config/*.toml "$share/board-config/"
install -m 0644 tests/scenes/*.toml "$share/scenes/"
if compgen -G "models/*" >/dev/null; then cp -r models/. "$share/models/"; fi
# ONNX Runtime's library for `compute.runtime` (tools/onnxruntime.sh fetches the pinned
# wheel's; without it the daemon runs its networks on tract).
[ -f target/onnxruntime/libonnxruntime.so ] || tools/onnxruntime.sh --optional
if [ -f target/onnxruntime/libonnxruntime.so ]; then
  ort="$root/usr/lib/volcap/onnxruntime"
  install -d -m 0755 "$ort"
  cp -P target/onnxruntime/libonnxruntime.so* "$ort/"
  install -m 0644 target/onnxruntime/LICENSE target/onnxruntime/ThirdPartyNotices.txt \
    target/onnxruntime/SOURCE "$ort/"
fi
install -D -m 0644 README.md "$root/usr/share/doc/volcap/README.md"

# The board config, with its relative paths pointed at the installed copies.
etc="$root/etc/volcap/volcapd.toml"
if [ -e "$etc" ] && [ "$force" = 0 ]; then
  echo "install.sh: keeping the existing $etc (--force replaces it)"
else
  install -d -m 0755 "$root/etc/volcap"
  sed -e 's#"\.\./tests/scenes/#"/usr/share/volcap/scenes/#' \
      -e 's#"\.\./models"#"/usr/share/volcap/models"#' \
      -e 's#"\.\./models/#"/usr/share/volcap/models/#' \
      "board-config/$board.toml" > "$etc"
  chmod 0644 "$etc"
fi

if [ "$root" = / ] && [ "$(id -u)" = 0 ]; then
  command -v systemd-sysusers >/dev/null && systemd-sysusers
  command -v systemctl >/dev/null && systemctl daemon-reload || true
  echo "installed; start with: systemctl enable --now volcapd"
else
  echo "installed under $root"
fi
