#!/usr/bin/env bash
# Times smooth against cell normals (docs/TRADEOFFS.md, "Normals (issue
# 15)"): 1024^2 surface renders on one thread, interleaved rounds of
# (cell, plain) (smooth, plain) (smooth, halo) (cell, halo), render
# seconds from --stats; prints one line per render and the medians.
#
#   CDVOL=target/release-lto/cdvol tools/normals-bench.sh ROUNDS PLAIN.cdv HALO.cdv [render args...]
set -euo pipefail
cdvol=${CDVOL:?set CDVOL to the cdvol binary}
rounds=$1; plain=$2; halo=$3; shift 3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for r in $(seq "$rounds"); do
    for cfg in "cell $plain" "smooth $plain" "smooth $halo" "cell $halo"; do
        read -r n file <<<"$cfg"
        "$cdvol" render "$file" -o "$work/t.png" --normals "$n" --width 1024 --height 1024 \
            --threads 1 -q --stats "$work/st.json" "$@" >/dev/null
        s=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['seconds_total'])" "$work/st.json")
        echo "$n $(basename "$file") $s"
    done
done | tee "$work/all.txt"
python3 - "$work/all.txt" <<'PY'
import collections, statistics, sys
d = collections.defaultdict(list)
for line in open(sys.argv[1]):
    n, f, s = line.split()
    d[(n, f)].append(float(s))
base = statistics.median(next(iter(d.values())))
for (n, f), v in d.items():
    m = statistics.median(v)
    print(f"median {n:6} {f:28} {m:.4f} s  x{m / base:.3f}")
PY
