#!/usr/bin/env bash
# Whole-program render benchmark (docs/BENCHMARKS.md, "Rendering").
#  1. The real CT (tools/fetch-ct.sh), bone at 300 HU, 1024x1024 surface
#     renders from three views with FVT and CD: render seconds, rays/s,
#     steps per ray, bricks read; and peak RSS with --cache-mb 64 vs 4096.
#  2. The CT phantom at 256^3, 512^3 and 1024^3 (u16): the CD/FVT time
#     ratio as resolution grows.
# Each row's ratio comes from runs in the same invocation, back to back;
# render seconds are the minimum of REPS (default 3) runs.
#
# usage: tools/bench-render.sh [WORKDIR]   (SIZES="256 512 1024" to choose)
set -euo pipefail
work=${1:-target/bench-render}
mkdir -p "$work"
cargo build --profile release-lto --quiet
bin=target/release-lto/cdvol
tools/fetch-ct.sh target/ct >/dev/null
json() { python3 -c "import json,sys; d=json.load(open('$1')); print($2)"; }

render() { # file view traversal cache_mb -> prints "seconds steps/ray bricks rss_mib"
    # Render seconds are the minimum of REPS runs (default 3): the machine
    # is shared, and the minimum is the least disturbed figure.
    local f=$1 view=$2 t=$3 cache=$4 best=1e9
    for _ in $(seq "${REPS:-3}"); do
        /usr/bin/time -v "$bin" render -q "$f" -o "$work/out.png" --width 1024 --height 1024 \
            --view "$view" --traversal "$t" --cache-mb "$cache" --stats "$work/stats.json" \
            > /dev/null 2> "$work/time.txt"
        best=$(json "$work/stats.json" "min($best, d['seconds_total'])")
    done
    local rss; rss=$(grep 'Maximum resident set size' "$work/time.txt" | awk '{print $NF}')
    echo "$best $(json "$work/stats.json" "'%.2f %d/%d' % (d['steps']/d['rays'], d['bricks_read'], d['bricks_total'])") $((rss / 1024))"
}

echo "### Real CT (256x256x108 i16, bone at 300 HU), 1024x1024 surface, 2 threads"
echo
"$bin" prep -q --iso 300 target/ct/cranium.json -o "$work/ct.cdv" > /dev/null
printf '| view | FVT s | CD s | CD/FVT speed-up | FVT steps/ray | CD steps/ray | CD Mrays/s | bricks read | RSS MiB cache 64 / 4096 |\n|---|---|---|---|---|---|---|---|---|\n'
for view in 0,0 30,20 90,0; do
    read -r fs fst fb frss <<< "$(render "$work/ct.cdv" "$view" fvt 4096)"
    read -r cs cst cb crss <<< "$(render "$work/ct.cdv" "$view" cd 4096)"
    read -r _ _ _ srss <<< "$(render "$work/ct.cdv" "$view" cd 64)"
    printf '| %s | %.3f | %.3f | %.2f | %.1f | %.1f | %.2f | %s | %s / %s |\n' "$view" "$fs" "$cs" \
        "$(echo "$fs / $cs" | bc -l)" "$fst" "$cst" "$(echo "1.048576 / $cs" | bc -l)" "$cb" "$srss" "$crss"
done
echo
echo "### CT phantom (u16, bone at 300 HU), 1024x1024 surface, view 30,20, 2 threads"
echo
printf '| volume | FVT s | CD s | CD/FVT speed-up | FVT steps/ray | CD steps/ray | bricks read |\n|---|---|---|---|---|---|---|\n'
for n in ${SIZES:-256 512 1024}; do
    "$bin" phantom ct -q --dims "$n,$n,$n" --dtype u16 -o "$work/ph$n.json" > /dev/null
    "$bin" prep -q --iso 300 "$work/ph$n.json" -o "$work/ph$n.cdv" > /dev/null
    rm -f "$work/ph$n.raw"
    read -r fs fst fb _ <<< "$(render "$work/ph$n.cdv" 30,20 fvt 4096)"
    read -r cs cst cb _ <<< "$(render "$work/ph$n.cdv" 30,20 cd 4096)"
    printf '| %d^3 | %.3f | %.3f | %.2f | %.1f | %.1f | %s |\n' "$n" "$fs" "$cs" "$(echo "$fs / $cs" | bc -l)" "$fst" "$cst" "$cb"
    [ "${KEEP:-0}" = 1 ] || rm -f "$work/ph$n.cdv"
done
