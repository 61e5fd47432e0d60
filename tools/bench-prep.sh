#!/usr/bin/env bash
# Whole-program prep benchmark: generates CT-like raw volumes of
# 1024 x 1024 x 2048 u16 (4 GiB) and of half that depth with
# `cdvol phantom ct`, then for each, in the same run:
#   * reads the page-cached input with `cat INPUT > /dev/null` (baseline MB/s),
#   * runs `cdvol prep --iso 300` under /usr/bin/time -v (wall, MB/s, peak RSS).
# Prints one markdown table row per volume. Needs ~4 + 2 GiB for inputs, up
# to 2 GiB of spill and the outputs; deletes them unless KEEP=1.
#
# usage: tools/bench-prep.sh [WORKDIR] [NX NY NZ...]
set -euo pipefail
work=${1:-target/bench-prep}
nx=${NX:-1024}; ny=${NY:-1024}; depths=${DEPTHS:-"1024 2048"}
mkdir -p "$work"
cargo build --profile release-lto --quiet
bin=target/release-lto/cdvol
need=$(( (nx * ny * 2048 * 2 * 5 / 2) / 1024 / 1024 / 1024 + 1 ))
free=$(df -Pk "$work" | awk 'NR==2 {print int($4 / 1024 / 1024)}')
echo "bench-prep: needs about ${need} GiB free in $work, ${free} GiB available" >&2
[ "$free" -ge "$need" ] || { echo "bench-prep: not enough disk" >&2; exit 1; }

printf '| volume | input MiB | cat MB/s | prep s | prep MB/s | prep/cat | peak RSS MiB | output MiB | 1-cells |\n'
printf '|---|---|---|---|---|---|---|---|---|\n'
for nz in $depths; do
    side="$work/ct-$nz.json"
    "$bin" phantom ct -q --dims "$nx,$ny,$nz" --dtype u16 -o "$side" >/dev/null
    raw="$work/ct-$nz.raw"
    bytes=$(stat -c %s "$raw")
    cat "$raw" > /dev/null   # warm the page cache
    t0=$(date +%s.%N); cat "$raw" > /dev/null; t1=$(date +%s.%N)
    cat_mbs=$(echo "$bytes / ($t1 - $t0) / 1000000" | bc -l)
    out="$work/ct-$nz.cdv"
    /usr/bin/time -v "$bin" prep -q --iso 300 "$side" -o "$out" > "$work/prep-$nz.out" 2> "$work/prep-$nz.time"
    wall=$(grep 'Elapsed (wall clock)' "$work/prep-$nz.time" | awk '{print $NF}' | awk -F: '{ if (NF == 3) print $1*3600 + $2*60 + $3; else print $1*60 + $2 }')
    rss=$(grep 'Maximum resident set size' "$work/prep-$nz.time" | awk '{print $NF}')
    prep_mbs=$(echo "$bytes / $wall / 1000000" | bc -l)
    outb=$(stat -c %s "$out")
    ones=$("$bin" info --json "$out" | python3 -c 'import json,sys; print("%.4f %%" % (100 * json.load(sys.stdin)["one_cell_fraction"]))')
    printf '| %dx%dx%d u16 | %.0f | %.0f | %.1f | %.0f | %.2f | %.0f | %.0f | %s |\n' \
        "$nx" "$ny" "$nz" "$(echo "$bytes / 1048576" | bc -l)" "$cat_mbs" "$wall" "$prep_mbs" \
        "$(echo "$prep_mbs / $cat_mbs" | bc -l)" "$(echo "$rss / 1024" | bc -l)" \
        "$(echo "$outb / 1048576" | bc -l)" "$ones"
    [ "${KEEP:-0}" = 1 ] || rm -f "$raw" "$out"
done
