#!/usr/bin/env bash
# Fault figures for docs/RELIABILITY.md ("Truncations, kills and
# concurrent renders"), from the release binary on a CT phantom:
#  - truncations: the packed file cut at N evenly spaced lengths (and at
#    every length within 64 bytes of each end); each must be refused by
#    `info` or `render` with an error naming the file, or (never) render;
#  - kills: `prep` SIGKILLed at 20 points in its run; the output name must
#    never hold a partial file, and a re-run must give the same bytes;
#  - concurrent renders: 24 renders at once with caches of 1 MiB, each
#    byte-identical to a single render.
#
# usage: tools/reliability.sh [WORKDIR]   (env BIN=path/to/cdvol)
set -euo pipefail
work=${1:-target/reliability}
rm -rf "$work"; mkdir -p "$work"
if [ -z "${BIN:-}" ]; then cargo build --release --quiet; BIN=target/release/cdvol; fi
"$BIN" phantom ct -q --dims 256,256,200 -o "$work/h.json" > /dev/null
"$BIN" prep -q --iso 300 "$work/h.json" -o "$work/h.cdv" > /dev/null
"$BIN" render -q "$work/h.cdv" -o "$work/want.png" --width 96 --height 96 > /dev/null
size=$(stat -c %s "$work/h.cdv")

# Truncations.
lens=$(python3 -c "
n=$size; s=set(range(0, n, max(1, n // 200))); s |= set(range(0, 64)); s |= set(range(n - 64, n)); print(' '.join(map(str, sorted(s))))")
refused=0 named=0 rendered=0 panics=0 total=0
for L in $lens; do
    total=$((total + 1))
    head -c "$L" "$work/h.cdv" > "$work/t.cdv"
    if err=$("$BIN" render -q "$work/t.cdv" -o "$work/t.png" --width 32 --height 32 2>&1 >/dev/null); then
        rendered=$((rendered + 1))
    else
        refused=$((refused + 1))
        case $err in *t.cdv*) named=$((named + 1));; esac
        case $err in *panicked*) panics=$((panics + 1));; esac
    fi
done
echo "truncations: $total lengths of $size bytes; refused $refused (naming the file: $named), rendered $rendered, panics $panics"

# Kills during prep.
"$BIN" prep -q --iso 300 "$work/h.json" -o "$work/k-want.cdv" > /dev/null
t0=$(date +%s.%N); "$BIN" prep -q --iso 300 "$work/h.json" -o "$work/k-time.cdv" > /dev/null; t1=$(date +%s.%N)
dur=$(echo "$t1 - $t0" | bc -l)
partial_under_name=0 identical=0 finished=0
for i in $(seq 1 20); do
    rm -f "$work/k.cdv"
    "$BIN" prep -q --iso 300 "$work/h.json" -o "$work/k.cdv" > /dev/null 2>&1 &
    pid=$!
    sleep "$(echo "$dur * $i / 21" | bc -l)"
    kill -9 "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    if [ -e "$work/k.cdv" ]; then
        if cmp -s "$work/k.cdv" "$work/k-want.cdv"; then
            finished=$((finished + 1))
        else
            partial_under_name=$((partial_under_name + 1))
        fi
    fi
    "$BIN" prep -q --iso 300 "$work/h.json" -o "$work/k.cdv" > /dev/null
    cmp -s "$work/k.cdv" "$work/k-want.cdv" && identical=$((identical + 1))
done
echo "kills: 20 runs, SIGKILL at 1/21 .. 20/21 of a $(printf %.2f "$dur") s prep; finished before the kill $finished; partial files under the output name $partial_under_name; re-runs byte-identical $identical of 20"

left=$(find "$work" -maxdepth 1 -name '.cdvol-partial-*' | wc -l)
echo "kills: $left hidden partial files of killed runs are left beside the output; a write into the directory removes them once they are 60 s old and their process is gone"

# Concurrent renders with tiny caches.
pids=()
for i in $(seq 1 24); do
    "$BIN" render -q "$work/h.cdv" -o "$work/c$i.png" --width 96 --height 96 --cache-mb 1 --threads 1 > /dev/null &
    pids+=($!)
done
for p in "${pids[@]}"; do wait "$p"; done
same=0
for i in $(seq 1 24); do cmp -s "$work/c$i.png" "$work/want.png" && same=$((same + 1)); done
echo "concurrent renders: 24 at once with 1 MiB caches; byte-identical to a single render: $same of 24"
