#!/usr/bin/env bash
# The README's label pictures from the real CT (tools/fetch-ct.sh): its
# threshold segmentation (`cdvol segment`: soft tissue translucent, bone,
# air spaces) drawn alone, and its bone and air spaces inside the CT's
# ct-skin composite (`render --overlay`).
#
# usage: tools/labels-demo.sh CT.json OUTDIR [CDVOL]
set -euo pipefail
ct=$1; out=$2; bin=${3:-target/release/cdvol}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
"$bin" -q segment "$ct" -o "$tmp/seg.json"
"$bin" -q prep --labels --lut "$tmp/seg.lut.json" "$tmp/seg.json" -o "$tmp/seg.cdv"
"$bin" -q prep --envelope ct "$ct" -o "$tmp/ct.cdv"
"$bin" -q render "$tmp/seg.cdv" --view 160,10 --width 512 --height 512 -o "$out/labels.png"
"$bin" -q render "$tmp/ct.cdv" --preset ct-skin --mode composite --overlay "$tmp/seg.cdv" \
    --labels bone,air-spaces --view 160,10 --width 512 --height 512 -o "$out/labels-over-ct.png"
