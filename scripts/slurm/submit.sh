#!/bin/bash
# Submits a sharded generation or evaluation to Slurm: the array job (one task per shard) and the
# job that finishes it once every shard has succeeded (afterok). Prints the finishing job's id.
#   KIND=generate SHARDS=8 TASK=t3 EPISODES=1005 VAL=5 OUT=datasets/t3_1000 scripts/slurm/submit.sh
#   KIND=eval SHARDS=4 RUN=runs/state_t3 OUT=results/t3 EVAL_ARGS="--seed 1000 --full-budget" scripts/slurm/submit.sh
# Extra sbatch flags (partition, account, time) go in SBATCH_ARGS. Run from the repository root
# (the scripts call target/release/{sim,eval}; BIN overrides).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
: "${KIND:?set KIND=generate or KIND=eval}" "${SHARDS:?set SHARDS (number of array tasks)}"
export KIND
case "$KIND" in
  generate) array_script=$here/generate.sbatch ;;
  eval) array_script=$here/eval.sbatch ;;
  *) echo "KIND must be generate or eval, not $KIND" >&2; exit 2 ;;
esac
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_ARGS:-} --array=0-$((SHARDS - 1)) --export=ALL "$array_script")
# shellcheck disable=SC2086
sbatch --parsable ${SBATCH_ARGS:-} --dependency=afterok:"$array" --kill-on-invalid-dep=yes \
  --export=ALL "$here/finish.sbatch"
