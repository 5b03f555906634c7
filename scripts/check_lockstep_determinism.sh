#!/usr/bin/env bash
# Lock-step determinism: runs the closed-loop rostest (tests/rostest/sim_closed_loop.test, lock-step on
# simulated time) twice, the second time with every core kept busy by another process, and compares the
# simulated trajectories (/sim/pose up to the sensor-stall part) sample by sample: they must agree to
# 1e-6 on at least 10 s of common simulated time.
#
# Usage: scripts/check_lockstep_determinism.sh [FIRST.npz]
#   FIRST.npz: a trajectory already recorded by a first run (run_tests.sh passes the one of its own
#   rostest run, so only the loaded run is added); without it both runs are made here.
# Starts roscore/rostest: run it under `flock /tmp/uq-ros.lock` on a shared machine.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
OUT="$(mktemp -d /tmp/uq_lockstep.XXXXXX)"
export ROS_HOME="${ROS_HOME:-$OUT/ros_home}"; mkdir -p "$ROS_HOME"

run_closed_loop() {  # $1: trajectory file
  rm -rf "$ROS_HOME/test_results"
  if ! UQ_TRAJECTORY_FILE="$1" timeout 900 rostest underwater_quadruped sim_closed_loop.test >"$1.log" 2>&1 \
      || [ ! -s "$1" ]; then
    echo "closed-loop rostest failed; last lines of $1.log:" >&2; tail -30 "$1.log" >&2; return 1
  fi
}

FIRST="${1:-}"
if [ -z "$FIRST" ]; then
  FIRST="$OUT/quiet.npz"
  echo "-- lock-step closed loop, run 1 (no extra load)"
  run_closed_loop "$FIRST"
fi
CORES="$(nproc)"
echo "-- lock-step closed loop, run 2 with $CORES busy processes"
LOAD_PIDS=()
for _ in $(seq 1 "$CORES"); do
  python -c "while True: pass" & LOAD_PIDS+=($!)
done
trap 'kill "${LOAD_PIDS[@]}" 2>/dev/null || true' EXIT
run_closed_loop "$OUT/loaded.npz"
kill "${LOAD_PIDS[@]}" 2>/dev/null || true
trap - EXIT
python -m quadruped_control.sim.lockstep "$FIRST" "$OUT/loaded.npz" --tolerance 1e-6 --min-samples 1000
