#!/usr/bin/env bash
# First frame against warm frame (docs/BENCHMARKS.md, "First frame: brick
# decode (issue 15)"). Each run is a two-frame turntable at one view
# (`--frames 2 --orbit 0`, one process, one cache): frame 0 decodes every
# brick it needs (cold), frame 1 finds them all in the cache (warm).
# Binaries are run interleaved, REPS times each; the table gives medians
# of the per-frame `seconds_total`, the bricks read by frame 0, its decode
# seconds and its system (kernel) seconds (`seconds_system`: mostly the
# clearing of fresh pages for the decoded bricks, docs/BENCHMARKS.md,
# "The kernel's share of the first frame"; "-" from builds without it).
#
# IDLE=S sleeps S seconds before each run, as a user's first look at a
# volume follows idle time: on a virtual machine whose host takes back the
# guest's free memory (free page reporting), fresh huge pages then cost
# several times more to clear than in back-to-back runs (docs/BENCHMARKS.md,
# "Huge pages only while they are fast").
#
# usage: tools/bench-first-frame.sh WORKDIR BIN... 
#   env: SIZES="256 512 1024" (phantoms WORKDIR/phN.cdv, made if missing),
#        TRAV="cd fvt", REPS=5, THREADS=1, EXTRA="" (more render flags,
#        e.g. "--cd-lazy-min 4"), SIZE=1024 (image edge),
#        VERSIONS="" (e.g. "2 3": each phantom also prepared by the first
#        binary with `--format-version V` as WORKDIR/phN-vV.cdv, and every
#        binary renders every version, interleaved)
set -euo pipefail
work=$1
shift
bins=("$@")
mkdir -p "$work"
for n in ${SIZES:-256 512 1024}; do
    if [ ! -f "$work/ph$n.cdv" ]; then
        "${bins[0]}" phantom ct -q --dims "$n,$n,$n" --dtype u16 -o "$work/ph$n.json" > /dev/null
        "${bins[0]}" prep -q --iso 300 "$work/ph$n.json" -o "$work/ph$n.cdv" > /dev/null
    fi
    for v in ${VERSIONS:-}; do
        if [ ! -f "$work/ph$n-v$v.cdv" ]; then
            [ -f "$work/ph$n.raw" ] ||
                "${bins[0]}" phantom ct -q --dims "$n,$n,$n" --dtype u16 -o "$work/ph$n.json" > /dev/null
            "${bins[0]}" prep -q --iso 300 --format-version "$v" "$work/ph$n.json" \
                -o "$work/ph$n-v$v.cdv" > /dev/null
        fi
    done
    rm -f "$work/ph$n.raw"
done
# The runs: every binary on the default file, or on every version's file.
cases=()
for i in "${!bins[@]}"; do
    if [ -z "${VERSIONS:-}" ]; then
        cases+=("$i:")
    else
        for v in $VERSIONS; do cases+=("$i:-v$v"); done
    fi
done
run() { # bin file traversal -> "cold warm bricks_read cold_decode cold_system"
    sleep "${IDLE:-0}"
    "$1" render -q "$2" -o "$work/ff.png" --width "${SIZE:-1024}" --height "${SIZE:-1024}" \
        --view 30,20 --threads "${THREADS:-1}" --frames 2 --orbit 0 --traversal "$3" \
        ${EXTRA:-} --stats "$work/ff.json" > /dev/null
    python3 -c "import json; d=json.load(open('$work/ff.json')); print(d[0]['seconds_total'], d[1]['seconds_total'], d[0]['bricks_read'], d[0]['seconds_decode'], d[0].get('seconds_system', 'nan'))"
}
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
printf '| volume | traversal | binary | file | cold s | warm s | cold/warm | bricks read | cold decode s | cold system s |\n|---|---|---|---|---|---|---|---|---|---|\n'
for n in ${SIZES:-256 512 1024}; do
    for t in ${TRAV:-cd fvt}; do
        rm -f "$work"/ff.*.txt
        for _ in $(seq "${REPS:-5}"); do
            for k in "${!cases[@]}"; do
                i=${cases[$k]%%:*}
                run "${bins[$i]}" "$work/ph$n${cases[$k]#*:}.cdv" "$t" >> "$work/ff.$k.txt"
            done
        done
        for k in "${!cases[@]}"; do
            i=${cases[$k]%%:*}
            c=$(cut -d' ' -f1 "$work/ff.$k.txt" | median)
            w=$(cut -d' ' -f2 "$work/ff.$k.txt" | median)
            b=$(cut -d' ' -f3 "$work/ff.$k.txt" | median)
            dc=$(cut -d' ' -f4 "$work/ff.$k.txt" | median)
            sy=$(cut -d' ' -f5 "$work/ff.$k.txt" | median)
            [ "$sy" = nan ] && sy=- || sy=$(printf '%.3f' "$sy")
            printf '| %d^3 | %s | %s | ph%d%s.cdv | %.3f | %.3f | %.2f | %s | %.3f | %s |\n' "$n" "$t" "${bins[$i]}" \
                "$n" "${cases[$k]#*:}" "$c" "$w" "$(echo "$c / $w" | bc -l)" "$b" "$dc" "$sy"
        done
    done
done
