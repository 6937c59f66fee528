#!/usr/bin/env bash
# Installs the system packages nerve needs on a fresh Debian machine (which
# has the Rust toolchain, cargo-nextest, gcc and Python). Idempotent: installs
# only what is missing. Used by `scripts/demo.sh` (no flag: only what
# building and running nerve needs) and `.ci/run` (`--test`).
# `scripts/setup.sh --test` also installs what the tests alone need: socat,
# systemd (`systemd-analyze`), iproute2 (network namespaces), python3-venv,
# g++ and cmake (C and C++ agents) and headless Chromium with its WebDriver (`nerve ui`'s page tests); the
# flags combine (`--test --bench`).
# `scripts/setup.sh --bench` also installs the peers of the benchmarks:
# cyclictest (rt-tests), ddsperf (cyclonedds-tools) and Chromium, and builds dora-rs
# (its CLI `dora` and the two nodes of bench/dora, both 1.1.0 from crates.io)
# once into a cache outside the repository:
# ${NERVE_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/nerve-bench}/dora
# (about 22 min on 2 cores the first time; skipped when already built).
set -euo pipefail
if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
bench=0
test=0
for flag in "$@"; do
    case "$flag" in
        --bench) bench=1 ;;
        --test) test=1 ;;
        *) echo "setup.sh: unknown flag $flag (known: --test, --bench)" >&2; exit 2 ;;
    esac
done
need=()
# building nerve (the demo's only need): bindgen for iceoryx2's and the v4l camera backend's bindings
ls /usr/lib/llvm-*/lib/libclang*.so >/dev/null 2>&1 || need+=(libclang-dev)
if [ $test = 1 ]; then
    command -v socat >/dev/null || need+=(socat)                       # linked pty pairs for serial work by hand
    command -v systemd-analyze >/dev/null || need+=(systemd)           # `systemd-analyze verify` of the unit files
    command -v ip >/dev/null || need+=(iproute2)                       # network namespaces and veth pairs of the bridge tests
    command -v chromedriver >/dev/null || need+=(chromium-driver)      # `nerve ui`'s tests drive Chromium through WebDriver (tests/src/browser.rs)
    python3 -c 'import ensurepip' 2>/dev/null || need+=(python3-venv)  # the virtual environment of the MCAP reader (tests/tests/record.rs)
    command -v g++ >/dev/null || need+=(g++)                           # the C++ agents of agent-sdk-c (nerve.hpp) and `nerve new --lang cpp`
    command -v cmake >/dev/null || need+=(cmake)                       # the projects of `nerve new --lang c|cpp` (agent-sdk-c/tests/new_project.rs)
    command -v pkg-config >/dev/null || need+=(pkg-config)             # libnerve's nerve.pc (agent-sdk-c/tests/c_harness.rs)
fi
if [ $test = 1 ] || [ $bench = 1 ]; then
    command -v chromium >/dev/null || need+=(chromium)                 # headless: `nerve ui`'s tests, and `nerve bench ui`'s page load
fi
if [ $bench = 1 ]; then
    command -v cyclictest >/dev/null || need+=(rt-tests)           # `nerve bench jitter`
    command -v ddsperf >/dev/null || need+=(cyclonedds-tools)      # `nerve bench hop`: Cyclone DDS
    command -v pkg-config >/dev/null || need+=(pkg-config)         # dora-cli: openssl-sys (through git2) finds OpenSSL with it
    pkg-config --exists openssl 2>/dev/null || need+=(libssl-dev)
fi
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
if [ $bench = 1 ]; then
    # dora-rs, the peer of `nerve bench hop` (bench/src/dora.rs reads the same path)
    dora_version=1.1.0
    cache="${NERVE_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/nerve-bench}/dora"
    repo="$(cd "$(dirname "$0")/.." && pwd)"
    mkdir -p "$cache"
    if ! "$cache/bin/dora" --version 2>/dev/null | grep -qF "$dora_version"; then
        echo "building dora-cli $dora_version into $cache (about 15 min on 2 cores, once)"
        t0=$(date +%s)
        cargo install dora-cli --version "$dora_version" --locked --root "$cache" --quiet
        echo "dora-cli $dora_version built in $(( ($(date +%s) - t0) / 60 )) min"
    fi
    # the nodes: cargo rebuilds only what changed (a second or so when nothing did)
    if [ ! -x "$cache/target/release/nerve-dora-ping" ] || [ ! -x "$cache/target/release/nerve-dora-pong" ]; then
        echo "building the dora nodes of bench/dora (dora-node-api $dora_version) into $cache (about 7 min on 2 cores, once)"
    fi
    cargo build --release --locked --quiet --manifest-path "$repo/bench/dora/Cargo.toml" --target-dir "$cache/target"
fi
