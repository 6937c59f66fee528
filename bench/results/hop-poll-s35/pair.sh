#!/bin/bash
# manual profile of the polling pair: router, poll ping (cpu0) and poll pong (cpu1), wired; batches by suspend/resume
set -u
BIN=${BIN:-/tmp/h8-before/nerve-bench}
N=/work/main/target/release/nerve
export NERVE_HOME=/tmp/h8-prof/home; rm -rf $NERVE_HOME; mkdir -p $NERVE_HOME
R=h8prof$$
export NERVE_CPU_LATENCY=off
$N --robot $R router >/tmp/h8-prof/router.log 2>&1 &
RP=$!
for i in $(seq 50); do $N --robot $R ps --json >/dev/null 2>&1 && break; sleep 0.1; done
mkdir -p out
RUST_MIN_STACK=67108864 $BIN __agent-ping --robot $R --name pping --cpus 0 --suspended --poll --no-realtime -- --size 8 --count ${COUNT:-20000} --out /tmp/h8-prof/out >/tmp/h8-prof/ping.log 2>&1 &
PI=$!
RUST_MIN_STACK=67108864 $BIN __agent-pong --robot $R --name ppong --cpus 1 --suspended --poll --no-realtime -- --size 8 --count 1000 --out /tmp/h8-prof/out >/tmp/h8-prof/pong.log 2>&1 &
PO=$!
sleep 1.5
$N --robot $R connect pping/out ppong/in
$N --robot $R connect --allow-cycle ppong/out pping/in
$N --robot $R resume ppong
echo "ping $PI pong $PO"
$N --robot $R resume pping
sleep ${SLEEP:-3}
if [ -n "${PERF:-}" ]; then perf record ${PERFARGS:--g} -o /tmp/h8-prof/perf-$1.data -p $PI,$PO -- sleep ${PERFSECS:-3} 2>/dev/null; fi
sleep 2
ls out
$N --robot $R suspend pping; $N --robot $R suspend ppong
kill $PI $PO; sleep 0.5; kill $RP; wait 2>/dev/null
$N --robot $R down >/dev/null 2>&1
