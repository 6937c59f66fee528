#!/bin/bash
# One pinned event-driven ping/pong pair of the hop bench's agents (the
# `nerve-pinned` row: both on CPU 0, SCHED_FIFO 20 as the SDK sets it), in a
# robot of its own, one batch of COUNT round trips; with PERF=stat or
# PERF=record the pong (and ping) are measured by perf for PERFSECS seconds.
# usage: pair-pinned.sh old|new TAG
set -u
V=$1; TAG=$2
BIN=/work/work/bin-$V/nerve-bench
N=/work/work/bin-$V/nerve
W=/work/work/ab/prof-$TAG; rm -rf $W; mkdir -p $W/out
export NERVE_HOME=$W/home; mkdir -p $NERVE_HOME
R=gab$$
export NERVE_CPU_LATENCY=off
$N --robot $R router >$W/router.log 2>&1 &
RP=$!
for i in $(seq 50); do $N --robot $R ps --json >/dev/null 2>&1 && break; sleep 0.1; done
RUST_MIN_STACK=67108864 $BIN __agent-ping --robot $R --name pping --cpus 0 --suspended -- --size 8 --count ${COUNT:-400000} --out $W/out >$W/ping.log 2>&1 &
PI=$!
RUST_MIN_STACK=67108864 $BIN __agent-pong --robot $R --name ppong --cpus 0 -- --size 8 --count 1000 --out $W/out >$W/pong.log 2>&1 &
PO=$!
sleep 1.5
$N --robot $R connect pping/out ppong/in
$N --robot $R connect --allow-cycle ppong/out pping/in
sleep 0.3
if [ "${PERF:-}" = count ]; then
  perf stat -e probe_libc:pthread_mutex_lock,probe_libc:malloc,probe_libc:free,probe_libc:clock_gettime,context-switches --per-thread -p $PO,$PI -o $W/perf-count.txt &
  PS=$!; sleep 0.5
fi
$N --robot $R resume pping
sleep 1
case "${PERF:-}" in
  stat) perf stat -e task-clock,context-switches,cpu-migrations,page-faults -p $PO -o $W/perf-stat-pong.txt -- sleep ${PERFSECS:-3} 2>/dev/null
        perf stat -e task-clock,context-switches -p $PI -o $W/perf-stat-ping.txt -- sleep ${PERFSECS:-3} 2>/dev/null ;;
  record) perf record ${PERFARGS:--F 20000 -g} -o $W/perf.data -p $PO,$PI -- sleep ${PERFSECS:-3} >/dev/null 2>&1 ;;
  *) sleep ${PERFSECS:-3} ;;
esac
for i in $(seq 100); do ls $W/out/* >/dev/null 2>&1 && break; sleep 0.2; done
ls $W/out
if [ "${PERF:-}" = count ]; then kill -INT $PS; wait $PS; fi
$N --robot $R suspend pping >/dev/null 2>&1
kill $PI $PO; sleep 0.5; kill $RP; wait 2>/dev/null
$N --robot $R down >/dev/null 2>&1
echo "ping $PI pong $PO"
