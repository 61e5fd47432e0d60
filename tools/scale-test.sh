#!/usr/bin/env bash
# Larger-than-RAM test, end to end (not part of CI). For each size S (GiB of
# u16 samples, default "16 32": the second exceeds this machine's 24 GiB of
# RAM and doubles the first):
#   1. `cdvol phantom ct` writes a NXY x NXY x NZ u16 CT-like stack
#      (NZ = S GiB / (2 NXY^2); slice gaps scaled by 160/NZ so the head keeps
#      its proportions), streamed, on both cores;
#   2. `cdvol prep --iso 300` packs it;
#   3. with SHARDS=N, the same prep in N shards on this machine, one after
#      another (`prep --shard K/N --pass 1` for every K, then `--pass 2`,
#      then `prep-merge`), each step timed, and the merged file compared
#      with the single prep's (sha256);
#   4. `cdvol render` draws 2048x2048 surface and composite images with
#      --cache-mb 1024 (RENDER=0 leaves them out).
# Each stage runs under /usr/bin/time -v while a sampler records the peak
# of extra disk in use; the render stages also report, from --stats, the
# distinct bricks read of the total, all brick reads (a brick evicted and
# needed again is read again) and the cache hit rate. Prints one markdown row per
# stage and appends JSON lines to WORKDIR/scale.jsonl. Checks free disk
# first; deletes what it generated unless KEEP=1.
#
# usage: tools/scale-test.sh [WORKDIR]
#   SIZES="16 32"  GiB per volume      NXY=2048   samples along x and y
#   KEEP=1         keep the generated files
#   SHARDS=N       also prep in N shards (step 3)   RENDER=0  no renders
#   DROP_CACHES=0  keep the page cache between stages (default: dropped)
#   OVERFLOW_CHECKS=1  build with integer overflow checks (catches 32-bit
#                      index arithmetic at these sizes; slower)
set -euo pipefail
work=$(realpath -m "${1:-target/scale}")
sizes=${SIZES:-"16 32"}
nxy=${NXY:-2048}
cache_mb=1024
cd "$(dirname "$0")/.."
mkdir -p "$work"

if [ "${OVERFLOW_CHECKS:-0}" = 1 ]; then
    export CARGO_PROFILE_RELEASE_OVERFLOW_CHECKS=true
    export CARGO_TARGET_DIR=target/overflow-checks
fi
cargo build --profile release-lto --quiet
bin=$(realpath "${CARGO_TARGET_DIR:-target}/release-lto/cdvol")

gib=$((1024 * 1024 * 1024))
# Disk: the raw stack, the prep spill (1 byte per cell = half the raw
# size), the packed output (about 8 % of the raw size) and 1 GiB to spare.
for s in $sizes; do
    need=$((s * 16 / 10 + 1))
    free=$(df -Pk "$work" | awk 'NR==2 {print int($4 / 1024 / 1024)}')
    echo "scale-test: $s GiB needs about $need GiB free in $work; $free GiB available" >&2
    if [ "$free" -lt "$need" ]; then
        echo "scale-test: not enough disk for $s GiB (need $need GiB, have $free GiB)" >&2
        exit 1
    fi
done

cat > "$work/tf.json" <<'EOF'
{"points": [{"value": 300, "opacity": 0.0, "color": [1.0, 0.9, 0.8]},
            {"value": 800, "opacity": 0.08, "color": [1.0, 0.85, 0.7]},
            {"value": 1500, "opacity": 0.5, "color": [1.0, 1.0, 1.0]}]}
EOF

used_kb() { df -Pk "$work" | awk 'NR==2 {print $3}'; }

# run NAME BYTES CMD...: times CMD, samples disk use every 0.2 s; sets
# wall (s), rss (MiB), disk (MiB above the start), mbs (BYTES / wall).
run() {
    local name=$1 bytes=$2; shift 2
    local base peak u pid
    base=$(used_kb); peak=$base
    /usr/bin/time -v -o "$work/$name.time" "$@" > "$work/$name.out" 2> "$work/$name.err" &
    pid=$!
    while kill -0 "$pid" 2>/dev/null; do
        u=$(used_kb); [ "$u" -gt "$peak" ] && peak=$u
        sleep 0.2
    done
    if ! wait "$pid"; then
        echo "scale-test: $name failed:" >&2
        cat "$work/$name.err" >&2
        exit 1
    fi
    wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, t, ":"); s = 0;
        for (i = 1; i <= n; i++) s = s * 60 + t[i]; print s}' "$work/$name.time")
    rss=$(awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$work/$name.time")
    disk=$(( (peak - base) / 1024 ))
    mbs=$(echo "$bytes / $wall / 1000000" | bc -l)
}

json() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])' "$@"; }

printf '| volume | stage | wall s | MB/s | peak RSS MiB | extra disk MiB | bricks read / total | brick reads | cache hit rate |\n'
printf '|---|---|---|---|---|---|---|---|---|\n'
row() { # volume stage [bricks reads hit-rate]
    printf '| %s | %s | %.1f | %.0f | %s | %s | %s | %s | %s |\n' "$1" "$2" "$wall" "$mbs" "$rss" "$disk" "${3:--}" "${4:--}" "${5:--}"
    printf '{"volume": "%s", "stage": "%s", "wall_s": %s, "mb_per_s": %.1f, "peak_rss_mib": %s, "extra_disk_mib": %s, "bricks": "%s", "brick_reads": "%s", "cache_hit_rate": "%s", "overflow_checks": %s}\n' \
        "$1" "$2" "$wall" "$mbs" "$rss" "$disk" "${3:--}" "${4:--}" "${5:--}" "${OVERFLOW_CHECKS:-0}" >> "$work/scale.jsonl"
}

for s in $sizes; do
    nz=$((s * gib / (2 * nxy * nxy)))
    name="ct-${nxy}x${nxy}x${nz}"
    vol="${nxy}x${nxy}x${nz} u16 ($s GiB)"
    side="$work/$name.json"; raw="$work/$name.raw"; cdv="$work/$name.cdv"
    zs=$(echo "160 / $nz" | bc -l)
    bytes=$((nxy * nxy * nz * 2))

    run "$name.phantom" "$bytes" "$bin" phantom ct -q --dims "$nxy,$nxy,$nz" --dtype u16 \
        --z-scale "$zs" -o "$side"
    row "$vol" "phantom ct"

    # Start prep from disk, not from the page cache, where we may.
    [ "${DROP_CACHES:-1}" = 0 ] || { sync; echo 1 > /proc/sys/vm/drop_caches 2>/dev/null || true; }
    run "$name.prep" "$bytes" "$bin" prep -q --iso 300 "$side" -o "$cdv"
    row "$vol" "prep"
    grep -h '^wrote\|^stages' "$work/$name.prep.out" >&2 || true
    if [ "${SHARDS:-0}" -gt 0 ]; then
        n=$SHARDS
        want=$(sha256sum < "$cdv")
        single_s=$wall
        # Room for the shards' spills and parts: the single file goes.
        [ "${RENDER:-1}" = 0 ] && rm -f "$cdv"
        sharded="$work/$name.sharded.cdv"
        total=0
        for pass in 1 2; do
            for ((k = 0; k < n; k++)); do
                [ "${DROP_CACHES:-1}" = 0 ] || { sync; echo 1 > /proc/sys/vm/drop_caches 2>/dev/null || true; }
                run "$name.shard$k.pass$pass" $((bytes / n)) "$bin" prep -q --iso 300 "$side" \
                    -o "$sharded" --shard "$k/$n" --pass "$pass"
                row "$vol" "shard $k/$n pass $pass"
                grep -h '^wrote\|^stages' "$work/$name.shard$k.pass$pass.out" >&2 || true
                total=$(echo "$total + $wall" | bc -l)
            done
        done
        run "$name.merge" "$bytes" "$bin" prep-merge -q "$sharded.parts" -o "$sharded"
        row "$vol" "prep-merge"
        total=$(echo "$total + $wall" | bc -l)
        got=$(sha256sum < "$sharded")
        [ "$got" = "$want" ] || { echo "scale-test: the $n-shard prep differs from the single prep" >&2; exit 1; }
        echo "scale-test: $n-shard prep == single prep (sha256 ${got:0:16}); shards in sequence ${total} s against ${single_s} s for one prep" >&2
        rm -rf "$sharded" "$sharded.parts"
    fi
    [ "${KEEP:-0}" = 1 ] || rm -f "$raw"
    [ "${RENDER:-1}" = 1 ] || continue

    for mode in surface composite; do
        extra=()
        [ "$mode" = composite ] && extra=(--tf "$work/tf.json")
        stats="$work/$name.$mode.json"
        [ "${DROP_CACHES:-1}" = 0 ] || { sync; echo 1 > /proc/sys/vm/drop_caches 2>/dev/null || true; }
        run "$name.$mode" 0 "$bin" render -q "$cdv" -o "$work/$name.$mode.png" --mode "$mode" \
            "${extra[@]}" --width 2048 --height 2048 --view 30,20 --cache-mb "$cache_mb" \
            --stats "$stats"
        dec=$(json "$stats" bytes_decompressed)
        mbs=$(echo "$dec / $wall / 1000000" | bc -l)
        bricks="$(json "$stats" bricks_distinct) / $(json "$stats" bricks_total)"
        reads=$(json "$stats" bricks_read)
        rate=$(python3 -c 'import json,sys; d = json.load(open(sys.argv[1]));
print("%.5f" % (d["cache_hits"] / max(1, d["cache_hits"] + d["cache_misses"])))' "$stats")
        row "$vol" "render $mode" "$bricks" "$reads" "$rate"
    done
    [ "${KEEP:-0}" = 1 ] || rm -f "$raw" "$cdv"
done
echo "scale-test: render MB/s are bytes decompressed per second; results in $work/scale.jsonl" >&2
