#!/usr/bin/env bash
# Runs `nerve bench control` with two builds of `nerve`, alternately, three
# times over (BENCHMARKS.md section 3, 2026-11-27 13:59 UTC): the build
# before with iceoryx2's default room for expired connections (128, in its
# agents and the benchmark's own client too), the other as it runs.
#
#   bash bench/scripts/control-ab.sh BEFORE_NERVE AFTER_NERVE [OUT_DIR]
#
# Agents and nerve-bench are taken from target/release; each run's JSON and
# tables go to OUT_DIR/<before|after>-<round>/ (default /tmp/control-ab).
set -euo pipefail
before=${1:?the nerve binary of the build before}
after=${2:?the nerve binary of the build after}
out=${3:-/tmp/control-ab}
cd "$(dirname "$0")/../.."
export PATH="$PWD/target/release:$PATH"
for round in 1 2 3; do
  for which in before after; do
    dir="$out/$which-$round"
    mkdir -p "$dir"
    if [ "$which" = before ]; then
      bin=$before
      export NERVE_IOX2_EXPIRED_CONNECTIONS=128
    else
      bin=$after
      unset NERVE_IOX2_EXPIRED_CONNECTIONS
    fi
    echo "== $which $round $(date -u +%T) load $(cut -d' ' -f1 /proc/loadavg)"
    NERVE_BIN=$bin target/release/nerve-bench control --rounds 40 --out "$dir" 2>/dev/null | grep '^|'
  done
done
