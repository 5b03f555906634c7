#!/usr/bin/env bash
# Timing of the ROS graph on the simulated robot (issue: 100 Hz held, p99 jitter < 1 ms, p99 latency
# < 5 ms): runs the stack through a 45 deg roll maneuver for DURATION s (default 60) and prints the
# figures the nodes measured themselves and published on /diagnostics (recorded in the bag):
#   attitude_controller: loop rate, period jitter p50/p99 (|period - 10 ms|), step time, overruns
#   pwm_node: IMU-sample-to-PCA9685-write latency p50/p99/max (IMU stamp -> end of the I2C write)
#   servo_feedback_node, vn100_node: rates and read times
# Usage: bash benchmarks/bench_sim_graph.sh [DURATION]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
DURATION="${1:-60}"
OUT="$(mktemp -d /tmp/uq_bench_graph.XXXXXX)"
UQ_ROS_PORT="${UQ_ROS_PORT:-11358}" bash scripts/sim_maneuver.sh "$OUT" "$DURATION" >/dev/null
python - "$OUT"/bags/*.bag <<'PYEOF'
import sys
from quadruped_control.bag_report import health, read_bags
for name, values in health(read_bags(sys.argv[1:])).items():
    print(name)
    for key, value in values.items():
        print("  %-28s %s" % (key, value))
PYEOF
echo "(bag and logs in $OUT)"
