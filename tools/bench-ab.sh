#!/usr/bin/env bash
# Two builds on one packed file: 1024^2 (or SIZE^2), view 35,15 or VIEW (surface unless EXTRA
# says otherwise); per run the cold frame (the first of 3) and the warm one
# (median of the other two), REPS (5) runs interleaved A, B, A, B...;
# prints the medians per build, with the peak of the brick cache and the
# process's peak RSS (GNU time).
#
# usage: tools/bench-ab.sh FILE.cdv CDVOL_A CDVOL_B
#   env: REPS=5, THREADS=1 (one thread runs pinned: taskset -c 0), VIEW=35,15, SIZE=1024,
#        EXTRA="" (more render flags, e.g. "--mode composite --tf tf.json --shade")
set -euo pipefail
f=$1; A=$2; B=$3; reps=${REPS:-5}; threads=${THREADS:-1}
pin=(); [ "$threads" = 1 ] && pin=(taskset -c 0)
for bin in A B; do : > /tmp/ab-$bin.txt; done
for r in $(seq $reps); do
  for bin in A B; do
    b=${!bin}
    /usr/bin/time -f %M -o /tmp/ab.rss "${pin[@]}" $b render -q $f -o /tmp/ab.png --threads $threads \
      --view ${VIEW:-35,15} --width ${SIZE:-1024} --height ${SIZE:-1024} --frames 3 --orbit 0 --stats /tmp/ab.json ${EXTRA:-} > /dev/null
    python3 -c "import json, statistics as st; d=json.load(open('/tmp/ab.json')); print(d[0]['seconds_total'], st.median(x['seconds_total'] for x in d[1:]), d[0]['peak_cache_bytes'], open('/tmp/ab.rss').read().split()[-1])" >> /tmp/ab-$bin.txt
  done
done
for bin in A B; do python3 -c "
import statistics as st
rows=[list(map(float,l.split())) for l in open('/tmp/ab-$bin.txt')]
print('$bin', 'cold %.3f warm %.3f cache %.1f MiB peak RSS %.1f MiB' % (st.median(r[0] for r in rows), st.median(r[1] for r in rows), max(r[2] for r in rows) / 2**20, st.median(r[3] for r in rows) / 1024))"; done
