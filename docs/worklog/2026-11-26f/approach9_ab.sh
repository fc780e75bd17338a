#!/bin/bash
# approach9's A/B: main (a detached worktree at c898557) vs approach9, interleaved, 2 pairs:
# the 10 s loop per controller, pre-flight once each per pair, the cycles by kind (realtime, 10 s).
PY=/work/main/.venv/bin/python
A=/work/wt/approach9-main; B=/work/wt/approach9
out=${1:-/tmp/approach9_ab.txt}; : > $out
for tree in $A $B; do (cd $tree && PYTHONPATH=$PWD $PY -m talus bench loop --seconds 1 --controller paden_panja --json > /dev/null 2>&1); done  # warm numba caches
for pair in 1 2; do
 for c in paden_panja adaptive; do
  for tree in $A $B; do
   echo "== pair $pair loop $c $tree $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)" >> $out
   (cd $tree && PYTHONPATH=$PWD $PY -m talus bench loop --seconds 10 --controller $c --json >> $out 2>&1)
  done
 done
 for tree in $A $B; do
  echo "== pair $pair cycles paden_panja $tree $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)" >> $out
  (cd $B && PYTHONPATH=$tree $PY bench/approach_cycles.py --mode realtime --seconds 10 --duration 10 --json --inner >> $out 2>&1)
 done
 for tree in $A $B; do
  echo "== pair $pair preflight $tree $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)" >> $out
  (cd $tree && PYTHONPATH=$PWD $PY bench/preflight.py --repeats 1 --json >> $out 2>&1)
 done
done
echo done >> $out
