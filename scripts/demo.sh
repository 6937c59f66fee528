#!/usr/bin/env bash
# The main job: on a fresh machine, install what is missing, build nerve, and
# run the exploration experiment of the thesis (section 4.2) in simulation.
# Plots, CSV logs and summary.json land in out/explore-<seed>/ (or $1).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
echo "== building nerve and its agents (release)"
cargo build --release --workspace --bins
out="${1:-out/explore-1}"
echo "== running the exploration demo (about 2 minutes)"
target/release/nerve --robot explore demo explore --seed 1 --out "$out"
echo
echo "plots: $out/trajectory.png and $out/motion.png (SVG beside them); summary: $out/summary.json"
