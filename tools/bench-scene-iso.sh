#!/usr/bin/env bash
# Render-time iso (`render --iso`, issue 16) against files prepared at
# each iso: surface renders at 1024^2, view 35,15, 1 thread, CD, from a
# file prepared at ENVELOPE (300) with --iso V, and from a file prepared at
# V, for V in ISOS (500 700 1000). Per row: cold frame (the first of a
# 3-frame run) and warm frame (median of the other two) `seconds_total`,
# medians over REPS (3) interleaved runs, the ratio envelope / own, and
# whether the PNGs are byte-identical.
#
# usage: tools/bench-scene-iso.sh VOLUME.json [WORKDIR]
#        env: BIN=path/to/cdvol ENVELOPE=300 ISOS="500 700 1000" REPS=3
set -euo pipefail
vol=$1
work=${2:-target/bench-scene-iso}
mkdir -p "$work"
if [ -z "${BIN:-}" ]; then
    cargo build --profile release-lto --quiet
    BIN=target/release-lto/cdvol
fi
env_iso=${ENVELOPE:-300}
"$BIN" prep -q --iso "$env_iso" "$vol" -o "$work/env.cdv" > /dev/null
frame() { # file png extra... -> "cold warm"
    local f=$1 png=$2; shift 2
    taskset -c 0 "$BIN" render -q "$f" -o "$png" --threads 1 --view 35,15 --width 1024 \
        --height 1024 --frames 3 --orbit 0 --stats "$work/s.json" "$@" > /dev/null
    python3 -c "import json, statistics as st; d = json.load(open('$work/s.json')); \
print(d[0]['seconds_total'], st.median(f['seconds_total'] for f in d[1:]))"
}
med() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
printf '| iso | envelope cold s | own cold s | ratio | envelope warm s | own warm s | ratio | same PNG |\n|---|---|---|---|---|---|---|---|\n'
for v in ${ISOS:-500 700 1000}; do
    "$BIN" prep -q --iso "$v" "$vol" -o "$work/own.cdv" > /dev/null
    : > "$work/e.txt"; : > "$work/o.txt"
    for _ in $(seq "${REPS:-3}"); do
        frame "$work/env.cdv" "$work/e.png" --iso "$v" >> "$work/e.txt"
        frame "$work/own.cdv" "$work/o.png" >> "$work/o.txt"
    done
    same=no
    for k in 0000 0001 0002; do cmp -s "$work/e.$k.png" "$work/o.$k.png" && same=yes || { same=no; break; }; done
    ec=$(cut -d' ' -f1 "$work/e.txt" | med); ew=$(cut -d' ' -f2 "$work/e.txt" | med)
    oc=$(cut -d' ' -f1 "$work/o.txt" | med); ow=$(cut -d' ' -f2 "$work/o.txt" | med)
    printf '| %s | %.3f | %.3f | %.2f | %.3f | %.3f | %.2f | %s |\n' "$v" "$ec" "$oc" \
        "$(echo "$ec / $oc" | bc -l)" "$ew" "$ow" "$(echo "$ew / $ow" | bc -l)" "$same"
done
