#!/usr/bin/env bash
# The main job: on a fresh machine, install what is missing, build nerve, and
# run the exploration experiment of the thesis (section 4.2) in simulation.
# Plots, CSV logs and summary.json land in out/explore-<seed>/ (or $1).
# It installs only what building and running nerve needs (`scripts/setup.sh`
# without `--test`: no Chromium) and builds, in release, only the programs
# the demo starts: `nerve` (router and launcher), `nerve-demo` (the demo
# itself, which `nerve demo` runs) and the agents of launch/explore.toml,
# not the benchmarks, the Python package or the test agents (`cargo build
# --release --workspace --bins` builds everything).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# kind `K` in the launch file is the program `nerve-K` of package `nerve-K`
kinds=$(sed -n 's/^kind = "\([a-z0-9-]*\)"$/\1/p' launch/explore.toml | sort -u)
if [ -z "$kinds" ]; then
    echo "demo.sh: found no agent kinds in launch/explore.toml" >&2
    exit 1
fi
build=(-p nerve --bin nerve -p nerve-demo --bin nerve-demo)
for kind in $kinds; do
    build+=(-p "nerve-$kind" --bin "nerve-$kind")
done
echo "== building nerve, nerve-demo and the demo's agents (release): $(echo $kinds)"
# without the release profile's line tables (debug = 1): a demo build does
# not need them, and generating and linking them for 17 programs costs time
CARGO_PROFILE_RELEASE_DEBUG=0 cargo build --release --locked "${build[@]}"
out="${1:-out/explore-1}"
# on simulated time at 4x (docs/time.md): the same run, its figures in
# simulated seconds, in a quarter of the wall time; NERVE_DEMO_SCALE=1 runs
# it in real time as the thesis did
scale="${NERVE_DEMO_SCALE:-4}"
echo "== running the exploration demo (about $((120 / scale + 10)) s at ${scale}x simulated time)"
"${CARGO_TARGET_DIR:-target}/release/nerve" --robot explore demo explore --seed 1 --out "$out" --sim-time --time-scale "$scale"
echo
echo "plots: $out/trajectory.png and $out/motion.png (SVG beside them); summary: $out/summary.json"
