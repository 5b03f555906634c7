#!/usr/bin/env bash
# The main job: the whole stack on the simulated robot, ending in a report.
# Does its own set-up first (scripts/setup.sh). Output goes to out/ (ignored by git), or $UQ_OUT.
#
#  1. The paper's simulation study, offline (model + controller, no ROS): out/paper-sim.
#  2. The ROS graph on the simulated robot (sim.launch, headless: sim_node behind the fake PCA9685 /
#     ADS1115 / TCA9548A / VN-100, the unchanged driver nodes, the attitude controller), armed, level
#     for 5 s, then a 45 degree roll maneuver for UQ_DURATION s (default 120), recorded to a bag.
#  3. The report made from the bag: the paper's metrics, a figure, the stack's health (rates, loop
#     jitter, IMU-to-PWM latency, error counters): out/sim-maneuver/report.md.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
set +u
# shellcheck disable=SC1091
source scripts/env.sh
set -u
OUT="${UQ_OUT:-$ROOT/out}"
DURATION="${UQ_DURATION:-120}"
mkdir -p "$OUT"
export ROS_HOME="$OUT/ros_home"; mkdir -p "$ROS_HOME"

echo "== 1/3 Offline closed-loop simulation: the paper's simulation study (no ROS) =="
python -m quadruped_control.simulate --study paper-sim --jobs 2 --out "$OUT/paper-sim"

echo
echo "== 2/3 The ROS stack on the simulated robot: 45 deg roll maneuver, ${DURATION} s, recorded =="
BAGS="$OUT/sim-maneuver/bags"
rm -rf "$BAGS"; mkdir -p "$BAGS"
# A private master port so that a roscore already running on 11311 is not disturbed.
PORT="${UQ_ROS_PORT:-11357}"
export ROS_MASTER_URI="http://localhost:$PORT"
timeout $((DURATION + 180)) roslaunch -p "$PORT" underwater_quadruped sim_maneuver.launch \
  bag_dir:="$BAGS" duration:="$DURATION" roll:=45 >"$OUT/sim-maneuver.log" 2>&1 &
LAUNCH_PID=$!
trap 'kill -INT $LAUNCH_PID 2>/dev/null || true' EXIT
# Progress from the maneuver node while the launch runs.
tail -n +1 -F "$OUT/sim-maneuver.log" 2>/dev/null | grep --line-buffered -E "maneuver:|FATAL|ERROR|died" &
TAIL_PID=$!
wait $LAUNCH_PID || true
trap - EXIT
kill $TAIL_PID 2>/dev/null || true
shopt -s nullglob
bags=("$BAGS"/*.bag)
if [ "${#bags[@]}" -eq 0 ]; then
  echo "no bag was recorded; last lines of $OUT/sim-maneuver.log:"; tail -40 "$OUT/sim-maneuver.log"; exit 1
fi

echo
echo "== 3/3 Report from the bag =="
python -m quadruped_control.bag_report "${bags[@]}" --out "$OUT/sim-maneuver" \
  --title "Simulated robot through the full ROS stack: 45 deg roll"
echo
echo "Reports: $OUT/paper-sim (study.json, paper_sim.png), $OUT/sim-maneuver (report.md, metrics.json, attitude.png)"
