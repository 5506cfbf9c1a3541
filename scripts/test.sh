#!/usr/bin/env bash
# The whole test suite: set-up, then every crate's tests (dev profile; dependencies are built optimised).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo test --workspace --no-fail-fast 2>&1
