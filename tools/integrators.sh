#!/usr/bin/env bash
# The accuracy harness of the composite and MIP integrators (issue 54;
# docs/TRADEOFFS.md, "Integrators"): preps the real head CT (all CT
# presets' envelope) and the MR phantom, then runs examples/integrators.rs,
# which writes docs/integrators.csv and docs/integrators.svg and prints the
# table. Takes about 15 minutes on 2 cores at 256 x 256 (the f64
# reference is most of it).
#
# usage: tools/integrators.sh [SIZE]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
size=${1:-256}
work=target/integrators
mkdir -p "$work"
bash tools/fetch-ct.sh target/ct >&2
cargo build --release --quiet --bin cdvol --example integrators
bin=target/release/cdvol
[ -f "$work/ct.cdv" ] || "$bin" prep -q --envelope ct target/ct/cranium.json -o "$work/ct.cdv"
if [ ! -f "$work/mr.cdv" ]; then
    "$bin" phantom mr -q -o "$work/mr.json"
    "$bin" prep -q --envelope mr "$work/mr.json" -o "$work/mr.cdv"
fi
target/release/examples/integrators "$work/ct.cdv" "$work/mr.cdv" "$size" docs
