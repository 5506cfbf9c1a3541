#!/usr/bin/env bash
# kill -9 chaos, more than CI's 3 kills: `train` and `sim generate` killed with SIGKILL at random
# moments N times (default 20), then run to the end; the final weights (by tensor content) and
# the generated files (byte for byte) must equal an uninterrupted run's, with nothing left behind.
# Usage: bash scripts/chaos.sh [N] [SEED]   (the kill schedule follows SEED; default: from the clock)
set -euo pipefail
cd "$(dirname "$0")/.."
export CHAOS_KILLS="${1:-20}"
export CHAOS_SEED="${2:-$(date +%s)}"
echo "chaos: $CHAOS_KILLS kills per test, seed $CHAOS_SEED"
cargo test -q -p train --test chaos -- --nocapture
cargo test -q -p sim --test chaos -- --nocapture
