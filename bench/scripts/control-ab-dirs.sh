#!/usr/bin/env bash
# Runs `nerve bench control` with two builds, alternately, three times over:
# each build is a folder holding its `nerve`, `nerve-bench` and the agents
# the benchmark starts (`nerve-relay`, `nerve-ticker`), so that a change in
# the agents' start-up is measured with its own agents (BENCHMARKS.md
# section 3, 2026-11-27 evening).
#
#   bash bench/scripts/control-ab-dirs.sh BEFORE_DIR AFTER_DIR [OUT_DIR] [ROUNDS]
#
# Each run's JSON and tables go to OUT_DIR/<before|after>-<round>/ (default
# /tmp/control-ab-dirs); ROUNDS is the benchmark's --rounds (default 40).
set -euo pipefail
before=$(realpath "${1:?the folder of the build before}")
after=$(realpath "${2:?the folder of the build after}")
out=${3:-/tmp/control-ab-dirs}
rounds=${4:-40}
for round in 1 2 3; do
  for which in before after; do
    dir="$out/$which-$round"
    bin=$before
    [ "$which" = after ] && bin=$after
    mkdir -p "$dir"
    echo "== $which $round $(date -u +%T) load $(cut -d' ' -f1 /proc/loadavg)"
    PATH="$bin:$PATH" NERVE_BIN="$bin/nerve" "$bin/nerve-bench" control --rounds "$rounds" --out "$dir" 2>/dev/null | grep '^|'
  done
done
