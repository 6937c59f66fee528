#!/bin/bash
# alternating A/B of the hop bench: old (21aaac5) and new (HEAD) binaries, copied out of their targets
# usage: run-ab.sh OUTROOT N   (runs old-1 new-1 old-2 new-2 ...)
set -u
OUT=$1; N=${2:-3}
mkdir -p "$OUT"
for i in $(seq 1 "$N"); do
  for v in old new; do
    d="$OUT/$v-$i"; mkdir -p "$d"
    {
      echo "start $(date -u +%FT%TZ) load $(cat /proc/loadavg)"
      echo "binary /work/work/bin-$v/nerve-bench ($(cat /work/work/bin-$v/REV))"
    } > "$d/out.txt"
    NERVE_PYTHON=/nonexistent/python /work/work/bin-$v/nerve-bench hop --rounds 3 --count 1000 --out "$d" >>"$d/out.txt" 2>&1
    echo "exit $? end $(date -u +%FT%TZ) load $(cat /proc/loadavg)" >> "$d/out.txt"
    tail -1 "$d/out.txt"
  done
done
