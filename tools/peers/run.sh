#!/usr/bin/env bash
# cdvol against the tools users would otherwise pick, on the real head CT,
# same view and image size, in one run (docs/peers/PEERS.md):
#   surface    cdvol  vs  OpenVDB vdb_render (CT -> level set by vdb_tool -iso2ls)
#   composite  cdvol  vs  VTK vtkFixedPointVolumeRayCastMapper
#   mip        cdvol  vs  VTK vtkFixedPointVolumeRayCastMapper (MIP blend)
# at 1 and 2 threads, setup (prep / conversion / load) timed apart from the
# render; medians of REPS interleaved repeats. Installs the peers itself.
# Not part of CI.
#
# usage: tools/peers/run.sh [WORKDIR]   env: REPS=5 SIZE=512 THREADS=1,2 VIEW=35,15
#        CDVOL=/path/to/cdvol (default: cargo build --profile release-lto, copied into WORKDIR)
#        OUT=docs/peers (where the CSVs, PNGs and RESULTS.md go)
#        CT_SIDECAR=path/to/volume.json (another raw volume instead of the CT,
#        e.g. a `cdvol phantom ct --dims 512,512,512` phantom)
#        PREP_FLAGS="--aniso" (more `cdvol prep` flags for the packed files)
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
work=$(mkdir -p "${1:-$root/target/peers}" && cd "${1:-$root/target/peers}" && pwd)
out=${OUT:-$root/docs/peers}
"$root/tools/peers/install.sh" "$work/venv"
ct=$root/target/ct
if [ -n "${CT_DIR:-}" ]; then ct=$CT_DIR; fi
sidecar=${CT_SIDECAR:-$ct/cranium.json}
[ -n "${CT_SIDECAR:-}" ] || [ -f "$ct/cranium.json" ] || "$root/tools/fetch-ct.sh" "$ct" >/dev/null
if [ -z "${CDVOL:-}" ]; then
    (cd "$root" && cargo build --profile release-lto --quiet)
    tdir=${CARGO_TARGET_DIR:-$root/target}
    cp "$tdir/release-lto/cdvol" "$work/cdvol"   # private copy: later builds can't change it mid-run
    CDVOL=$work/cdvol
fi
"$CDVOL" --version >&2
"$work/venv/bin/python" "$root/tools/peers/bench.py" --cdvol "$CDVOL" --ct "$sidecar" \
    --work "$work" --out "$out" --reps "${REPS:-5}" --size "${SIZE:-512}" \
    --threads "${THREADS:-1,2}" "--view=${VIEW:-35,15}" "--prep-flags=${PREP_FLAGS:-}"
