#!/usr/bin/env bash
# The main job on the built-in defaults. Today the furthest step that works end to end is the simulator:
# print the MuJoCo/GL set-up, reset the LIBERO tabletop scene, render both cameras, and measure throughput.
# (generate → train → eval on the tiny config replaces this as those crates land.)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
cargo build -q --release -p sim
SIM=target/release/sim
"$SIM" info
"$SIM" render --out out/agentview.png --camera agentview --size 128 --seed 0
"$SIM" render --out out/eye_in_hand.png --camera robot0_eye_in_hand --size 128 --seed 0
"$SIM" bench
