#!/bin/bash
# local-slurm-mpi-test.sh — MPI training under Slurm end to end on one machine: brings up a
# single-node Slurm on localhost (munge, slurmctld, slurmd, all under a temporary folder, as
# local-slurm-test.sh does), makes a two-shot training set, trains it once plainly (one process),
# then runs pmsc-train-mpi.sbatch as a 2-task job twice — ranks started by `srun --mpi=pmix` and
# by `mpirun` inside the allocation — and checks that
#   1. both jobs succeeded and their summaries say 2 MPI processes,
#   2. each model equals the local one (same M and keys, basis angle < 1e-9, same residual),
# then ALWAYS stops the daemons by their pid files. Needs root, slurm-wlm, munge and Open MPI;
# exits 77 (skipped) without them.
#
#   local-slurm-mpi-test.sh --pmsc build/bin/pmsc --make-frames build/bin/pmsc_scaleout_frames \
#       --compare build/bin/pmsc_scaleout_compare [--grid 40] [--timeout 170] [--keep]
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
pmsc="" maker="" compare="" grid=40 budget=170 keep=0
while (($#)); do
  case $1 in
    --pmsc) pmsc=$2; shift 2 ;;
    --make-frames) maker=$2; shift 2 ;;
    --compare) compare=$2; shift 2 ;;
    --grid) grid=$2; shift 2 ;;
    --timeout) budget=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    *) echo "local-slurm-mpi-test: unknown argument '$1'" >&2; exit 2 ;;
  esac
done
say() { echo "local-slurm-mpi-test: $*"; }
fail() { echo "local-slurm-mpi-test: FAILED: $*" >&2; exit 1; }
skip() { echo "local-slurm-mpi-test: SKIPPED: $*"; exit 77; }

[ -n "$pmsc" ] && [ -n "$maker" ] && [ -n "$compare" ] ||
  { echo "usage: $0 --pmsc PMSC --make-frames TOOL --compare TOOL" >&2; exit 2; }
pmsc=$(realpath "$pmsc") maker=$(realpath "$maker") compare=$(realpath "$compare")
[ "$(id -u)" = 0 ] || skip "needs root (munged and slurmd run as root here)"
for c in munged slurmctld slurmd sbatch squeue sinfo scancel srun mpirun; do
  command -v "$c" >/dev/null || skip "$c not installed (Debian: apt-get install slurm-wlm munge openmpi-bin)"
done

start=$(date +%s)
deadline=$((start + budget))
left() { echo $((deadline - $(date +%s))); }

work=$(mktemp -d /tmp/pmsc-slurm-mpi.XXXXXX) || fail "mktemp"
chmod 755 "$work"
mkdir -p "$work"/{munge,state,spool,log,run,logs}
pidfiles=("$work/run/slurmd.pid" "$work/run/slurmctld.pid" "$work/munge/munged.pid")
watchdog=""
stop_daemons() {
  local f pid pids=() i
  for f in "${pidfiles[@]}"; do
    [ -s "$f" ] || continue
    pid=$(cat "$f" 2>/dev/null)
    [[ $pid =~ ^[0-9]+$ ]] && kill -TERM "$pid" 2>/dev/null && pids+=("$pid")
  done
  for pid in "${pids[@]}"; do
    for i in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -0 "$pid" 2>/dev/null && kill -KILL "$pid" 2>/dev/null
  done
  return 0
}
cleanup() {
  local status=$? f
  trap - EXIT INT TERM
  trap '' PIPE
  [ -n "$watchdog" ] && kill "$watchdog" 2>/dev/null
  stop_daemons
  if ((status != 0 && status != 77)); then
    for f in "$work"/logs/* "$work"/log/*.log; do [ -f "$f" ] && { echo "--- tail of $f"; tail -n 15 "$f"; }; done >&2
  fi
  if ((keep)); then say "kept $work"; else rm -rf "$work"; fi
  exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM
(
  trap - EXIT
  sleep $((budget + 20))
  for f in "${pidfiles[@]}"; do [ -s "$f" ] && kill -KILL "$(cat "$f")" 2>/dev/null; done
) </dev/null >/dev/null 2>&1 &
watchdog=$!

# --- the training set: two shots, the second in float32, and the one-process model --------------
"$maker" "$work/shot1.npy" "$grid" 120 11 float64 && "$maker" "$work/shot2.npy" "$grid" 80 12 float32 ||
  fail "cannot make the training shots"
trainOptions=(--max-keys 40 --tolerance 0.02)
timeout "$(left)" "$pmsc" train --frames "$work/shot1.npy" --frames "$work/shot2.npy" --out "$work/local.pmsc" \
  --quiet "${trainOptions[@]}" >"$work/logs/local.log" 2>&1 || fail "local pmsc train"

# --- munge and Slurm, everything under $work ------------------------------------------------------
chown munge:munge "$work/munge" 2>/dev/null
chmod 700 "$work/munge"
dd if=/dev/urandom of="$work/munge/munge.key" bs=1 count=1024 status=none || fail "munge key"
chown munge:munge "$work/munge/munge.key" 2>/dev/null
chmod 400 "$work/munge/munge.key"
timeout 20 munged --force --key-file="$work/munge/munge.key" --socket="$work/munge/munge.socket" \
  --pid-file="$work/munge/munged.pid" --log-file="$work/munge/munged.log" \
  --seed-file="$work/munge/munged.seed" 2>>"$work/log/munged.stderr" || fail "munged did not start"
listening() {
  local hex
  hex=$(printf '%04X' "$1")
  cat /proc/net/tcp /proc/net/tcp6 2>/dev/null | awk '{print $2}' | grep -qi ":$hex\$"
}
port=$((20000 + (RANDOM % 20000) * 2))
for _ in $(seq 200); do
  if ! listening "$port" && ! listening $((port + 1)); then break; fi
  port=$((20000 + (RANDOM % 20000) * 2))
done
host=$(hostname -s)
export SLURM_CONF=$work/slurm.conf
cat >"$SLURM_CONF" <<CONF
ClusterName=pmscmpi
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$work/munge/munge.socket
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/run/slurmctld.pid
SlurmdPidFile=$work/run/slurmd.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN
PartitionName=pmsc Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
timeout 20 slurmctld -c || fail "slurmctld did not start"
timeout 20 slurmd -c || fail "slurmd did not start"
until [ "$(timeout 5 sinfo -h -n "$host" -o %T 2>/dev/null)" = idle ]; do
  (($(left) > 0)) || fail "node $host never became idle"
  sleep 0.5
done
say "slurm up on $host; srun knows the MPI plugins: $(srun --mpi=list 2>&1 | grep -o 'pmix[_a-z0-9]*\|pmi2' | sort -u | paste -sd' ')"

# --- the 2-task jobs ----------------------------------------------------------------------------------
for launch in srun mpirun; do
  job=$(timeout 20 sbatch --parsable --ntasks=2 --cpus-per-task=1 --output="$work/logs/job-$launch.log" \
    --chdir="$work" --export="ALL,PMSC=$pmsc,PMSC_MPI_LAUNCH=$launch,OMPI_ALLOW_RUN_AS_ROOT=1,OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1" \
    "$here/pmsc-train-mpi.sbatch" "$work/mpi-$launch.pmsc" "$work/shot1.npy" "$work/shot2.npy" -- "${trainOptions[@]}") ||
    fail "sbatch ($launch)"
  job=${job%%;*}
  say "submitted 2-task job $job (ranks started by $launch)"
  while [ -n "$(timeout 5 squeue -h -j "$job" -o %T 2>/dev/null)" ]; do
    if (($(left) <= 0)); then
      timeout 10 scancel "$job"
      fail "job $job ($launch) did not finish within ${budget}s"
    fi
    sleep 0.3
  done
  log=$work/logs/job-$launch.log
  grep -q "^pmsc-train-mpi: end .* exit 0$" "$log" || fail "job $job ($launch) failed: $(tail -n 5 "$log")"
  grep -q "2 MPI processes" "$log" || fail "job $job ($launch) did not train on 2 ranks: $(tail -n 12 "$log")"
  verdict=$("$compare" "$work/local.pmsc" "$work/mpi-$launch.pmsc") ||
    fail "the $launch job's model differs from the local one: $verdict"
  say "$launch: $verdict"
done
say "PASSED: the 2-task MPI training jobs (srun --mpi=pmix, mpirun in sbatch) equal one local process, in $(($(date +%s) - start)) s"
