#!/usr/bin/env bash
# The main job on the built-in defaults: set-up, the simulator's self-check, then generate → train →
# eval on the tiny state-mode config: `train configs/state/tiny.toml` records 105 scripted-expert
# demonstrations of LIBERO-Mem T1 (datasets/t1_105p) when they are missing, trains a micro
# Embodied-SlotSSM on the objects' poses for 3 000 steps, and `eval` prints the subgoal table of
# its closed-loop evaluation on 20 held-out seeds (75 % success, 80 % subgoal completion measured,
# bit for bit the same on every run on one machine; README, "Quick start"). Everything builds in the dev profile (dependencies optimised), shared with
# `scripts/test.sh`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
cargo build -q -p sim -p train -p eval
BIN=target/debug
"$BIN/sim" info
"$BIN/sim" render --out out/agentview.png --task t1 --seed 0 --size 128
# A fresh run each time: a runs/state_tiny left by an older build may hold another model's weights.
rm -rf runs/state_tiny
"$BIN/train" configs/state/tiny.toml --run-dir runs/state_tiny
"$BIN/eval" --run runs/state_tiny --tasks t1 --seed 1000 --episodes 20 --full-budget --workers 2
