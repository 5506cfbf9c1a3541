#!/bin/bash
# Optional check of the Slurm scripts on a single-node cluster on this machine (Debian's
# slurm-wlm and munge; as root): starts munged, slurmctld and slurmd with a throw-away
# configuration under $WORK, runs a sharded generation and a sharded evaluation through
# submit.sh, and checks that the sharded dataset and the merged table equal unsharded runs'
# byte for byte. Not part of the test suite (it needs root and starts daemons); stops the daemons
# it started on exit.
#   sudo apt-get install -y slurm-wlm munge && cargo build --release -p sim -p eval
#   bash scripts/slurm/local-test.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-$PWD/target/release}
export BIN
for b in sim eval; do
  [ -x "$BIN/$b" ] || { echo "no $BIN/$b: cargo build --release -p sim -p eval" >&2; exit 2; }
done
for c in slurmctld slurmd munged sbatch; do
  command -v "$c" >/dev/null || { echo "no $c: apt-get install -y slurm-wlm munge" >&2; exit 2; }
done
WORK=${WORK:-$(mktemp -d /tmp/slurm-local.XXXXXX)}
host=$(hostname -s)
mkdir -p "$WORK/state" "$WORK/spool"
cat > "$WORK/slurm.conf" <<CONF
ClusterName=local
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/slurmctld.log
SlurmdLogFile=$WORK/slurmd.log
JobCompType=jobcomp/none
NodeName=$host CPUs=$(nproc) State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$WORK/slurm.conf
started=()
cleanup() {
  for p in "${started[@]}"; do [ -f "$p" ] && kill "$(cat "$p")" 2>/dev/null || true; done
}
trap cleanup EXIT
if ! munge -n >/dev/null 2>&1; then
  mkdir -p /run/munge && chown munge: /run/munge
  [ -f /etc/munge/munge.key ] || { mungekey --create 2>/dev/null || /usr/sbin/create-munge-key; }
  munged --force --pid-file="$WORK/munged.pid" && started+=("$WORK/munged.pid")
fi
slurmctld -f "$SLURM_CONF" && started+=("$WORK/slurmctld.pid")
slurmd -f "$SLURM_CONF" && started+=("$WORK/slurmd.pid")
for _ in $(seq 30); do sinfo -h -o %t 2>/dev/null | grep -q idle && break; sleep 1; done
sinfo
# Waits until a job has left the queue (the comparisons below fail if it did not succeed).
wait_for() { while squeue -h -j "$1" 2>/dev/null | grep -q .; do sleep 2; done; }
cd "$WORK"
export SBATCH_ARGS="--chdir=$WORK"

echo "== sharded generation: T1, 6 episodes, 3 shards"
done_id=$(KIND=generate SHARDS=3 TASK=t1 EPISODES=6 VAL=1 SEED=3 SIZE=32 OUT=$WORK/gen_sharded \
  bash "$OLDPWD/scripts/slurm/submit.sh")
wait_for "$done_id"
"$BIN/sim" generate --task t1 --episodes 6 --val 1 --seed 3 --size 32 --out "$WORK/gen_whole" >/dev/null
for f in "$WORK"/gen_whole/episode_*.mcap "$WORK/gen_whole/index.json"; do
  cmp "$f" "$WORK/gen_sharded/$(basename "$f")"
done
echo "dataset: $(ls "$WORK"/gen_sharded/episode_*.mcap | wc -l) episodes and index.json identical to an unsharded run"

echo "== sharded evaluation: expert on t1,t3, 4 episodes, 2 shards"
args="--tasks t1,t3 --episodes 4 --seed 1000 --full-budget"
done_id=$(KIND=eval SHARDS=2 POLICY=expert OUT=$WORK/eval_sharded EVAL_ARGS="$args" \
  bash "$OLDPWD/scripts/slurm/submit.sh")
wait_for "$done_id"
# shellcheck disable=SC2086
"$BIN/eval" --policy expert $args --quiet --out "$WORK/eval_whole" >/dev/null
for f in results.md results.json results.csv; do cmp "$WORK/eval_whole/$f" "$WORK/eval_sharded/$f"; done
cat "$WORK/eval_sharded/results.md"
echo "merged table identical to an unsharded run's; Slurm logs:"
for log in "$WORK"/slurm-*.out; do echo "--- $(basename "$log")"; cat "$log"; done
echo "local Slurm check passed ($WORK)"
