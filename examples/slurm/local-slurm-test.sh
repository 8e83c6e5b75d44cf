#!/bin/bash
# local-slurm-test.sh — the render-farm path end to end on one machine: brings up a single-node
# Slurm on localhost (munge, slurmctld, slurmd with a generated slurm.conf, all under a temporary
# folder), renders a shot as an array job of pmsc-array.sbatch tasks, and checks that
#   1. every task succeeded and every frame file is there,
#   2. the frames are byte-identical to one local `pmsc run` of the whole shot,
#   3. tasks really ran at the same time (from the start/end timestamps the tasks print, or from
#      the start/end of each task in slurmctld's log; squeue's most RUNNING at once is shown too),
# then ALWAYS stops the daemons by the pids they wrote (trap; a watchdog does it even if this
# script is killed). Needs root and Debian's slurm-wlm + munge; exits 77 (skipped) without them.
#
#   local-slurm-test.sh --pmsc build/bin/pmsc --asset /usr/share/assimp/models/X/Testwuson.X:animation=Wuson_Walk
#   local-slurm-test.sh --pmsc build/bin/pmsc --model MODEL --evaluator SPEC --frames A-B
#
# Options: --tasks T (4) array tasks, --parallel P (2) at a time, --timeout S (150) for the whole
# test, --keep (leave the temporary folder), --workdir DIR (instead of a new temporary folder).
# With --asset the script makes its own training frames (pmsc export-frames) and model (pmsc train
# with --train-options, default "--max-keys 40"); the shot is then every frame of the asset.
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
pmsc="" model="" evaluator="" frames="" asset="" tasks=4 parallel=2 budget=150 keep=0 work=""
trainOptions="--max-keys 40"
while (($#)); do
  case $1 in
    --pmsc) pmsc=$2; shift 2 ;;
    --model) model=$2; shift 2 ;;
    --evaluator) evaluator=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --asset) asset=$2; shift 2 ;;
    --train-options) trainOptions=$2; shift 2 ;;
    --tasks) tasks=$2; shift 2 ;;
    --parallel) parallel=$2; shift 2 ;;
    --timeout) budget=$2; shift 2 ;;
    --workdir) work=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    *) echo "local-slurm-test: unknown argument '$1'" >&2; exit 2 ;;
  esac
done

say() { echo "local-slurm-test: $*"; }
fail() { echo "local-slurm-test: FAILED: $*" >&2; exit 1; }
skip() { echo "local-slurm-test: SKIPPED: $*"; exit 77; }

[ -n "$pmsc" ] || { echo "usage: $0 --pmsc PMSC (--asset ASSET | --model M --evaluator E --frames A-B)" >&2; exit 2; }
pmsc=$(realpath "$pmsc")
[ -x "$pmsc" ] || fail "no pmsc program at $pmsc"
[ -n "$asset" ] || [ -n "$model" ] || fail "give --asset or --model/--evaluator/--frames"
[ "$(id -u)" = 0 ] || skip "needs root (munged and slurmd run as root here)"
for c in munged slurmctld slurmd sbatch squeue scontrol sinfo scancel; do
  command -v "$c" >/dev/null || skip "$c not installed (Debian: apt-get install slurm-wlm munge)"
done

start=$(date +%s)
deadline=$((start + budget))
left() { echo $((deadline - $(date +%s))); }

# --- temporary world, and the guarantee that it goes away -------------------------------------------
if [ -z "$work" ]; then work=$(mktemp -d /tmp/pmsc-slurm.XXXXXX) || fail "mktemp"; fi
mkdir -p "$work" && chmod 755 "$work"
work=$(realpath "$work")
mkdir -p "$work"/{munge,state,spool,log,run,logs}
pidfiles=("$work/run/slurmd.pid" "$work/run/slurmctld.pid" "$work/munge/munged.pid")
watchdog=""

stop_daemons() {  # TERM to all three at once, then wait (bounded), then KILL what is left
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
  local status=$?
  trap - EXIT INT TERM
  trap '' PIPE  # a reader that went away (| head) must not stop the clean-up half way
  [ -n "$watchdog" ] && kill "$watchdog" 2>/dev/null
  stop_daemons
  if ((status != 0 && status != 77)); then
    for f in "$work"/logs/*.log "$work"/log/*.log "$work"/munge/munged.log; do
      [ -f "$f" ] && { echo "--- tail of $f"; tail -n 15 "$f"; }
    done >&2
  fi
  if ((keep)); then say "kept $work"; else rm -rf "$work"; fi
  exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM
# If this script is killed outright (no trap runs), a detached watchdog still stops the daemons
# by their pid files shortly after the budget runs out.
(
  trap - EXIT
  sleep $((budget + 20))
  for f in "${pidfiles[@]}"; do [ -s "$f" ] && kill -KILL "$(cat "$f")" 2>/dev/null; done
) </dev/null >/dev/null 2>&1 &
watchdog=$!

# --- the shot: a given model, or one trained here from an animated asset ---------------------------
if [ -n "$asset" ]; then
  evaluator="skin:$asset"
  say "exporting training frames of $asset"
  timeout "$(left)" "$pmsc" export-frames "$evaluator" --out "$work/train.npy" || fail "pmsc export-frames"
  # shellcheck disable=SC2086
  timeout "$(left)" "$pmsc" train --frames "$work/train.npy" --out "$work/model.pmsc" $trainOptions >"$work/logs/train.log" 2>&1 ||
    fail "pmsc train"
  model=$work/model.pmsc
  if [ -z "$frames" ]; then
    count=$(head -c 256 "$work/train.npy" | tr -d '\0' | grep -ao "'shape': *([0-9]*" | grep -o '[0-9]*$')
    [[ $count =~ ^[0-9]+$ ]] || fail "cannot read the frame count of $work/train.npy"
    frames="0-$((count - 1))"
  fi
fi
[ -n "$model" ] && [ -n "$evaluator" ] && [ -n "$frames" ] || fail "--model, --evaluator and --frames are needed"
[[ $frames =~ ^([0-9]+)-([0-9]+)$ ]] || fail "--frames must be FIRST-LAST"
first=${BASH_REMATCH[1]} last=${BASH_REMATCH[2]}
nframes=$((last - first + 1))

# --- munge: our own key and socket, nothing of the system's ------------------------------------------
chown munge:munge "$work/munge" 2>/dev/null
chmod 700 "$work/munge"
dd if=/dev/urandom of="$work/munge/munge.key" bs=1 count=1024 status=none || fail "munge key"
chown munge:munge "$work/munge/munge.key" 2>/dev/null
chmod 400 "$work/munge/munge.key"
timeout 20 munged --force --key-file="$work/munge/munge.key" --socket="$work/munge/munge.socket" \
  --pid-file="$work/munge/munged.pid" --log-file="$work/munge/munged.log" \
  --seed-file="$work/munge/munged.seed" 2>>"$work/log/munged.stderr" || fail "munged did not start"

# --- two free TCP ports -----------------------------------------------------------------------------
listening() {  # port in use (any state) on IPv4 or IPv6?
  local hex
  hex=$(printf '%04X' "$1")
  cat /proc/net/tcp /proc/net/tcp6 2>/dev/null | awk '{print $2}' | grep -qi ":$hex\$"
}
port=$((20000 + (RANDOM % 20000) * 2))
for _ in $(seq 200); do
  if ! listening "$port" && ! listening $((port + 1)); then break; fi
  port=$((20000 + (RANDOM % 20000) * 2))
done
ctldPort=$port slurmdPort=$((port + 1))

# --- slurm.conf: one node, CPUs=2, everything under $work --------------------------------------------
host=$(hostname -s)
export SLURM_CONF=$work/slurm.conf
cat >"$SLURM_CONF" <<EOF
ClusterName=pmsctest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctldPort
SlurmdPort=$slurmdPort
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
EOF
timeout 20 slurmctld -c || fail "slurmctld did not start"
timeout 20 slurmd -c || fail "slurmd did not start"
say "slurm up on $host (ports $ctldPort/$slurmdPort), waiting for the node"
until [ "$(timeout 5 sinfo -h -n "$host" -o %T 2>/dev/null)" = idle ]; do
  (($(left) > 0)) || fail "node $host never became idle"
  sleep 0.5
done

# --- the reference: one local run of the whole shot --------------------------------------------------
say "local reference run: frames $frames"
# Every core here, one per task on the farm: the frames must not depend on it.
timeout "$(left)" "$pmsc" run --model "$model" --evaluator "$evaluator" --frames "$frames" \
  --out "$work/local" >"$work/logs/local.log" 2>&1 || fail "local pmsc run"

# --- the array job --------------------------------------------------------------------------------------
job=$(timeout 20 sbatch --parsable --array="0-$((tasks - 1))%$parallel" --cpus-per-task=1 \
  --output="$work/logs/task-%a.log" --chdir="$work" --export="ALL,PMSC=$pmsc" \
  "$here/pmsc-array.sbatch" "$model" "$evaluator" "$frames" "$work/farm" --threads 1) || fail "sbatch"
job=${job%%;*}
say "submitted array job $job: $tasks tasks, $parallel at a time"
mostRunning=0
while :; do
  states=$(timeout 5 squeue -h -j "$job" -o %T 2>/dev/null) || states="?"
  running=$(grep -c '^RUNNING$' <<<"$states")
  ((running > mostRunning)) && mostRunning=$running
  [ -z "$states" ] && break
  if (($(left) <= 0)); then
    timeout 10 scancel "$job"
    fail "array job $job did not finish within ${budget}s"
  fi
  sleep 0.2
done

# --- checks -------------------------------------------------------------------------------------------
problems=0
for ((i = 0; i < tasks; i++)); do
  log=$work/logs/task-$i.log
  if ! grep -q "^pmsc-array: task $i .* end .* exit 0$" "$log" 2>/dev/null; then
    echo "task $i did not succeed:" >&2
    tail -n 5 "$log" >&2 2>/dev/null
    problems=$((problems + 1))
  fi
done
((problems == 0)) || fail "$problems array task(s) failed"

mapfile -t localFiles < <(cd "$work/local" && ls | grep '^frame\.' | sort)
mapfile -t farmFiles < <(cd "$work/farm" && ls | grep '^frame\.' | sort)
((${#localFiles[@]} == nframes)) || fail "local run wrote ${#localFiles[@]} frames, expected $nframes"
((${#farmFiles[@]} == nframes)) || fail "array job wrote ${#farmFiles[@]} frames, expected $nframes"
[ "${localFiles[*]}" = "${farmFiles[*]}" ] || fail "the array job's frame files are not named like the local run's"
different=0
for f in "${localFiles[@]}"; do cmp -s "$work/local/$f" "$work/farm/$f" || different=$((different + 1)); done
((different == 0)) || fail "$different of $nframes frames differ from the local run"
ls "$work/farm" | grep -q '\.tmp' && fail "temporary files left in the output folder"
bytes=$(cat "$work/farm"/frame.* | wc -c)

# Concurrency, from the timestamps the tasks printed: "start"/"end" events swept in time order
# give the most tasks running at one instant.
events=$(for ((i = 0; i < tasks; i++)); do
  awk '$1 == "pmsc-array:" && ($6 == "start" || $6 == "end") {print $7, ($6 == "start" ? 1 : -1), $3, $5}' \
    "$work/logs/task-$i.log"
done | sort -k1,1g -k2,2n)
overlap=$(awk '{n += $2; if (n > most) most = n} END {print most + 0}' <<<"$events")
say "task intervals, seconds after the first start:"
awk 'NR == 1 {t0 = $1} $2 == 1 {s[$3] = $1 - t0; r[$3] = $4} $2 == -1 {e[$3] = $1 - t0}
  END {for (t in s) printf "  task %s  frames %-8s %7.3f .. %7.3f\n", t, r[t], s[t], e[t]}' <<<"$events" | sort -k2,2n
# Concurrency as Slurm recorded it: slurmctld logs when it started each task ("sched: Allocate" or
# "backfill: Started") and when it ended ("_job_complete ... done"). Both views count: a task of
# this small test does its frames in a fraction of a second, and slurmd may launch two tasks it
# started together a second apart, so on a fast machine the pmsc runs themselves need not overlap
# while Slurm still ran the tasks side by side. With --parallel 1 both views say 1 and the test fails.
ctldEvents=$(sed -nE "s/^\[([^]]+)\] (sched: Allocate|backfill: Started) JobId=${job}_[0-9]+\(.*/\1 1/p
  s/^\[([^]]+)\] _job_complete: JobId=${job}_[0-9]+\([0-9]+\) done.*/\1 -1/p" "$work/log/slurmctld.log" |
  while read -r when delta; do echo "$(date -d "$when" +%s.%N) $delta"; done | sort -k1,1g -k2,2n)
ctldOverlap=$(awk '{n += $2; if (n > most) most = n} END {print most + 0}' <<<"$ctldEvents")
say "most tasks running at once: $overlap by the tasks' timestamps, $ctldOverlap by slurmctld's log, $mostRunning seen by squeue"
((overlap >= 2 || ctldOverlap >= 2)) || fail "no two array tasks ran at the same time"

say "stats of the array tasks: $(cat "$work/farm"/pmsc-run.*.json | grep -c '"status": "ok"') ok, frames evaluated $(grep -h '"frames_evaluated"' "$work/farm"/pmsc-run.*.json | grep -o '[0-9]*' | paste -sd+ | bc)"
say "PASSED: $tasks tasks ($parallel at a time) wrote $nframes frames ($bytes bytes), byte-identical to the local run, in $(($(date +%s) - start)) s"
