#!/bin/bash
# Interleaved quiet A/B: abbase (b192407, start of the stop) vs trial (merged main), loop 10 s per controller, 2 pairs; preflight twice each.
PY=/work/main/.venv/bin/python
out=/work/notes8/ab_quiet.txt; : > $out
(cd /work/wt/trial && PYTHONPATH=$PWD $PY bench/preflight.py --repeats 1 --json > /dev/null 2>&1)   # warm the numba caches
(cd /work/wt/abbase && PYTHONPATH=$PWD $PY bench/preflight.py --repeats 1 --json > /dev/null 2>&1)
for pair in 1 2; do
 for c in paden_panja adaptive; do
  for tree in abbase trial; do
   echo "== pair $pair $c $tree $(date +%T) $(cut -d' ' -f1 /proc/loadavg)" >> $out
   (cd /work/wt/$tree && PYTHONPATH=$PWD $PY -m talus bench loop --seconds 10 --controller $c --json >> $out 2>&1)
  done
 done
done
for pair in 1 2; do
 for tree in abbase trial; do
  echo "== preflight $pair $tree $(date +%T) $(cut -d' ' -f1 /proc/loadavg)" >> $out
  (cd /work/wt/$tree && PYTHONPATH=$PWD $PY bench/preflight.py --repeats 1 --json >> $out 2>&1)
 done
done
echo done >> $out
