#!/usr/bin/env bash
# Reproducible rviz screenshot of the robot for docs/tuning_and_recording.md: docs/images/rviz.png.
#
# Starts launch/rviz.launch (with description.launch: robot_description, robot_state_publisher, the
# visualization node) on its own ROS master port under a virtual X server, publishes a fixed scene
# (joint states of a stroke pose solved by the package's inverse kinematics, a tilted IMU orientation, a
# controller state with a level setpoint and foot targets), waits for rviz to draw it, grabs the screen
# and stores a downscaled PNG.
#
# Needs (not part of CI): apt-get install -y rviz xvfb imagemagick ros-robot-state-publisher
# and the workspace from scripts/setup.sh.
#
# Usage: scripts/rviz_screenshot.sh [output.png]     (default docs/images/rviz.png)
#   env PORT (ROS master port, default 11471), SETTLE (seconds to wait for rviz, default 20),
#       KEEP=1 keeps the scratch folder (logs) for debugging
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="${1:-$ROOT/docs/images/rviz.png}"
PORT="${PORT:-11471}"
SETTLE="${SETTLE:-20}"

for tool in xvfb-run import convert rviz; do
  command -v "$tool" >/dev/null || { echo "rviz_screenshot: '$tool' not found (apt-get install -y rviz xvfb imagemagick)" >&2; exit 1; }
done

source "$ROOT/scripts/prepare.sh"

SCRATCH="$(mktemp -d /tmp/uq_rviz_shot.XXXXXX)"
export HOME="$SCRATCH" ROS_HOME="$SCRATCH/ros" ROS_LOG_DIR="$SCRATCH/log"
export ROS_MASTER_URI="http://localhost:$PORT"
mkdir -p "$(dirname "$OUT")"

PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  sleep 2
  for pid in "${PIDS[@]}"; do kill -KILL "$pid" 2>/dev/null || true; done
  if [ -z "${KEEP:-}" ]; then rm -rf "$SCRATCH"; else echo "rviz_screenshot: kept $SCRATCH" >&2; fi
}
trap cleanup EXIT

# The scene publisher: 20 Hz, as the drivers and the controller would.
cat > "$SCRATCH/scene.py" <<'EOF'
import math

import numpy as np
import rospy
from geometry_msgs.msg import Point, Quaternion
from sensor_msgs.msg import Imu, JointState

from quadruped_control.model.kinematics import joint_angles
from quadruped_common.robot import JOINT_NAMES, LEGS
from quadruped_control.model.params import load_robot_params
from underwater_quadruped.msg import ControllerState


def quaternion_rpy(roll, pitch, yaw):
    """(x, y, z, w) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return Quaternion(x=sr * cp * cy - cr * sp * sy, y=cr * sp * cy + sr * cp * sy,
                      z=cr * cp * sy - sr * sp * cy, w=cr * cp * cy + sr * sp * sy)


params = load_robot_params()
# Diagonal pairs mid-stroke: legs 1 and 3 forward of nominal, legs 2 and 4 behind it (body frame).
stroke = {1: (0.03, 0.0, 0.01), 2: (-0.03, 0.0, -0.01), 3: (0.03, 0.0, 0.01), 4: (-0.03, 0.0, -0.01)}
feet = {leg: params.nominal_foot_body(leg) + np.array(stroke[leg]) for leg in LEGS}
q = np.concatenate([joint_angles(feet[leg], leg, params) for leg in LEGS])
# Targets a little further along the stroke than the feet are now.
targets = [feet[leg] + 0.5 * np.array(stroke[leg]) for leg in LEGS]

rospy.init_node("screenshot_scene")
joints = rospy.Publisher("joint_states", JointState, queue_size=1)
imu_pub = rospy.Publisher("imu/data", Imu, queue_size=1)
state_pub = rospy.Publisher("controller_state", ControllerState, queue_size=1)
rate = rospy.Rate(20)
while not rospy.is_shutdown():
    now = rospy.Time.now()
    js = JointState(name=list(JOINT_NAMES), position=[float(v) for v in q])
    js.header.stamp = now
    joints.publish(js)
    imu = Imu(orientation=quaternion_rpy(math.radians(12.0), math.radians(-8.0), 0.0))
    imu.header.stamp, imu.header.frame_id = now, "base_link"
    imu_pub.publish(imu)
    state = ControllerState(setpoint=quaternion_rpy(0.0, math.radians(10.0), 0.0),
                            foot_targets=[Point(*map(float, t)) for t in targets])
    state.header.stamp = now
    state_pub.publish(state)
    rate.sleep()
EOF

cat > "$SCRATCH/inside_x.sh" <<EOF
set -e
roslaunch -p "$PORT" "$ROOT/launch/rviz.launch" description:=true >"$SCRATCH/roslaunch.log" 2>&1 &
LAUNCH=\$!
for _ in \$(seq 1 100); do rostopic list >/dev/null 2>&1 && break; sleep 0.2; done
python "$SCRATCH/scene.py" >"$SCRATCH/scene.log" 2>&1 &
SCENE=\$!
sleep "$SETTLE"
import -window root "$SCRATCH/shot.png"
kill -INT \$SCENE \$LAUNCH
wait \$LAUNCH || true
EOF

xvfb-run -a -s "-screen 0 1280x800x24" bash "$SCRATCH/inside_x.sh" &
PIDS+=($!)
wait "${PIDS[0]}" || { echo "rviz_screenshot: failed; roslaunch log:" >&2; tail -30 "$SCRATCH/roslaunch.log" >&2; tail -30 "$SCRATCH/scene.log" >&2; exit 1; }

# A black frame means rviz died before drawing (it occasionally aborts at start-up under llvmpipe).
if [ "$(convert "$SCRATCH/shot.png" -format '%[fx:standard_deviation > 0.01]' info:)" != 1 ]; then
  echo "rviz_screenshot: the screen is blank, rviz did not draw; rerun (KEEP=1 keeps the logs)" >&2
  exit 1
fi
# Crop to rviz's 3-D view (the window is 1280 x 800 at 0,0 from the rviz config: menu and tool bar
# above, status bar below, dock handles at the sides) and downscale; a reduced palette keeps it small.
convert "$SCRATCH/shot.png" -crop 1248x706+16+62 +repage -resize 1024x -strip -colors 256 \
  -define png:compression-level=9 "$OUT"
echo "rviz_screenshot: wrote $OUT ($(du -k "$OUT" | cut -f1) KB)"
