#!/usr/bin/env bash
# The test suite under load, as CI on a busy machine would see it (issue 18).
#
#   scripts/stress_suite.sh [RUNS] [BURNERS]
#
# Clones the current HEAD into a fresh folder (as CI does), then runs `bash .ci/run` there
# RUNS times in a row (default 5) with BURNERS CPU-bound processes beside it (default: one per
# core). Prints each run's result and wall time; stops at nothing (every run is reported) and
# exits non-zero if any run failed. The burners are killed on exit, whatever happens.
set -uo pipefail

runs=${1:-5}
burners=${2:-$(nproc)}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
work=$(mktemp -d /tmp/vd-stress.XXXXXX)
pids=()

cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null; done
  wait 2>/dev/null
}
trap cleanup EXIT INT TERM

git clone --quiet "$root" "$work/clone"
for _ in $(seq "$burners"); do
  ( while :; do :; done ) &
  pids+=($!)
done
echo "stress: $runs run(s) of .ci/run in $work/clone beside $burners CPU burner(s)"

failed=0
for run in $(seq "$runs"); do
  start=$(date +%s)
  (cd "$work/clone" && CI=true bash .ci/run > "$work/run_$run.log" 2>&1)
  code=$?
  seconds=$(( $(date +%s) - start ))
  summary=$(grep -E '^[=]+ .*(passed|failed).* in ' "$work/run_$run.log" | tail -1)
  echo "run $run: exit $code in ${seconds} s, load $(cut -d' ' -f1 /proc/loadavg): ${summary:-no summary}"
  [ "$code" -eq 0 ] || failed=$((failed + 1))
done
echo "stress: $failed of $runs run(s) failed; logs in $work"
[ "$failed" -eq 0 ]
