#!/usr/bin/env bash
# A crop box keeping a tenth of the cells (the middle 46.4 % of the cells
# on each axis) against no crop, on one packed file and its input sidecar
# (for the sample positions): bricks read, cold and warm frame, surface and
# composite and MIP, SIZE^2 (1024), view 35,15, REPS (3) interleaved runs; medians.
#
# usage: tools/bench-crop.sh FILE.cdv SIDECAR.json [CDVOL]
#   env: REPS=3, SIZE=1024, THREADS=2, PRESET=ct-bone
set -euo pipefail
f=$1; side=$2; bin=${3:-target/release/cdvol}
reps=${REPS:-3}; size=${SIZE:-1024}; threads=${THREADS:-2}; preset=${PRESET:-ct-bone}
crop=$(python3 - "$side" <<'PY'
import json, sys, pathlib
s = json.loads(pathlib.Path(sys.argv[1]).read_text())
out = []
for k, name in enumerate("xyz"):
    n = s["dims"][k]
    ax = s[name]
    pos = ax["positions"] if isinstance(ax, dict) and "positions" in ax else None
    if pos is None:
        h = ax if isinstance(ax, (int, float)) else None
        pos = [s.get("origin", [0, 0, 0])[k] + i * h for i in range(n)]
    cells = n - 1
    a, b = round(cells * 0.268), round(cells * 0.732)
    out.append(f"{pos[a]}:{pos[b]}")
print(",".join(out))
PY
)
echo "crop $crop"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
for mode in surface composite mip; do
  extra=(--preset "$preset"); [ $mode != surface ] && extra+=(--mode $mode)
  for what in whole crop; do : > "$tmp/$mode-$what"; done
  for r in $(seq "$reps"); do
    for what in whole crop; do
      c=(); [ $what = crop ] && c=(--crop "$crop")
      "$bin" render -q "$f" -o "$tmp/x.png" --threads "$threads" --view 35,15 --width "$size" \
        --height "$size" --frames 3 --orbit 0 --stats "$tmp/s.json" "${extra[@]}" "${c[@]}" > /dev/null
      python3 -c "import json, statistics as st; d=json.load(open('$tmp/s.json')); print(d[0]['seconds_total'], st.median(x['seconds_total'] for x in d[1:]), d[0]['bricks_distinct'], d[0]['bricks_total'])" >> "$tmp/$mode-$what"
    done
  done
  python3 - "$tmp" "$mode" <<'PY'
import statistics as st, sys
d, mode = sys.argv[1], sys.argv[2]
rows = {w: [list(map(float, l.split())) for l in open(f"{d}/{mode}-{w}")] for w in ("whole", "crop")}
m = {w: [st.median(r[i] for r in v) for i in range(4)] for w, v in rows.items()}
w, c = m["whole"], m["crop"]
print(f"{mode}: bricks read {c[2]:.0f} / {w[2]:.0f} ({100 * c[2] / w[2]:.1f} %, of {w[3]:.0f}); "
      f"cold {w[0]:.3f} -> {c[0]:.3f} s ({w[0] / c[0]:.1f}x), warm {w[1]:.3f} -> {c[1]:.3f} s ({w[1] / c[1]:.1f}x)")
PY
done
