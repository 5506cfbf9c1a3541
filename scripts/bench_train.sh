#!/usr/bin/env bash
# Training throughput: the real trainer (`train CONFIG --bench N`) on the t3 settings (tiny
# e_slotssm, B=8, T=16, 64², augmentation on) at 1 and 2 threads and at 2 threads with two
# data-parallel replicas (`train.replicas = 2`: half the batch each, one thread each), and — when its venv is present —
# the PyTorch twin of the tiny model (../shared/tools/torch_twin, the yardstick; not part of the
# product) timed in the same run, with the ratio ours / PyTorch per thread count (≤ 1: Burn no slower).
#
#   bash scripts/bench_train.sh [CONFIG] [STEPS]
#
# With the twin present, ROUNDS (default 3) more pairs follow — ours at 2 threads with 2 replicas,
# then the twin at 2 threads, alternating — and the median of their ratios is printed: on a
# shared machine the speed drifts by 10–40 % within minutes, which one pair cannot tell from a
# real difference.
#
# Environment: TORCH_TWIN (the twin's folder, default ../shared/tools/torch_twin), TORCH_TWIN_PYTHON
# (default ~/.venvs/torch_twin/bin/python). CONFIG defaults to configs/t3.toml, whose dataset is
# generated first when missing (100 expert episodes). Build: cargo build --release -p train.
set -euo pipefail
cd "$(dirname "$0")/.."
config=${1:-configs/t3.toml}
steps=${2:-10}
twin=${TORCH_TWIN:-../shared/tools/torch_twin}
py=${TORCH_TWIN_PYTHON:-$HOME/.venvs/torch_twin/bin/python}
bin=target/release/train
[ -x "$bin" ] || cargo build -q --release -p train
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# The twin's training step at the thread counts $1 (e.g. 1,2), one JSON line.
twin_bench() {
  (cd "$twin" && "$py" bench.py --steps 15 --warmup 3 --threads "$1" --skip-stream --set sa_dec_hidden=64)
}
# Ours at 2 threads with two data-parallel replicas, one JSON line.
ours_2r() {
  "$bin" "$config" --bench "$steps" --threads 2 --quiet --json --set train.replicas=2
}

for n in 1 2; do
  echo "== ours, $n thread(s): $bin $config --bench $steps --threads $n" >&2
  "$bin" "$config" --bench "$steps" --threads "$n" --quiet --json >"$out/ours_$n.json"
done
echo "== ours, 2 threads, 2 replicas: $bin $config --bench $steps --threads 2 --set train.replicas=2" >&2
ours_2r >"$out/ours_2r.json"
if [ -x "$py" ] && [ -f "$twin/bench.py" ]; then
  echo "== PyTorch twin: bench.py --steps 15 --warmup 3 --threads 1,2 --skip-stream --set sa_dec_hidden=64" >&2
  twin_bench 1,2 >"$out/twin.json"
  for r in $(seq 1 "${ROUNDS:-3}"); do
    echo "== round $r: ours (2 threads, 2 replicas), then the twin (2 threads)" >&2
    ours_2r >"$out/round_ours_$r.json"
    twin_bench 2 >"$out/round_twin_$r.json"
  done
else
  echo "(no PyTorch twin at $twin with $py: ours only)" >&2
fi

python3 - "$out" <<'EOF'
import json, os, sys
out = sys.argv[1]
ours = {n: json.load(open(f"{out}/ours_{n}.json")) for n in (1, 2, "2r")}
twin = json.load(open(f"{out}/twin.json")) if os.path.exists(f"{out}/twin.json") else None
r = ours[1]
print(f"trainer bench: {r['name']} ({r['variant']}, {r['params']} parameters, B={r['batch_size']}, T={r['window']}), "
      f"median of {r['steps']} steps after 3 untimed\n")
print("| threads | step ms | data wait | forward | backward | clip+AdamW | steps/s | PyTorch twin ms | ours / twin |")
print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for n in (1, 2, "2r"):
    o = ours[n]
    key = "train_step_ms_1thread" if n == 1 else "train_step_ms_2threads"
    t = twin.get(key) if twin else None
    ratio = f"{o['step_ms'] / t:.2f}" if t else "-"
    label = "2, 2 replicas" if n == "2r" else n
    print(f"| {label} | {o['step_ms']:.0f} | {o['data_ms']:.1f} | {o['forward_ms']:.0f} | "
          f"{o['backward_ms']:.0f} | {o['optim_ms']:.0f} | {o['steps_per_s']:.3f} | "
          f"{t if t else '-'} | {ratio} |")
o = ours["2r"]
print(f"\nloader alone: {o['loader_windows_per_s']:.0f} windows/s vs the trainer's "
      f"{o['trainer_windows_per_s']:.1f} at 2 threads, 2 replicas "
      f"({o['loader_windows_per_s'] / o['trainer_windows_per_s']:.0f}×)")
if twin:
    print(f"twin: torch {twin['torch_version']}, {twin['params']} parameters")
    rounds = sorted(f for f in os.listdir(out) if f.startswith("round_ours_"))
    ratios = []
    for f in rounds:
        r = f.removeprefix("round_ours_").removesuffix(".json")
        o = json.load(open(f"{out}/{f}"))["step_ms"]
        t = json.load(open(f"{out}/round_twin_{r}.json"))["train_step_ms_2threads"]
        ratios.append(o / t)
        print(f"round {r}: ours {o:.0f} ms (2 replicas), twin {t:.0f} ms (2 threads): {o / t:.2f}")
    if ratios:
        ratios.sort()
        print(f"median ratio over {len(ratios)} alternating rounds: {ratios[len(ratios) // 2]:.2f}")
EOF
