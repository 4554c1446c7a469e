#!/usr/bin/env bash
# Fetch ONNX Runtime's shared library for volcap's `[compute] runtime = "onnxruntime"`
# (or "auto"), from the pinned `onnxruntime` wheel on PyPI: the file is checked against its
# pinned SHA-256, and only the C library and its licence texts are kept.
#
#   tools/onnxruntime.sh [--dest DIR] [--optional]
#
#   --dest DIR    where to put it (default target/onnxruntime, where volcap and volcapd look
#                 in a checkout; tools/install.sh copies it to /usr/lib/volcap/onnxruntime)
#   --optional    a failed download is a warning, not an error (volcapd then runs on tract)
#
# Dependency record: ONNX Runtime 1.32.0, MIT licence (Microsoft), the CPU build of the
# PyPI wheel `onnxruntime==1.32.0` (cp311, manylinux_2_28; the C library inside does not
# depend on Python). Leaves DIR/libonnxruntime.so -> libonnxruntime.so.1.32.0, LICENSE,
# ThirdPartyNotices.txt and SOURCE (the wheel's URL and hash). Nothing is fetched at build
# or run time: without this library volcap runs its networks on tract.
set -euo pipefail
cd "$(dirname "$0")/.."

dest=target/onnxruntime optional=0
while [ $# -gt 0 ]; do
  case "$1" in
    --dest) dest="$2"; shift 2 ;;
    --optional) optional=1; shift ;;
    -h|--help) sed -n '2,17p' "$0"; exit 0 ;;
    *) echo "onnxruntime.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done

version=1.32.0
case "$(uname -m)" in
  x86_64)
    url=https://files.pythonhosted.org/packages/1d/46/e6f356c9539d2eed44126de3421a81e217da2ad91b22dc11b379cb1e384f/onnxruntime-1.32.0-cp311-cp311-manylinux_2_28_x86_64.whl
    sha=5a34fc4dfeb5a7b4a74c95dcba1e773d722abda720b474edf1b0c419dc6d163d ;;
  aarch64)
    url=https://files.pythonhosted.org/packages/b7/30/103820b32e9dc1d1fcfc5b519fd2de5bd699d25a25895caf5d726350d1b5/onnxruntime-1.32.0-cp311-cp311-manylinux_2_28_aarch64.whl
    sha=2303372a85299b6757b0e11e1cbf13e410ddf7e10c37f4b37e99d1c90e7daf7c ;;
  *)
    echo "onnxruntime.sh: no pinned wheel for $(uname -m); volcap runs on tract" >&2
    [ "$optional" = 1 ] && exit 0 || exit 1 ;;
esac

lib="$dest/libonnxruntime.so.$version"
if [ -f "$lib" ] && [ -f "$dest/SOURCE" ] && grep -q "$sha" "$dest/SOURCE"; then
  echo "onnxruntime.sh: $lib is already there"
  exit 0
fi

fail() {
  echo "onnxruntime.sh: $*" >&2
  if [ "$optional" = 1 ]; then
    echo "onnxruntime.sh: continuing without it: volcap runs its networks on tract" >&2
    exit 0
  fi
  exit 1
}

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
wheel="$tmp/$(basename "$url")"
echo "onnxruntime.sh: fetching $(basename "$url") (28 MB) from PyPI"
curl -fsSL --retry 3 -o "$wheel" "$url" || fail "cannot download $url"
echo "$sha  $wheel" | sha256sum -c --quiet - || fail "$(basename "$url"): SHA-256 differs from the pinned $sha"
python3 - "$wheel" "$tmp" "$version" <<'EOF' || fail "cannot unpack $(basename "$url")"
import sys, zipfile
wheel, out, version = sys.argv[1:]
with zipfile.ZipFile(wheel) as z:
    for name, to in [
        (f"onnxruntime/capi/libonnxruntime.so.{version}", f"libonnxruntime.so.{version}"),
        ("onnxruntime/LICENSE", "LICENSE"),
        ("onnxruntime/ThirdPartyNotices.txt", "ThirdPartyNotices.txt"),
    ]:
        with open(f"{out}/{to}", "wb") as f:
            f.write(z.read(name))
EOF
mkdir -p "$dest"
install -m 0644 "$tmp/libonnxruntime.so.$version" "$lib"
install -m 0644 "$tmp/LICENSE" "$tmp/ThirdPartyNotices.txt" "$dest/"
ln -sf "libonnxruntime.so.$version" "$dest/libonnxruntime.so"
printf 'onnxruntime %s (MIT)\n%s\nsha256 %s\n' "$version" "$url" "$sha" > "$dest/SOURCE"
echo "onnxruntime.sh: installed $lib"
