#!/usr/bin/env python3
"""One way from an SDK sender to an SDK sink at several sending intervals,
with and without a PM QoS bound of 0 µs: how much of the one-way latency in
dora's pattern (a sample every 5 ms) is the time the two processes sleep
between samples rather than nerve's code path (BENCHMARKS.md §1, "A settled
batch").

It starts its own robot (a router and, per interval, the `bridge`
scenario's `__agent-bsend` and `__agent-bsink` of `nerve-bench`, connected
through the router), runs ROUNDS rounds in which every interval gets one
batch of N samples without the bound and one holding `/dev/cpu_dma_latency`
at 0 for the batch (as `nerve bench hop` does for its `-pmqos` rows), drops
the first 5 samples of each batch, and prints the median one-way latency
(the sink's arrival minus the sender's stamp, both CLOCK_MONOTONIC). A
sample the sink was too slow for is overwritten in its buffer, not
counted (a batch is then shorter than N). On stderr, each batch's median
and the time the hypervisor took from the guest meanwhile (`steal` of
/proc/stat).

    cargo build --release -p nerve -p nerve-bench
    python3 bench/py/oneway_interval.py 200 1000 5000 20000   # intervals in µs
    ROUNDS=3 N=200 ...                                        # the defaults

Run it on a quiet machine; it removes its robot (`nerve down`) at the end,
also when it fails.
"""

import os
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.path.join(REPO, "target", "release")
ROBOT = f"ow{os.getpid()}"
DISCARD = 5


def steal_ms() -> float:
    """CPU time the hypervisor gave to others while this guest's vCPUs
    wanted to run, all CPUs, ms (`steal` of /proc/stat, in USER_HZ ticks)."""
    with open("/proc/stat") as f:
        fields = f.readline().split()
    return int(fields[8]) * 1000 / os.sysconf("SC_CLK_TCK")


def main() -> int:
    intervals = [int(x) for x in sys.argv[1:]] or [200, 1000, 5000, 20000]
    n = int(os.environ.get("N", "200"))
    rounds = int(os.environ.get("ROUNDS", "3"))
    for exe in ("nerve", "nerve-bench"):
        if not os.access(os.path.join(BIN, exe), os.X_OK):
            print(f"no {exe} in {BIN}: run `cargo build --release -p nerve -p nerve-bench` first", file=sys.stderr)
            return 2
    work = tempfile.mkdtemp(prefix="nerve-oneway-")
    home = os.path.join(work, "home")
    os.makedirs(home)
    # the agents hold no bound of their own: the rows with it hold it here
    env = dict(os.environ, NERVE_HOME=home, NERVE_CPU_LATENCY="off")

    def nerve(*args: str) -> str:
        return subprocess.run(
            [os.path.join(BIN, "nerve"), "--robot", ROBOT, *args], env=env, capture_output=True, text=True, check=True
        ).stdout

    quiet = {"env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs = [subprocess.Popen([os.path.join(BIN, "nerve"), "--robot", ROBOT, "router"], **quiet)]
    try:
        deadline = time.time() + 10
        while True:
            try:
                nerve("ps")
                break
            except subprocess.CalledProcessError:
                if time.time() > deadline:
                    raise
                time.sleep(0.1)
        for iv in intervals:
            d = os.path.join(work, str(iv))
            os.makedirs(os.path.join(d, "s"))
            os.makedirs(os.path.join(d, "k"))
            for sub, name, out in (("__agent-bsend", f"s{iv}", "s"), ("__agent-bsink", f"k{iv}", "k")):
                args = ["--size", "8", "--count", str(n), "--interval-us", str(iv), "--out", os.path.join(d, out)]
                cmd = [os.path.join(BIN, "nerve-bench"), sub, "--robot", ROBOT, "--name", name, "--", *args]
                procs.append(subprocess.Popen(cmd, **quiet))
            for _ in range(100):
                listed = nerve("ps")
                if f"s{iv}" in listed and f"k{iv}" in listed:
                    break
                time.sleep(0.1)
            nerve("connect", f"s{iv}/out", f"k{iv}/in")
        results: dict[tuple[int, bool], list[float]] = {}
        for r in range(rounds):
            for held in (False, True):
                for iv in intervals:
                    sink = os.path.join(work, str(iv), "k")
                    before = set(os.listdir(sink))
                    fd = None
                    if held:
                        fd = os.open("/dev/cpu_dma_latency", os.O_WRONLY)
                        os.write(fd, struct.pack("i", 0))
                    try:
                        time.sleep(0.2)
                        steal0 = steal_ms()
                        nerve("suspend", f"s{iv}")
                        nerve("resume", f"s{iv}")
                        new: list[str] = []
                        t0 = time.time()
                        sent_by = n * iv / 1e6 + 0.5
                        while not new and time.time() - t0 < sent_by + 10:
                            time.sleep(0.05)
                            new = [f for f in os.listdir(sink) if f.startswith("batch-") and f not in before]
                            if not new and time.time() - t0 > sent_by:
                                # samples were lost (overwritten in a full
                                # buffer): a sink resumed after its input went
                                # quiet closes a short batch, as in the bench
                                nerve("suspend", f"k{iv}")
                                nerve("resume", f"k{iv}")
                                time.sleep(0.2)
                    finally:
                        if fd is not None:
                            os.close(fd)
                    if not new:
                        print(f"interval {iv} µs: no batch from the sink in {sink}: {sorted(os.listdir(sink))}; "
                              f"the sender's: {sorted(os.listdir(os.path.join(work, str(iv), 's')))}", file=sys.stderr)
                        print(nerve("ps"), file=sys.stderr)
                        return 1
                    time.sleep(0.05)  # written by rename: whole once it is there
                    with open(os.path.join(sink, new[0])) as f:
                        rows = [[int(x) for x in line.split()] for line in f if line.strip()]
                    batch = [(row[2] - row[0]) / 1e3 for row in rows[DISCARD:]]
                    results.setdefault((iv, held), []).extend(batch)
                    steal = steal_ms() - steal0
                    print(f"  interval {iv} µs, PM QoS {'held' if held else 'no'}: batch median "
                          f"{statistics.median(batch) if batch else float('nan'):.1f} µs, "
                          f"time stolen by the host {steal:.0f} ms (in steps of {1000 / os.sysconf('SC_CLK_TCK'):.0f} ms)",
                          file=sys.stderr)
            print(f"round {r + 1}/{rounds} done", file=sys.stderr)
        print("| interval µs | PM QoS 0 | n | one way p50 µs | p99 µs |")
        print("|---:|---|---:|---:|---:|")
        for (iv, held), v in sorted(results.items()):
            v.sort()
            p99 = v[min(len(v) - 1, int(0.99 * len(v)))]
            print(f"| {iv} | {'held' if held else 'no'} | {len(v)} | {statistics.median(v):.1f} | {p99:.1f} |")
        return 0
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
        subprocess.run([os.path.join(BIN, "nerve"), "--robot", ROBOT, "down"], env=env, capture_output=True)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
