#!/usr/bin/env bash
# One prep for a whole exploration (issue 16): `prep --envelope ct` plus a
# composite render of each of six CT presets, against six preps (`prep
# --preset NAME`) each followed by its render. Wall seconds of each
# command (`date`), summed; the images of the two ways are compared too
# (they differ only where the envelope file's codes are shorter: the
# composites of exact traversals are the same cells either way).
#
# usage: tools/bench-envelope.sh VOLUME.json [WORKDIR]
#        env: BIN=path/to/cdvol SIZE=512 THREADS=2
#             PRESETS="ct-bone ct-skin ct-soft-tissue ct-muscle ct-lung ct-vessels"
set -euo pipefail
vol=$1
work=${2:-target/bench-envelope}
mkdir -p "$work"
if [ -z "${BIN:-}" ]; then
    cargo build --profile release-lto --quiet
    BIN=target/release-lto/cdvol
fi
presets=${PRESETS:-ct-bone ct-skin ct-soft-tissue ct-muscle ct-lung ct-vessels}
r=(--width "${SIZE:-512}" --height "${SIZE:-512}" --threads "${THREADS:-2}" --view 35,15 --mode composite)
secs() { local t0 t1; t0=$(date +%s.%N); "$@" > /dev/null; t1=$(date +%s.%N); echo "$t1 - $t0" | bc -l; }
one_prep=$(secs "$BIN" prep -q --envelope ct "$vol" -o "$work/env.cdv")
one_render=0
six_prep=0
six_render=0
same=0
for p in $presets; do
    one_render=$(echo "$one_render + $(secs "$BIN" render -q "$work/env.cdv" -o "$work/env-$p.png" --preset "$p" "${r[@]}")" | bc -l)
    six_prep=$(echo "$six_prep + $(secs "$BIN" prep -q --preset "$p" "$vol" -o "$work/$p.cdv")" | bc -l)
    six_render=$(echo "$six_render + $(secs "$BIN" render -q "$work/$p.cdv" -o "$work/own-$p.png" --preset "$p" "${r[@]}")" | bc -l)
    if cmp -s "$work/env-$p.png" "$work/own-$p.png"; then same=$((same + 1)); fi
done
printf '| way | prep s | renders s | total s |\n|---|---|---|---|\n'
printf '| one prep --envelope ct, 6 renders | %.2f | %.2f | %.2f |\n' "$one_prep" "$one_render" "$(echo "$one_prep + $one_render" | bc -l)"
printf '| 6 preps --preset, 6 renders | %.2f | %.2f | %.2f |\n' "$six_prep" "$six_render" "$(echo "$six_prep + $six_render" | bc -l)"
printf '\nratio (6 preps) / (1 prep): %.2f; identical images: %d of 6\n' \
    "$(echo "($six_prep + $six_render) / ($one_prep + $one_render)" | bc -l)" "$same"
