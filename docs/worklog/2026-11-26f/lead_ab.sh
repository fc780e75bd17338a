#!/bin/bash
# Lead's quiet A/B at the end of stop 25: start of the stop (c898557, /work/wt/preflight9-base)
# against main, interleaved, 2 pairs: the 10 s loop per controller, then pre-flight.
PY=/work/main/.venv/bin/python
A=/work/wt/preflight9-base; B=/work/main
out=${1:-/work/notes9/lead_ab.txt}; : > $out
for tree in $A $B; do (cd $tree && PYTHONPATH=$PWD $PY -m talus bench loop --seconds 1 --controller paden_panja --json > /dev/null 2>&1; PYTHONPATH=$PWD $PY bench/preflight.py --repeats 1 --only sine60 --json > /dev/null 2>&1); done
for pair in 1 2; do
 for c in paden_panja adaptive; do
  for tree in $A $B; do
   echo "== pair $pair loop $c $tree $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)" >> $out
   (cd $tree && PYTHONPATH=$PWD $PY -m talus bench loop --seconds 10 --controller $c --json >> $out 2>&1)
  done
 done
 for tree in $A $B; do
  echo "== pair $pair preflight $tree $(date +%T) load $(cut -d' ' -f1-3 /proc/loadavg)" >> $out
  (cd $tree && PYTHONPATH=$PWD $PY bench/preflight.py --repeats 1 --json >> $out 2>&1)
 done
done
echo done >> $out
