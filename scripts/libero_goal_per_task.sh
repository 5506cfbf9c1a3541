#!/usr/bin/env bash
# LIBERO-Goal with one state-mode policy per task (the per-task runs beside the suite's multi-task
# model): for each of the 10 tasks, trains configs/state/libero_goal.toml on that task's 150 demos
# only (its folder of DATA) for STEPS steps, then evaluates it on 20 held-out seeds from 1000 under
# the full budget, as the experiment does. Runs resume; a run evaluated already is skipped. Ends
# with one table, a row per task (its run's row of eval's results.md) and the means, printed and
# written to OUT.
#
#   bash scripts/libero_goal_per_task.sh [STEPS=3000] [JOBS=2] [OUT=docs/libero_goal_per_task.md] [DATA=datasets/libero_goal_150ph] [SEED=0]
#
# SEED is the training seed (`train.seed`; runs other than seed 0 get `_seed<SEED>` appended to their
# names), and TASKS (environment, comma-separated task names without `libero_goal/`) limits the run
# to those tasks, e.g. the seed spread of the README:
#   TASKS=push_the_plate_to_the_front_of_the_stove,open_the_middle_drawer_of_the_cabinet \
#     bash scripts/libero_goal_per_task.sh 3000 2 /tmp/seed1.md datasets/libero_goal_150p 1
#
# MASK_IDLE_TAIL=1 (environment) trains with `data.mask_idle_tail = true` (no action loss on the
# demos' idle tail: the arm standing still after its last move); its runs get `_masktail`.
# FINGERS=0 (environment) trains with `model.state_fingers = false` (the robot token without the
# finger joints, so the gripper command cannot be copied from them); its runs get `_nofingers`.
# QUERIES=step (environment) trains with one decoder query per chunk step
# (`[model.overrides] decoder = { queries = "step" }`) instead of one per action value; its runs
# get `_qstep`.
#
# DATA is a suite dataset with one folder per task. The default, demos that go on after the goal
# to release, retreat and stand still for 30 steps (what a policy evaluated over the full budget
# must do):
#   cargo run --release -p sim -- generate --task libero_goal --episodes 155 --val 5 --seed 0 \
#     --out datasets/libero_goal_150ph --workers 2 --plain-expert --size 32 --hold-steps 30
# (without `--hold-steps 30` and with `--out datasets/libero_goal_150p`: demos that end 10 steps
# after the goal, the multi-task config's data). Runs are named runs/lg_task_<task>_<STEPS>, with
# `_<DATA's folder name>` appended for any DATA but datasets/libero_goal_150p. Needs release builds
# of train and eval.
set -euo pipefail
cd "$(dirname "$0")/.."
steps=${1:-3000}
jobs=${2:-2}
out=${3:-docs/libero_goal_per_task.md}
data=${4:-datasets/libero_goal_150ph}
data=${data%/}
suffix=""
[[ $data == datasets/libero_goal_150p ]] || suffix="_$(basename "$data")"
seed=${5:-0}
[[ $seed =~ ^[0-9]+$ ]] || { echo "error: SEED \`$seed\` is not a non-negative integer" >&2; exit 2; }
[[ $seed == 0 ]] || suffix="${suffix}_seed$seed"
mask=${MASK_IDLE_TAIL:-0}
[[ $mask == 0 || $mask == 1 ]] || { echo "error: MASK_IDLE_TAIL \`$mask\` is not 0 or 1" >&2; exit 2; }
[[ $mask == 0 ]] || suffix="${suffix}_masktail"
mask_set="data.mask_idle_tail=$([[ $mask == 1 ]] && echo true || echo false)"
fingers=${FINGERS:-1}
[[ $fingers == 0 || $fingers == 1 ]] || { echo "error: FINGERS \`$fingers\` is not 0 or 1" >&2; exit 2; }
[[ $fingers == 1 ]] || suffix="${suffix}_nofingers"
fingers_set="model.state_fingers=$([[ $fingers == 1 ]] && echo true || echo false)"
queries=${QUERIES:-value}
[[ $queries == value || $queries == step ]] || { echo "error: QUERIES \`$queries\` is not value or step" >&2; exit 2; }
[[ $queries == value ]] || suffix="${suffix}_qstep"
queries_set="model.overrides.decoder.queries=\"$queries\""
[[ -d $data ]] || { echo "error: $data is missing (see the header of $0 for the command that records it)" >&2; exit 2; }
[[ -x target/release/train && -x target/release/eval ]] || { echo "error: build first: cargo build --release -p train -p eval" >&2; exit 2; }

one() {
  # Run by xargs in a fresh bash, which does not inherit the options set above: a failed
  # training or evaluation must fail this task (and, through xargs, the script).
  set -euo pipefail
  local task=$1 steps=$2 data=$3 suffix=$4 seed=$5 mask_set=$6 fingers_set=$7 queries_set=$8
  local stem=${task#libero_goal/}
  local run=runs/lg_task_${stem}_${steps}${suffix}
  if [[ ! -f $run/eval/results.json ]]; then
    ./target/release/train configs/state/libero_goal.toml --quiet --steps "$steps" --run-dir "$run" \
      --set "name=\"lg_task_${stem}_${steps}${suffix}\"" --set train.stagger=false --set "train.seed=$seed" \
      --set "$mask_set" --set "$fingers_set" --set "$queries_set" --set "data.dir=\"$data/libero_goal_${stem}\"" --set "eval.tasks=[\"$task\"]" >"$run.log" 2>&1
    ./target/release/eval --run "$run" --tasks "$task" --episodes 20 --seed 1000 --full-budget \
      --workers 1 --quiet >>"$run.log" 2>&1
  fi
  echo "$run"
}
export -f one
mkdir -p runs
tasks=$(./target/release/sim tasks | awk '$1 ~ /^libero_goal\// {print $1}')
if [[ -n ${TASKS:-} ]]; then
  picked=""
  for t in ${TASKS//,/ }; do
    grep -qx "libero_goal/$t" <<<"$tasks" || { echo "error: TASKS: \`$t\` is not a LIBERO-Goal task (\`sim tasks\` lists them)" >&2; exit 2; }
    picked="$picked libero_goal/$t"
  done
  tasks=$picked
fi
for t in $tasks; do
  [[ -f $data/libero_goal_${t#libero_goal/}/index.json ]] || {
    echo "error: $data/libero_goal_${t#libero_goal/} holds no generated dataset (see the header of $0 for the command that records it)" >&2
    exit 2
  }
done
runs=$(printf '%s\n' $tasks | xargs -P "$jobs" -I{} bash -c 'one "$@"' _ {} "$steps" "$data" "$suffix" "$seed" "$mask_set" "$fingers_set" "$queries_set" | sort) || {
  echo "error: a task's training or evaluation failed; see runs/lg_task_*_$steps$suffix.log" >&2
  exit 1
}
{
  echo "LIBERO-Goal, one state-mode e_slotssm_oracle policy per task, $steps steps each (training seed"
  echo "$seed) on the task's 150 demos of $data; 20 seeds from 1000, full budget:"
  [[ $mask == 0 ]] || echo "No action loss on the demos' idle tail (\`data.mask_idle_tail = true\`)."
  [[ $fingers == 1 ]] || echo "The robot token without the finger joints (\`model.state_fingers = false\`)."
  [[ $queries == value ]] || echo "One decoder query per chunk step (\`decoder = { queries = \"step\" }\`)."
  echo "\`${TASKS:+TASKS=$TASKS }${MASK_IDLE_TAIL:+MASK_IDLE_TAIL=$MASK_IDLE_TAIL }${FINGERS:+FINGERS=$FINGERS }${QUERIES:+QUERIES=$QUERIES }bash scripts/libero_goal_per_task.sh $steps $jobs $out $data $seed\`"
  echo
  echo "| task | episodes | subgoal completion % (95 % CI) | success % (95 % CI) | mean steps | over-repetition |"
  echo "|---|---:|---:|---:|---:|---:|"
  for r in $runs; do grep '^| libero_goal/' "$r/eval/results.md"; done
} >"$out.tmp"
awk -F'|' '/^\| libero_goal\// {c += $4; s += $5; n++} END {printf "| **mean of %d policies** | | %.1f | %.1f | | |\n", n, c / n, s / n}' \
  "$out.tmp" >>"$out.tmp"
mv "$out.tmp" "$out"
cat "$out"
