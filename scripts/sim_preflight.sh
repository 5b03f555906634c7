#!/usr/bin/env bash
# The pre-dive check on the simulated robot, in lock-step (sim.launch preflight:=true): a simulated operator
# holds the body level and tilted on its stand, the check moves every servo; the report
# (preflight_<time>.md / .json) goes to OUT. Exit 0 when the check passed. Used by scripts/run_main.sh;
# expects scripts/env.sh sourced.
#
# Usage: scripts/sim_preflight.sh OUT   env: HARDWARE_FAULTS (a robot built wrong; default none), UQ_ROS_PORT
set -euo pipefail
OUT="$1"
rm -rf "$OUT"; mkdir -p "$OUT"
export ROS_HOME="${ROS_HOME:-$OUT/ros_home}"; mkdir -p "$ROS_HOME"
PORT="${UQ_ROS_PORT:-11358}"
export ROS_MASTER_URI="http://localhost:$PORT"
timeout 300 roslaunch -p "$PORT" underwater_quadruped sim.launch lockstep:=true preflight:=true \
  preflight_then_exit:=true require_preflight:=true description:=false sim_id:=preflight \
  hardware_faults:="${HARDWARE_FAULTS:-}" bag_dir:="$OUT" >"$OUT/launch.log" 2>&1 || true
shopt -s nullglob
reports=("$OUT"/preflight_*.md)
if [ "${#reports[@]}" -eq 0 ]; then
  echo "the pre-dive check wrote no report; last lines of $OUT/launch.log:" >&2; tail -30 "$OUT/launch.log" >&2; exit 1
fi
cat "${reports[-1]}"
head -1 "${reports[-1]}" | grep -q ": passed$"
