#!/usr/bin/env bash
# Label render against the single-iso surface of the same scene (issue 55's
# target: at most 1.5x): the real CT's threshold segmentation (`cdvol
# segment`: soft tissue, bone, air spaces), prepared with `--labels` and no
# colour table (every label opaque), rendered at SIZE^2 (1024) with all its
# labels and as the surface at iso 0.5 of the same file (the union of the
# labels, unsmoothed: the same cells walked, the same first-hit stop).
# Three views, REPS (5) interleaved runs of a cold frame and 2 warm ones
# each; medians of the warm frames and their ratio. Then the same with the
# overlay: the CT's ct-bone composite with the bone and air-space labels
# inside against the composite alone.
#
# usage: tools/bench-labels.sh CT.json [CDVOL]
#   env: REPS=5, SIZE=1024, THREADS=2
set -euo pipefail
ct=$1; bin=${2:-target/release-lto/cdvol}
reps=${REPS:-5}; size=${SIZE:-1024}; threads=${THREADS:-2}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
"$bin" -q segment "$ct" -o "$tmp/seg.json" > /dev/null
"$bin" -q prep --labels "$tmp/seg.json" -o "$tmp/seg.cdv" > /dev/null
"$bin" -q prep --envelope ct "$ct" -o "$tmp/ct.cdv" > /dev/null
run() { # name file args...
  local name=$1 file=$2; shift 2
  "$bin" render -q "$file" -o "$tmp/x.png" --threads "$threads" --width "$size" \
    --height "$size" --frames 3 --orbit 0 --stats "$tmp/s.json" "$@" > /dev/null
  python3 -c "import json, statistics as st; d=json.load(open('$tmp/s.json')); print(st.median(x['seconds_total'] for x in d[1:]))" >> "$tmp/$name"
}
report() { # a b what
  python3 - "$tmp/$1" "$tmp/$2" "$3" <<'PY'
import statistics as st, sys
a = [float(x) for x in open(sys.argv[1])]
b = [float(x) for x in open(sys.argv[2])]
print(f"{sys.argv[3]}: {st.median(a):.3f} s against {st.median(b):.3f} s, ratio {st.median(a) / st.median(b):.2f} (per run: {', '.join(f'{x / y:.2f}' for x, y in zip(a, b))})")
PY
}
for view in 160,10 90,0 0,60; do
  for r in $(seq "$reps"); do
    run "labels-$view" "$tmp/seg.cdv" --view "$view"
    run "iso-$view" "$tmp/seg.cdv" --view "$view" --iso 0.5
  done
  report "labels-$view" "iso-$view" "labels / iso 0.5 surface, view $view, ${size}^2"
done
for r in $(seq "$reps"); do
  run over "$tmp/ct.cdv" --view 160,10 --preset ct-bone --mode composite \
    --overlay "$tmp/seg.cdv" --labels 2,3
  run alone "$tmp/ct.cdv" --view 160,10 --preset ct-bone --mode composite
done
report over alone "composite with the overlay / composite alone, view 160,10, ${size}^2"
