#!/usr/bin/env bash
# First frame against warm frame (docs/BENCHMARKS.md, "First frame: brick
# decode (issue 15)"). Each run is a two-frame turntable at one view
# (`--frames 2 --orbit 0`, one process, one cache): frame 0 decodes every
# brick it needs (cold), frame 1 finds them all in the cache (warm).
# Binaries are run interleaved, REPS times each; the table gives medians
# of the per-frame `seconds_total` and the bricks read by frame 0.
#
# usage: tools/bench-first-frame.sh WORKDIR BIN... 
#   env: SIZES="256 512 1024" (phantoms WORKDIR/phN.cdv, made if missing),
#        TRAV="cd fvt", REPS=5, THREADS=1, EXTRA="" (more render flags,
#        e.g. "--cd-lazy-min 4"), SIZE=1024 (image edge)
set -euo pipefail
work=$1
shift
bins=("$@")
mkdir -p "$work"
for n in ${SIZES:-256 512 1024}; do
    if [ ! -f "$work/ph$n.cdv" ]; then
        "${bins[0]}" phantom ct -q --dims "$n,$n,$n" --dtype u16 -o "$work/ph$n.json" > /dev/null
        "${bins[0]}" prep -q --iso 300 "$work/ph$n.json" -o "$work/ph$n.cdv" > /dev/null
        rm -f "$work/ph$n.raw"
    fi
done
run() { # bin file traversal -> "cold warm bricks_read"
    "$1" render -q "$2" -o "$work/ff.png" --width "${SIZE:-1024}" --height "${SIZE:-1024}" \
        --view 30,20 --threads "${THREADS:-1}" --frames 2 --orbit 0 --traversal "$3" \
        ${EXTRA:-} --stats "$work/ff.json" > /dev/null
    python3 -c "import json; d=json.load(open('$work/ff.json')); print(d[0]['seconds_total'], d[1]['seconds_total'], d[0]['bricks_read'])"
}
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
printf '| volume | traversal | binary | cold s | warm s | cold/warm | bricks read |\n|---|---|---|---|---|---|---|\n'
for n in ${SIZES:-256 512 1024}; do
    for t in ${TRAV:-cd fvt}; do
        rm -f "$work"/ff.*.txt
        for _ in $(seq "${REPS:-5}"); do
            for i in "${!bins[@]}"; do
                run "${bins[$i]}" "$work/ph$n.cdv" "$t" >> "$work/ff.$i.txt"
            done
        done
        for i in "${!bins[@]}"; do
            c=$(cut -d' ' -f1 "$work/ff.$i.txt" | median)
            w=$(cut -d' ' -f2 "$work/ff.$i.txt" | median)
            b=$(cut -d' ' -f3 "$work/ff.$i.txt" | median)
            printf '| %d^3 | %s | %s | %.3f | %.3f | %.2f | %s |\n' "$n" "$t" "${bins[$i]}" "$c" "$w" \
                "$(echo "$c / $w" | bc -l)" "$b"
        done
    done
done
