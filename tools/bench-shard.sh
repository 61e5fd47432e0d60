#!/usr/bin/env bash
# Sharded render cost: renders VOL whole, then as N shards one after the
# other (as N workers would, each alone on its node) with each shard
# layout, and prints per layout: the slowest shard (the sharded render's
# wall time on N idle workers), the sum over shards (its CPU bill), and the
# bricks they read (sum of distinct per shard, and all reads), against the
# whole render. Checks that the assembled image equals the whole one.
#
# usage: tools/bench-shard.sh VOL.cdv [N] [render options...]
#   default options: --width 2048 --height 2048 --view 30,20 --cache-mb 1024
set -euo pipefail
vol=$(realpath "$1"); n=${2:-4}; shift $(( $# >= 2 ? 2 : 1 ))
opts=("$@")
[ ${#opts[@]} -gt 0 ] || opts=(--width 2048 --height 2048 --view "30,20" --cache-mb 1024)
cd "$(dirname "$0")/.."
cargo build --profile release-lto --quiet
bin=$(realpath target/release-lto/cdvol)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# one NAME ARGS...: runs a render, prints "wall distinct reads".
one() {
    local name=$1; shift
    /usr/bin/time -f %e -o "$work/$name.t" "$bin" render -q "$vol" "${opts[@]}" --stats "$work/$name.json" "$@" > /dev/null
    python3 -c 'import json,sys; d = json.load(open(sys.argv[1]));
print(open(sys.argv[2]).read().strip(), d["bricks_distinct"], d["bricks_read"])' "$work/$name.json" "$work/$name.t"
}

read -r w_wall w_dist w_reads < <(one whole -o "$work/whole.png")
printf '| layout | N | slowest shard s | sum of shards s | whole s | slowest/whole | sum/whole | distinct bricks, sum over shards | brick reads, sum | whole: distinct / reads |\n'
printf '|---|---|---|---|---|---|---|---|---|---|\n'
for layout in interleaved blocks; do
    max=0; sum=0; dist=0; reads=0; parts=()
    for k in $(seq 0 $((n - 1))); do
        read -r t d r < <(one "$layout.$k" -o "$work/$layout.$k.cdvpart" --shard "$k/$n" --shard-layout "$layout")
        max=$(echo "if ($t > $max) $t else $max" | bc -l); sum=$(echo "$sum + $t" | bc -l)
        dist=$((dist + d)); reads=$((reads + r)); parts+=("$work/$layout.$k.cdvpart")
    done
    "$bin" assemble "${parts[@]}" -o "$work/$layout.png" > /dev/null
    cmp -s "$work/whole.png" "$work/$layout.png" || { echo "bench-shard: $layout assembles to a different image" >&2; exit 1; }
    printf '| %s | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %d | %d | %d / %d |\n' "$layout" "$n" "$max" "$sum" "$w_wall" \
        "$(echo "$max / $w_wall" | bc -l)" "$(echo "$sum / $w_wall" | bc -l)" "$dist" "$reads" "$w_dist" "$w_reads"
done
