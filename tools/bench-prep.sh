#!/usr/bin/env bash
# Whole-program prep benchmark, and the check that catches a prep
# regression. Run it before and after any change to prep, the format or
# the input readers (docs/BENCHMARKS.md, "Prep").
#
# Generates CT-like raw volumes of 1024 x 1024 x NZ u16 with `cdvol phantom
# ct` (NZ from DEPTHS, default 1024: 2 GiB), then for each, in the same run:
#   * `cat INPUT > /dev/null` of the page-cached input (the read ceiling),
#   * `zstd -3 -T2 -c INPUT > /dev/null` (compression at prep's level on
#     both cores: what bounds prep's own compression),
#   * `cdvol prep --iso 300` under /usr/bin/time -v (wall, MB/s, peak RSS),
#     and the stage times prep prints.
# Prints one markdown row per volume. Machines differ and are shared, so the
# check is a ratio measured in the same run: prep's MB/s over zstd's (both
# on both cores). The script exits 1 when it falls below MIN_ZSTD_RATIO
# (default 0.6: 0.78-0.80 on 2026-11-30 at 3af5b01, less a quarter; a 2x
# regression reads about 0.4).
#
# usage: tools/bench-prep.sh [WORKDIR]
#   DEPTHS="1024 2048"  NX=1024 NY=1024  KEEP=1 keeps the files
#   CDVOL=path          the binary (default: built with --profile release-lto)
#   MIN_ZSTD_RATIO=r    the floor of prep MB/s / zstd MB/s
set -euo pipefail
work=${1:-target/bench-prep}
nx=${NX:-1024}; ny=${NY:-1024}; depths=${DEPTHS:-1024}
floor=${MIN_ZSTD_RATIO:-0.6}
mkdir -p "$work"
if [ -z "${CDVOL:-}" ]; then
    cargo build --profile release-lto --quiet
    bin=target/release-lto/cdvol
else
    bin=$CDVOL
fi
command -v zstd > /dev/null || { echo "bench-prep: needs the zstd command (apt-get install zstd)" >&2; exit 1; }
max_nz=$(tr ' ' '\n' <<< "$depths" | sort -n | tail -n 1)
need=$(( (nx * ny * max_nz * 2 * 5 / 2) / 1024 / 1024 / 1024 + 1 ))
free=$(df -Pk "$work" | awk 'NR==2 {print int($4 / 1024 / 1024)}')
echo "bench-prep: needs about ${need} GiB free in $work, ${free} GiB available" >&2
[ "$free" -ge "$need" ] || { echo "bench-prep: not enough disk" >&2; exit 1; }

rate() { # BYTES CMD... -> MB/s of CMD on BYTES
    local bytes=$1 t0 t1
    shift
    t0=$(date +%s.%N); "$@"; t1=$(date +%s.%N)
    echo "$bytes / ($t1 - $t0) / 1000000" | bc -l
}

printf '| volume | input MiB | cat MB/s | zstd -3 -T2 MB/s | prep s | prep MB/s | prep/zstd | peak RSS MiB | output MiB | stages (s) |\n'
printf '|---|---|---|---|---|---|---|---|---|---|\n'
status=0
for nz in $depths; do
    side="$work/ct-$nz.json"
    raw="$work/ct-$nz.raw"
    [ -s "$raw" ] || "$bin" phantom ct -q --dims "$nx,$ny,$nz" --dtype u16 -o "$side" > /dev/null
    bytes=$(stat -c %s "$raw")
    cat "$raw" > /dev/null   # warm the page cache
    cat_mbs=$(rate "$bytes" sh -c "cat '$raw' > /dev/null")
    zstd_mbs=$(rate "$bytes" sh -c "zstd -q -3 -T2 -c '$raw' > /dev/null")
    out="$work/ct-$nz.cdv"
    /usr/bin/time -v "$bin" prep -q --iso 300 "$side" -o "$out" > "$work/prep-$nz.out" 2> "$work/prep-$nz.time"
    wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, t, ":"); s = 0;
        for (i = 1; i <= n; i++) s = s * 60 + t[i]; print s}' "$work/prep-$nz.time")
    rss=$(awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$work/prep-$nz.time")
    prep_mbs=$(echo "$bytes / $wall / 1000000" | bc -l)
    ratio=$(echo "$prep_mbs / $zstd_mbs" | bc -l)
    stages=$(sed -n 's/^stages (s): //p' "$work/prep-$nz.out")
    printf '| %dx%dx%d u16 | %.0f | %.0f | %.0f | %.1f | %.0f | %.2f | %s | %.0f | %s |\n' \
        "$nx" "$ny" "$nz" "$(echo "$bytes / 1048576" | bc -l)" "$cat_mbs" "$zstd_mbs" "$wall" \
        "$prep_mbs" "$ratio" "$rss" "$(echo "$(stat -c %s "$out") / 1048576" | bc -l)" "$stages"
    if [ "$(echo "$ratio < $floor" | bc -l)" = 1 ]; then
        printf 'bench-prep: REGRESSION: %dx%dx%d prep/zstd %.3f is below %s\n' "$nx" "$ny" "$nz" "$ratio" "$floor" >&2
        status=1
    fi
    [ "${KEEP:-0}" = 1 ] || rm -f "$raw" "$out"
done
exit $status
