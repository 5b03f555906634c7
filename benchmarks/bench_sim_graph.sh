#!/usr/bin/env bash
# Timing of the ROS graph on the simulated robot in real-time mode (targets: 100 Hz held, period
# jitter p99 < 2 ms, IMU-to-PCA9685 latency p99 < 5 ms, zero stale-IMU hold episodes). Runs the stack
# headless and recording through a 45 deg roll maneuver of DURATION s (default 120), RUNS times
# (default 3) one after the other, and prints each run's figures and then min / median / max of every
# figure over the runs. The figures are the ones the nodes measured themselves and published on
# /diagnostics (recorded in the bag):
#   attitude_controller: loop rate, period jitter p50/p99 (|period - 10 ms|), step time, overruns,
#                        hold episodes (all / stale IMU), time held
#   pwm_node: IMU-sample-to-PCA9685-write latency p50/p99/max (IMU stamp -> end of the I2C write)
#   servo_feedback_node, vn100_node: rates and read times
# and, from benchmarks/machine_stall_probe.py run beside the stack at SCHED_FIFO 99, the machine's own
# stalls (times in which no thread could run) and which control-period outliers and stale-IMU holds fell
# into one; each run's hold episodes are listed with their reasons (benchmarks/sim_graph_summary.py).
# Usage: bash benchmarks/bench_sim_graph.sh [DURATION [RUNS]]
# Take figures on a quiet machine: other load shows up directly in the jitter and latency tails.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
DURATION="${1:-120}"
RUNS="${2:-3}"
OUT="$(mktemp -d /tmp/uq_bench_graph.XXXXXX)"
for run in $(seq 1 "$RUNS"); do
  echo "== run $run/$RUNS: ${DURATION} s =="
  mkdir -p "$OUT/run$run"
  # The independent witness of machine-level stalls (benchmarks/machine_stall_probe.py).
  # Wakes every 1 ms (about 1 % of one core); a wake-up 1.5 ms late or more is a stall.
  python benchmarks/machine_stall_probe.py "$OUT/run$run/machine_stalls.csv" --period 0.001 --threshold 0.0015 &
  PROBE=$!
  UQ_ROS_PORT="${UQ_ROS_PORT:-11358}" bash scripts/sim_maneuver.sh "$OUT/run$run" "$DURATION" >/dev/null
  kill -INT "$PROBE"; wait "$PROBE" || true
done
python benchmarks/sim_graph_summary.py "$OUT" "$RUNS"
echo "(bags and logs in $OUT)"
