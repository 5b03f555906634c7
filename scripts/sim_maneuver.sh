#!/usr/bin/env bash
# Runs launch/sim_maneuver.launch headless: the whole ROS stack on the simulated robot, armed, level for
# 5 s, then a roll maneuver (ROLL, default 45 deg) for DURATION s, recorded to OUT/bags/*.bag.
# Used by scripts/run_main.sh and benchmarks/bench_sim_graph.sh; expects scripts/env.sh sourced.
#
# Usage: scripts/sim_maneuver.sh OUT DURATION
#   env: ROLL (deg), UQ_ROS_PORT (master port), DESCRIPTION (default false: headless, no robot_state_publisher/visualization),
#        UQ_LAUNCH_PREFIX (launch-prefix of the control-path nodes; default "chrt -f 20" where permitted),
#        UQ_SIM_LAUNCH_PREFIX (launch-prefix of sim_node; default "chrt -f 30" where permitted)
set -euo pipefail
OUT="$1"; DURATION="$2"; ROLL="${ROLL:-45}"
BAGS="$OUT/bags"
rm -rf "$BAGS"; mkdir -p "$BAGS"
export ROS_HOME="${ROS_HOME:-$OUT/ros_home}"; mkdir -p "$ROS_HOME"
# A private master port so that a roscore already running on 11311 is not disturbed.
PORT="${UQ_ROS_PORT:-11357}"
export ROS_MASTER_URI="http://localhost:$PORT"
LOG="$OUT/launch.log"
# The control path (vn100_node, attitude_controller, pwm_node) runs SCHED_FIFO where allowed (root here),
# as on the robot (docs/on_the_robot.md): on two shared cores it halves the loop jitter. UQ_LAUNCH_PREFIX overrides.
if [ -z "${UQ_LAUNCH_PREFIX+x}" ]; then
  if chrt -f 20 true 2>/dev/null; then UQ_LAUNCH_PREFIX="chrt -f 20"; else UQ_LAUNCH_PREFIX=""; fi
fi
# The simulated hardware runs above the control path: a real IMU and a real PCA9685 never wait for the
# stack, so the simulation must not be starved by it (stale-IMU holds that only the simulation causes).
if [ -z "${UQ_SIM_LAUNCH_PREFIX+x}" ]; then
  if chrt -f 30 true 2>/dev/null; then UQ_SIM_LAUNCH_PREFIX="chrt -f 30"; else UQ_SIM_LAUNCH_PREFIX=""; fi
fi
timeout $((DURATION + 180)) roslaunch -p "$PORT" underwater_quadruped sim_maneuver.launch \
  bag_dir:="$BAGS" duration:="$DURATION" roll:="$ROLL" description:="${DESCRIPTION:-false}" launch_prefix:="$UQ_LAUNCH_PREFIX" \
  sim_launch_prefix:="$UQ_SIM_LAUNCH_PREFIX" >"$LOG" 2>&1 &
LAUNCH_PID=$!
trap 'kill -INT $LAUNCH_PID 2>/dev/null || true' EXIT
# Progress from the maneuver node while the launch runs (tail ends with the launch, then grep sees EOF:
# no process is left holding the caller's stdout).
tail --pid="$LAUNCH_PID" -n +1 -F "$LOG" 2>/dev/null | grep --line-buffered -E "maneuver:|FATAL|ERROR|died" | grep --line-buffered -v "process \[maneuver-" &
TAIL_PID=$!
wait $LAUNCH_PID || true
trap - EXIT
kill $TAIL_PID 2>/dev/null || true
shopt -s nullglob
bags=("$BAGS"/*.bag)
if [ "${#bags[@]}" -eq 0 ]; then
  echo "no bag was recorded; last lines of $LOG:" >&2; tail -40 "$LOG" >&2; exit 1
fi
