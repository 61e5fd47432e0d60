#!/usr/bin/env bash
# Renders one set of scenes with two cdvol binaries and compares them:
# every PNG/f32 output byte for byte, and the stats JSON counters that are
# deterministic (steps, macro/cell steps, hits, bricks read; cache hits,
# misses and bytes decompressed vary with thread races and are skipped).
# Scenes: a 64^3 sphere phantom prepared with --aniso --dda, every
# traversal in cost and surface mode; the real CT in surface, MIP, depth
# and cost with fvt, cd and the octree, f32, shadows with perspective and a
# composite. For refactors that must change no image.
#
#   tools/compare-renders.sh OLD_CDVOL NEW_CDVOL [WORK_DIR]
set -euo pipefail
old=$1; new=$2; work=${3:-$(mktemp -d)}
root=$(cd "$(dirname "$0")/.." && pwd)
ct=${CT:-$root/target/ct/cranium.json}
[ -f "$ct" ] || bash "$root/tools/fetch-ct.sh" "$(dirname "$ct")" >&2

scenes() {
    local B=$1 D=$2
    mkdir -p "$D"; cd "$D"
    "$B" -q phantom spheres -o sph.json --size 64 --per-axis 3 --seed 7 >/dev/null
    "$B" -q prep sph.json -o sph.cdv --iso 100 --aniso --dda >/dev/null
    local r=(--view 30,20 --width 96 --height 96)
    # The inexact traversals and --no-switch-fvt are `experiment render`'s
    # since issue 52; older binaries took them in `render`.
    local xr=(render)
    if "$B" experiment render --help >/dev/null 2>&1; then xr=(experiment render); fi
    for t in fvt cd cd-aniso octree dda-cityblock dda-chessboard dda-chamfer template; do
        for m in cost surface; do
            "$B" -q "${xr[@]}" sph.cdv -o "sph-$t-$m.png" --mode $m --traversal $t "${r[@]}" --stats "sph-$t-$m.json" >/dev/null
        done
    done
    "$B" -q "${xr[@]}" sph.cdv -o sph-noswitch.png --mode cost --traversal dda-cityblock --no-switch-fvt "${r[@]}" --stats sph-noswitch.json >/dev/null
    "$B" -q prep "$ct" -o ct.cdv --iso 300 >/dev/null
    r=(--view 35,15 --width 128 --height 128)
    for m in surface mip depth cost; do
        for t in fvt cd octree; do
            "$B" -q render ct.cdv -o "ct-$t-$m.png" --mode $m --traversal $t "${r[@]}" --stats "ct-$t-$m.json" >/dev/null
        done
    done
    "$B" -q render ct.cdv -o ct-f32.png --mode cost --precision f32 "${r[@]}" --stats ct-f32.json >/dev/null
    "$B" -q render ct.cdv -o ct-shadow.png --mode surface --shadows --persp --view 100,30 --width 128 --height 128 --stats ct-shadow.json >/dev/null
    # Bone only: no opacity below the file's iso value.
    cat > bone-tf.json <<'TF'
{"points": [{"value": 300, "opacity": 0, "color": [1, 1, 1]},
            {"value": 700, "opacity": 0.4, "color": [1, 0.9, 0.8]},
            {"value": 1500, "opacity": 0.9, "color": [1, 1, 1]}]}
TF
    "$B" -q render ct.cdv -o ct-comp.png --mode composite --tf bone-tf.json "${r[@]}" --stats ct-comp.json >/dev/null
}

( scenes "$old" "$work/old" )
( scenes "$new" "$work/new" )
status=0
n=0
for f in "$work"/old/*.png "$work"/old/*.f32; do
    n=$((n + 1))
    b=$(basename "$f")
    cmp -s "$f" "$work/new/$b" || { echo "differs: $b"; status=1; }
done
for f in "$work"/old/*.json; do
    b=$(basename "$f")
    case $b in sph.json | bone-tf.json) continue ;; esac
    python3 - "$f" "$work/new/$b" <<'PY' || status=1
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
a, b = (x[0] if isinstance(x, list) else x for x in (a, b))
keys = ["rays", "steps", "macro_steps", "cell_steps", "hits", "bricks_read", "bricks_total"]
bad = [k for k in keys if a.get(k) != b.get(k)]
for k in bad:
    print(f"{sys.argv[1]}: {k} {a.get(k)} -> {b.get(k)}")
sys.exit(1 if bad else 0)
PY
done
echo "compare-renders: $n images compared in $work, $( [ $status = 0 ] && echo identical || echo DIFFERENT )"
exit $status
