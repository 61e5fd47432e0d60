#!/usr/bin/env bash
# Renders the reference images of tests/reference/ with the CLI: the real
# head CT and a small CT-like phantom, each as a shaded surface, a MIP and
# a skin-and-bone composite (tests/reference/skin-bone-tf.json), unshaded and
# shaded, plus the
# cost maps of CD and the octree.
#
#   CDVOL=path/to/cdvol tools/bless-references.sh [OUT_DIR]
#
# OUT_DIR defaults to tests/reference. The test `reference` (tests/all/
# reference.rs) runs this same script with the binary under test into a
# temporary directory and compares each PNG with the one here, so bless
# only with a build whose images you mean to keep (see
# tests/reference/README.md). The real CT is fetched by tools/fetch-ct.sh
# into target/ct on first use (CT=path/to/cranium.json to use another copy).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cdvol=${CDVOL:?set CDVOL to the cdvol binary to bless with}
out=${1:-$root/tests/reference}
ct=${CT:-$root/target/ct/cranium.json}
tf=$root/tests/reference/skin-bone-tf.json

if [ ! -f "$ct" ]; then
    bash "$root/tools/fetch-ct.sh" "$(dirname "$ct")"
fi
mkdir -p "$out"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Inputs: the CT and the phantom, each prepared by iso value (surface, MIP)
# and by the transfer function (composite).
"$cdvol" phantom ct -q --dims 64,64,40 --z-scale 4 --seed 3 -o "$work/phantom.json"
for name in ct phantom; do
    if [ "$name" = ct ]; then src=$ct; else src=$work/phantom.json; fi
    "$cdvol" prep -q "$src" -o "$work/$name-iso.cdv" --iso 300 --brick 16
    "$cdvol" prep -q "$src" -o "$work/$name-tf.cdv" --classify-tf "$tf" --brick 16
done

# Renders: 128x128 for the CT, 96x96 for the phantom.
for name in ct phantom; do
    if [ "$name" = ct ]; then size=128; else size=96; fi
    common=(--width "$size" --height "$size" --view 120,10 --threads 2 -q)
    "$cdvol" render "$work/$name-iso.cdv" -o "$out/$name-surface.png" \
        --mode surface --shadows --normals cell "${common[@]}"
    "$cdvol" render "$work/$name-iso.cdv" -o "$out/$name-mip.png" \
        --mode mip --window full "${common[@]}"
    "$cdvol" render "$work/$name-tf.cdv" -o "$out/$name-composite.png" \
        --mode composite --tf "$tf" "${common[@]}"
    # Shaded, with smooth normals (the vertex gradients of every sampled
    # cell, render/sample/normals.rs).
    "$cdvol" render "$work/$name-tf.cdv" -o "$out/$name-composite-shaded.png" \
        --mode composite --tf "$tf" --shade "${common[@]}"
    # Traversal cost maps (paper Fig. 17): steps per pixel of CD and of
    # the octree, so a change in any walker's steps shows as a picture.
    # CD's stand-in threshold is given: by default it follows the rays'
    # density (16 or 4), and these maps pin the walk at 16.
    "$cdvol" render "$work/$name-iso.cdv" -o "$out/$name-cost-cd.png" \
        --mode cost --traversal cd --cd-lazy-min 16 "${common[@]}"
    "$cdvol" render "$work/$name-iso.cdv" -o "$out/$name-cost-octree.png" \
        --mode cost --traversal octree "${common[@]}"
done
