#!/usr/bin/env bash
# Installs the system packages nerve needs on a fresh Debian machine (which
# has the Rust toolchain, cargo-nextest, gcc and Python). Idempotent: installs
# only what is missing. Used by `.ci/run` and `scripts/demo.sh`.
# `scripts/setup.sh --bench` also installs the peers of the benchmarks:
# cyclictest (rt-tests) and ddsperf (cyclonedds-tools).
set -euo pipefail
if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
need=()
command -v socat >/dev/null || need+=(socat)                       # linked pty pairs for serial work by hand
command -v systemd-analyze >/dev/null || need+=(systemd)           # `systemd-analyze verify` of the unit files
ls /usr/lib/llvm-*/lib/libclang*.so >/dev/null 2>&1 || need+=(libclang-dev)  # bindgen for the v4l camera backend
command -v ip >/dev/null || need+=(iproute2)                       # network namespaces and veth pairs of the bridge tests
python3 -c 'import ensurepip' 2>/dev/null || need+=(python3-venv)  # the virtual environment of the MCAP reader (tests/tests/record.rs)
if [ "${1:-}" = "--bench" ]; then
    command -v cyclictest >/dev/null || need+=(rt-tests)           # `nerve bench jitter`
    command -v ddsperf >/dev/null || need+=(cyclonedds-tools)      # `nerve bench hop`: Cyclone DDS
fi
if [ ${#need[@]} -gt 0 ]; then
    echo "installing: ${need[*]}"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi
