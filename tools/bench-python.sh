#!/usr/bin/env bash
# The Python package against the library in Rust and the command line, on
# one packed file, in one run (issue 56's targets):
#   1. one Renderer's loop over VIEWS (36) orbit views 360/VIEWS degrees
#      apart at SIZE^2 (1024^2): from Python (cdvol.Renderer.render, the
#      numpy array included) and from Rust (examples/render_views.rs,
#      Renderer::render and Image::rgba8), both the release profile;
#   2. the same views as `cdvol render --frames VIEWS` (release binary,
#      PNG encoding and writing included), wall time of the process.
# Every frame has the same orthographic frame FRAME mm (default 300), so
# the three draw the same images. REPS (3) runs interleaved; medians.
#
# usage: tools/bench-python.sh FILE.cdv PYTHON
#   PYTHON: an interpreter with the package installed (pip install ./python)
#   env: REPS=3, VIEWS=36, SIZE=1024, FRAME=300, PRESET="" (the file's look)
set -euo pipefail
f=$1; py=$2; reps=${REPS:-3}; views=${VIEWS:-36}; size=${SIZE:-1024}; frame=${FRAME:-300}
preset=${PRESET:-}
cd "$(dirname "$0")/.."
cargo build --release --quiet --example render_views --bin cdvol
rust=target/release/examples/render_views; cli=target/release/cdvol
out=$(mktemp -d); trap 'rm -rf "$out"' EXIT
: > "$out/py"; : > "$out/rs"; : > "$out/cli"
preset_flag=(); [ -n "$preset" ] && preset_flag=(--preset "$preset")
for r in $(seq "$reps"); do
  "$py" - "$f" "$views" "$size" "$frame" "$preset" >> "$out/py" <<'PY'
import sys, time
import cdvol
f, views, size, frame, preset = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), sys.argv[5] or None
r = cdvol.open(f).renderer()
secs = []
for k in range(views):
    t = time.perf_counter()
    r.render((k * 360.0 / views, 0.0), width=size, height=size, frame=frame, preset=preset)
    secs.append(time.perf_counter() - t)
print(secs[0], sum(secs[1:]) / len(secs[1:]), sum(secs))
PY
  "$rust" "$f" "$views" "$size" "$preset" "$frame" |
    sed -E 's/first ([0-9.]+) s, warm mean ([0-9.]+) s .* total ([0-9.]+) s/\1 \2 \3/' >> "$out/rs"
  s=$(date +%s.%N)
  "$cli" render -q "$f" -o "$out/t.png" --view 0,0 --frames "$views" --width "$size" --height "$size" \
    --frame "$frame" "${preset_flag[@]}" > /dev/null
  echo "$(date +%s.%N) - $s" | bc >> "$out/cli"
done
python3 - "$out" <<'PY'
import statistics as st, sys
d = sys.argv[1]
rows = {k: [list(map(float, l.split())) for l in open(f"{d}/{k}")] for k in ("py", "rs", "cli")}
med = {k: [st.median(r[i] for r in v) for i in range(len(v[0]))] for k, v in rows.items()}
py, rs, cli = med["py"], med["rs"], med["cli"][0]
print(f"first frame: python {py[0]:.4f} s, rust {rs[0]:.4f} s")
print(f"warm frame:  python {py[1]:.4f} s, rust {rs[1]:.4f} s, python/rust {py[1] / rs[1]:.3f}")
print(f"loop total:  python {py[2]:.3f} s, rust {rs[2]:.3f} s, cdvol render --frames {cli:.3f} s, python/cli {py[2] / cli:.3f}")
PY
