#!/usr/bin/env bash
# The accuracy harness of the composite and MIP integrators (issue 54;
# docs/TRADEOFFS.md, "Integrators"): preps the real head CT (all CT
# presets' envelope) and the MR phantom, then runs examples/integrators.rs,
# which writes docs/integrators.csv and docs/integrators.svg and prints the
# table; then VTK through the same metrics (docs/integrators-vtk.csv).
# Takes about 20 minutes on 2 cores at 128 x 128 (the f64 reference is
# most of it).
#
# usage: tools/integrators.sh [SIZE]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
size=${1:-128}
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
# The references for VTK (tools/peers/vtk_integrators.py), which puts VTK
# through the same metrics when the peers' venv is there
# (tools/peers/install.sh VENV; PEERS_VENV, default target/peers/venv).
rm -rf "$work/export" && mkdir -p "$work/export"
INTEGRATORS_EXPORT="$work/export" target/release/examples/integrators \
    "$work/ct.cdv" "$work/mr.cdv" "$size" docs
venv=${PEERS_VENV:-target/peers/venv}
if "$venv/bin/python" -c 'import vtk' 2>/dev/null; then
    rm -f docs/integrators-vtk.csv
    "$venv/bin/python" tools/peers/vtk_integrators.py "$work/export" docs/integrators-vtk.csv
    target/release/examples/integrators --plot docs
else
    echo "no VTK in $venv (tools/peers/install.sh $venv): VTK left out" >&2
fi
