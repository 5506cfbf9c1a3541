#!/usr/bin/env bash
# The cost of openpi's websocket protocol in `eval --policy ws://`: env steps/s of an evaluation
# against a trivial Python server (zero actions, eval/tests/replay_server.py --zeros; the client
# renders both cameras at 256² and sends 2×224² images each step, --replan-steps 1; also with 5),
# against `eval --policy zero` (no rendering, no protocol) in the same run: the ratio is what
# rendering plus the protocol cost.
#
#   bash scripts/bench_remote.sh [TASK=t1] [EPISODES=4]
#
# Needs a release build of eval and the test venv (scripts/test.sh makes target/mcap-venv).
set -euo pipefail
cd "$(dirname "$0")/.."
task=${1:-t1}
episodes=${2:-4}
py=${EVAL_WS_PYTHON:-target/mcap-venv/bin/python}
[[ -x target/release/eval ]] || { echo "error: build first: cargo build --release -p eval" >&2; exit 2; }
"$py" -c "import websockets, msgpack" 2>/dev/null || { echo "error: $py lacks websockets/msgpack (run scripts/test.sh once)" >&2; exit 2; }
tmp=$(mktemp -d)
trap 'kill $server 2>/dev/null || true; rm -rf "$tmp"' EXIT
"$py" eval/tests/replay_server.py --zeros > "$tmp/port" &
server=$!
for _ in $(seq 50); do [[ -s $tmp/port ]] && break; sleep 0.1; done
port=$(awk '{print $2}' "$tmp/port")
steps_per_s() { # label, then eval's arguments
  local label=$1; shift
  local t0 t1
  t0=$(date +%s.%N)
  ./target/release/eval --tasks "$task" --episodes "$episodes" --seed 0 --full-budget --quiet --out "$tmp/out" "$@" >/dev/null 2>&1
  t1=$(date +%s.%N)
  local steps
  steps=$(python3 -c "import json;print(sum(e['steps'] for e in json.load(open('$tmp/out/results.json'))['episodes']))")
  python3 -c "print('%-58s %6d steps %7.2f s %8.1f steps/s' % ('$label', $steps, $t1-$t0, $steps/($t1-$t0)))"
}
echo "task $task, $episodes episodes, full budget, 1 worker"
steps_per_s "eval --policy zero (no rendering)" --policy zero
steps_per_s "eval --policy ws:// (zeros server, 2×224² per step)" --policy "ws://127.0.0.1:$port" --replan-steps 1
steps_per_s "eval --policy ws:// --replan-steps 5" --policy "ws://127.0.0.1:$port" --replan-steps 5
