#!/usr/bin/env bash
# Two builds on one packed file: surface, 1024^2, view 35,15, one thread
# (taskset -c 0); per run the cold frame (the first of 3) and the warm one
# (median of the other two), REPS (5) runs interleaved A, B, A, B...;
# prints the medians per build.
#
# usage: tools/bench-ab.sh FILE.cdv CDVOL_A CDVOL_B
set -euo pipefail
f=$1; A=$2; B=$3; reps=${REPS:-5}
for bin in A B; do : > /tmp/ab-$bin.txt; done
for r in $(seq $reps); do
  for bin in A B; do
    b=${!bin}
    taskset -c 0 $b render -q $f -o /tmp/ab.png --threads 1 --view 35,15 --width 1024 --height 1024 --frames 3 --orbit 0 --stats /tmp/ab.json > /dev/null
    python3 -c "import json, statistics as st; d=json.load(open('/tmp/ab.json')); print(d[0]['seconds_total'], st.median(x['seconds_total'] for x in d[1:]))" >> /tmp/ab-$bin.txt
  done
done
for bin in A B; do python3 -c "
import statistics as st
rows=[list(map(float,l.split())) for l in open('/tmp/ab-$bin.txt')]
print('$bin', 'cold %.3f warm %.3f' % (st.median(r[0] for r in rows), st.median(r[1] for r in rows)))"; done
