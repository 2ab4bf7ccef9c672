#!/usr/bin/env bash
# Run tests on a loaded machine: two CPU-bound processes beside pytest, the
# run repeated, one line per run (when, load average before -> after, pytest's
# last line); the busy loops are ended by their PIDs. docs/testing.md,
# "Running the suite on a loaded machine".
#
# Usage: scripts/loaded_test.sh RUNS [pytest arguments...]
#   e.g. nice -n 10 scripts/loaded_test.sh 5 src/holonomic_drivers/test/test_can_drivers.py
# (nice applies to the busy loops and pytest alike; the emulated drives and
# the rig's loop ask for SCHED_FIFO, which nice does not touch)
# Environment: VENV, WS as for make (default .venv, ros2_ws); LOGS: where each
# run's pytest output goes (default out/loaded).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
RUNS="${1:?usage: scripts/loaded_test.sh RUNS [pytest arguments...]}"
shift
VENV="${VENV:-.venv}"
WS="${WS:-ros2_ws}"
LOGS="${LOGS:-out/loaded}"
mkdir -p "$LOGS"
set +u                                   # the workspace's setup files read unset variables
# shellcheck disable=SC1091
. "$WS/env.sh"
set -u
python3 -c "while True: pass" & B1=$!
python3 -c "while True: pass" & B2=$!
trap 'kill $B1 $B2 2>/dev/null || true' EXIT
for i in $(seq 1 "$RUNS"); do
    before="$(cut -d' ' -f1-3 /proc/loadavg)"
    "$VENV/bin/python" -m pytest "$@" -q -rf -p no:cacheprovider -p no:rerunfailures \
        > "$LOGS/run$i.log" 2>&1 || true
    after="$(cut -d' ' -f1-3 /proc/loadavg)"
    echo "run $i ended $(date -u +%H:%M:%S) UTC, load $before -> $after: $(tail -1 "$LOGS/run$i.log")"
done
