#!/usr/bin/env bash
# The paper's Fig. 16 scene rendered as a user renders it: one whole
# `cdvol render` process per image (file open, brick decode, tiles, PNG),
# 128^3 spheres (N^3 of them, iso 1000), 250 x 250, view 30,20, surface.
# Prints the CD/FVT ratio of whole-process CPU time (perf stat task-clock
# when perf works, else wall time), medians of REPS interleaved runs, and
# the split of `--stats` (decode, traverse, sample) of one run of each.
#
# usage: tools/bench-fig16-whole.sh [WORKDIR]   (NS="2 21", REPS=11,
#        BIN=path/to/cdvol to time another build, PREP_FLAGS="--aniso"
#        with CD=cd-aniso for the octant codes)
set -euo pipefail
work=${1:-target/bench-fig16}
mkdir -p "$work"
if [ -z "${BIN:-}" ]; then
    cargo build --profile release-lto --quiet
    BIN=target/release-lto/cdvol
fi
clock() { # command... -> seconds of CPU (task-clock) or wall
    if perf stat -x, -e task-clock true >/dev/null 2>&1; then
        perf stat -x, -e task-clock "$@" 2>&1 >/dev/null | awk -F, '/task-clock/ {printf "%.4f\n", $1 / 1000}'
    else
        local t0 t1; t0=$(date +%s.%N); "$@" >/dev/null 2>&1; t1=$(date +%s.%N)
        echo "$t1 - $t0" | bc -l
    fi
}
median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
printf '| N | FVT s | CD s | FVT/CD | FVT steps/ray | CD steps/ray | CD decode / traverse / sample / tiles s |\n|---|---|---|---|---|---|---|\n'
for n in ${NS:-2 21}; do
    "$BIN" phantom spheres -q --per-axis "$n" -o "$work/s$n.json" > /dev/null
    "$BIN" prep -q ${PREP_FLAGS:-} --iso 1000 "$work/s$n.json" -o "$work/s$n.cdv" > /dev/null
    : > "$work/fvt.txt"; : > "$work/${CD:-cd}.txt"
    for _ in $(seq "${REPS:-11}"); do
        for t in fvt ${CD:-cd}; do
            clock taskset -c 0 "$BIN" render -q "$work/s$n.cdv" -o "$work/$t.png" --width 250 --height 250 \
                --view 30,20 --traversal "$t" --threads 1 >> "$work/$t.txt"
        done
    done
    cmp "$work/fvt.png" "$work/${CD:-cd}.png"
    f=$(median < "$work/fvt.txt"); c=$(median < "$work/${CD:-cd}.txt")
    split=()
    for t in fvt ${CD:-cd}; do
        "$BIN" render -q "$work/s$n.cdv" -o "$work/$t.png" --width 250 --height 250 --view 30,20 \
            --traversal "$t" --threads 1 --stats "$work/$t.json" > /dev/null
        split+=("$(python3 -c "import json; d=json.load(open('$work/$t.json')); print('%.2f' % (d['steps'] / d['rays']))")")
    done
    cd_split=$(python3 -c "import json; d=json.load(open('$work/${CD:-cd}.json')); print('%.4f / %.4f / %.4f / %.4f' % tuple(d.get(k, float('nan')) for k in ('seconds_decode', 'seconds_traverse', 'seconds_sample', 'seconds_tiles')))")
    printf '| %s | %.4f | %.4f | %.2f | %s | %s | %s |\n' "$n" "$f" "$c" "$(echo "$f / $c" | bc -l)" "${split[0]}" "${split[1]}" "$cd_split"
done
