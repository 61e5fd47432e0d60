#!/usr/bin/env bash
# Fetches the real head CT that Debian ships in `invesalius-examples`
# (Cranium.inv3: a gzip'd tar whose matrix.dat is int16 little-endian,
# shape (z, y, x) = (108, 256, 256), spacing 0.9570312 x 0.9570312 x 1.5 mm,
# values in HU) and writes DIR/cranium.raw plus the sidecar DIR/cranium.json.
#
# usage: tools/fetch-ct.sh DIR
set -euo pipefail
dir=${1:?usage: tools/fetch-ct.sh DIR}
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
if [ -s "$dir/cranium.json" ] && [ -s "$dir/cranium.raw" ]; then
    echo "fetch-ct: $dir/cranium.json already present"
    exit 0
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
# apt-get download needs package lists; refresh them once if it fails.
if ! apt-get download invesalius-examples >/dev/null 2>&1; then
    echo "fetch-ct: apt-get download failed; refreshing package lists" >&2
    if [ "$(id -u)" = 0 ]; then apt-get -o DPkg::Lock::Timeout=600 update -qq >&2; else sudo apt-get -o DPkg::Lock::Timeout=600 update -qq >&2; fi
    apt-get download invesalius-examples >&2 || {
        echo "fetch-ct: cannot download Debian package invesalius-examples" >&2
        exit 1
    }
fi
dpkg-deb -x invesalius-examples_*.deb pkg
inv3=$(find pkg -name Cranium.inv3 | head -n 1)
[ -n "$inv3" ] || { echo "fetch-ct: Cranium.inv3 not found in the package" >&2; exit 1; }
mkdir inv && tar -xzf "$inv3" -C inv
matrix=$(find inv -name matrix.dat | head -n 1)
[ -n "$matrix" ] || { echo "fetch-ct: matrix.dat not found in Cranium.inv3" >&2; exit 1; }
size=$(stat -c %s "$matrix")
want=$((108 * 256 * 256 * 2))
[ "$size" = "$want" ] || { echo "fetch-ct: matrix.dat is $size bytes, expected $want" >&2; exit 1; }
cp "$matrix" "$dir/cranium.raw.part"
mv "$dir/cranium.raw.part" "$dir/cranium.raw"
cat > "$dir/cranium.json.part" <<JSON
{
  "data": "cranium.raw",
  "dims": [256, 256, 108],
  "dtype": "i16",
  "endian": "little",
  "header_bytes": 0,
  "x": 0.9570312,
  "y": 0.9570312,
  "z": 1.5,
  "origin": [0, 0, 0]
}
JSON
mv "$dir/cranium.json.part" "$dir/cranium.json"
echo "fetch-ct: wrote $dir/cranium.raw and $dir/cranium.json"
