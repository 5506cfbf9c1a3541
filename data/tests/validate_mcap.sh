#!/usr/bin/env bash
# CI step: write synthetic episodes with the `data` binary and validate them with the reference
# MCAP reader (PyPI `mcap`). Usage: data/tests/validate_mcap.sh [PATH_TO_DATA_BINARY]
# Needs python3 with venv (Debian: python3-venv) and access to PyPI on first run.
# MCAP_VENV chooses the virtual environment (default /tmp/mcap-venv; created if missing).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
venv=${MCAP_VENV:-/tmp/mcap-venv}
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import mcap, mcap_protobuf, zstandard" 2>/dev/null; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q "mcap==1.6.0" "mcap-protobuf-support==0.6.0" "zstandard==0.25.0"
fi
bin=${1:-${CARGO_TARGET_DIR:-target}/debug/data}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$bin" synth --out "$out/synth" --episodes 4 --steps 30 --size 64
"$venv/bin/python" "$here/validate_mcap.py" "$out/synth"
