#!/usr/bin/env bash
# The main job on the built-in defaults: set-up, the simulator's self-check, then the furthest chain that
# works end to end today — train the tiny config (which first records its T1 expert demonstrations through
# the simulator when datasets/tiny is missing), and print
# the subgoal table of a closed-loop evaluation of its checkpoint.
# Everything builds in the dev profile (dependencies optimised), shared with `scripts/test.sh`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
cargo build -q -p sim -p train -p eval
BIN=target/debug
"$BIN/sim" info
"$BIN/sim" render --out out/agentview.png --task t1 --seed 0 --size 128
# A fresh run each time: a runs/tiny left by an older build may hold another model's weights.
rm -rf runs/tiny
"$BIN/train" configs/tiny.toml --run-dir runs/tiny
"$BIN/eval" --run runs/tiny --tasks t1 --episodes 2 --workers 2
