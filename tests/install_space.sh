#!/usr/bin/env bash
# CI step: the package builds the way a ROS user builds it and runs from its devel and install spaces.
# A copy of the repository (its tracked and untracked, not ignored files, as `git clone` would give) is
# placed in a fresh workspace's src/ and built with plain `catkin_make`; then, each in a clean
# environment that has only `source <ws>/devel/setup.bash`, resp. `source <prefix>/setup.bash` after
# `catkin_make install` into a temporary prefix (no source tree, no venv activation), it checks that
# rospack, rosmsg and the Python config lookup point into that space and runs sim.launch from it for a
# few seconds: every node up and /imu/data flowing.
#
# Usage: tests/install_space.sh [SCRATCH]   (run under flock /tmp/uq-ros.lock: it starts roslaunch)
#   env UQ_ROS_PORT (master port, default 11391), KEEP=1 keeps the scratch folder
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/paths.sh"
SCRATCH="${1:-$(mktemp -d /tmp/uq_install.XXXXXX)}"
PORT="${UQ_ROS_PORT:-11391}"
PREFIX="$SCRATCH/install"
LOG="$SCRATCH/log"
mkdir -p "$SCRATCH/ws/src" "$LOG"
cleanup() { if [ -z "${KEEP:-}" ]; then rm -rf "$SCRATCH"; else echo "install_space: kept $SCRATCH"; fi; }
trap cleanup EXIT
fail() { echo "install_space: FAILED: $*"; for f in "$LOG"/*; do echo "--- $f"; tail -25 "$f"; done; exit 1; }

SRC="$SCRATCH/ws/src/underwater_quadruped"
mkdir -p "$SRC"
if git -C "$UQ_ROOT" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  ( cd "$UQ_ROOT" && git ls-files -z --cached --others --exclude-standard | tar --null -T - -cf - 2>/dev/null ) \
    | tar -xf - -C "$SRC" || fail "copying the repository"
else
  ( cd "$UQ_ROOT" && tar --exclude=.venv --exclude=.stamps --exclude=build -cf - . ) | tar -xf - -C "$SRC"
fi
underlay=""
[ -f /opt/ros/noetic/setup.bash ] && underlay="source /opt/ros/noetic/setup.bash;"
# The interpreter is the project's venv (numpy, scipy, ... as pinned); on the robot it is the system's.
( cd "$SCRATCH/ws" && env -i HOME="$SCRATCH" PATH=/usr/bin:/bin bash -c "$underlay catkin_make \
    -DPYTHON_EXECUTABLE='$UQ_VENV/bin/python' -DCATKIN_ENABLE_TESTING=OFF" \
    >"$LOG/catkin_make.log" 2>&1 ) || fail "catkin_make in a fresh workspace"
[ -f "$SCRATCH/ws/devel/setup.bash" ] || fail "no devel/setup.bash"
( cd "$SCRATCH/ws" && env -i HOME="$SCRATCH" PATH=/usr/bin:/bin bash -c "$underlay catkin_make install \
    -DCMAKE_INSTALL_PREFIX='$PREFIX'" >"$LOG/catkin_make_install.log" 2>&1 ) || fail "catkin_make install"
[ -f "$PREFIX/setup.bash" ] || fail "no $PREFIX/setup.bash"

# Each check runs in a clean environment from one space only (SPACE: its setup.bash's folder; SHARE:
# where rospack must find the package; PYROOT: where quadruped_control must be imported from).
SPACE_NAME=devel SPACE="$SCRATCH/ws/devel" SHARE="$SRC" PYROOT="$SRC/"
write_check() {
cat >"$SCRATCH/from_$SPACE_NAME.sh" <<EOS
set -u
cd "$SCRATCH"
set +u; source "$SPACE/setup.bash"; set -u
export ROS_HOME="$SCRATCH/ros_home" ROS_MASTER_URI="http://localhost:$PORT"
share="\$(rospack find underwater_quadruped)"
[ "\$share" = "$SHARE" ] || { echo "rospack find underwater_quadruped: \$share"; exit 1; }
echo "[$SPACE_NAME] rospack find underwater_quadruped: \$share"
msg="\$(rosmsg show underwater_quadruped/ServoCommand)" || { echo "rosmsg show underwater_quadruped/ServoCommand failed"; exit 1; }
echo "[$SPACE_NAME] rosmsg show underwater_quadruped/ServoCommand: \$(echo "\$msg" | tr '\n' ' ' | cut -c1-80)..."
python - <<'PY' || exit 1
import quadruped_common, quadruped_control, underwater_quadruped.msg
from quadruped_common.config import config_dir
print("python: quadruped_control from %s, config from %s" % (quadruped_control.__file__, config_dir()))
assert quadruped_control.__file__.startswith("$PYROOT"), quadruped_control.__file__
assert config_dir() == "$SHARE/config", config_dir()
PY
roslaunch -p $PORT underwater_quadruped sim.launch sim_id:=${SPACE_NAME}_$PORT description:=true >"$LOG/roslaunch_$SPACE_NAME.log" 2>&1 &
launch=\$!
trap 'kill -INT \$launch 2>/dev/null; wait \$launch' EXIT
for _ in \$(seq 1 60); do rostopic list >/dev/null 2>&1 && break; sleep 0.5; done
timeout 60 rostopic echo -n 1 /imu/data/header/frame_id >"$LOG/imu_$SPACE_NAME.txt" 2>&1 || { echo "no /imu/data within 60 s"; exit 1; }
echo "/imu/data frame_id: \$(head -1 "$LOG/imu_$SPACE_NAME.txt")"
nodes="\$(rosnode list)"
for n in /sim_node /vn100_node /servo_feedback_node /pwm_node /attitude_controller /robot_state_publisher /visualization; do
  grep -qx "\$n" <<<"\$nodes" || { echo "node \$n is not running; nodes: \$(echo \$nodes)"; exit 1; }
done
echo "nodes up: \$(echo \$nodes)"
# /diagnostics: every status lands in exactly one analyzer of config/diagnostics_analyzers.yaml; hardware
# IDs follow diagnostic_updater's convention ("none" without hardware, the VN-100's serial number).
python - <<'PY' || exit 1
import rospy
from diagnostic_msgs.msg import DiagnosticArray
from quadruped_control.ros.diagnostics_analyzers import load_analyzers, matching_paths
statuses = {}
rospy.init_node("diagnostics_check", anonymous=True)
sub = rospy.Subscriber("/diagnostics", DiagnosticArray, lambda m: statuses.update((s.name, s.hardware_id) for s in m.status))
deadline = rospy.get_time() + 20.0
wanted = {"vn100_node: imu", "attitude_controller: control loop", "sim_node: simulation", "pwm_node: servo output"}
while not rospy.is_shutdown() and rospy.get_time() < deadline and not (wanted <= set(statuses) and statuses["vn100_node: imu"]):
    rospy.sleep(0.2)
analyzers = load_analyzers()
bad = {n: matching_paths(n, analyzers) for n in statuses if len(matching_paths(n, analyzers)) != 1}
print("diagnostics: %d statuses, hardware IDs %s" % (len(statuses), dict(sorted(statuses.items()))))
assert wanted <= set(statuses), "missing statuses: %s" % (wanted - set(statuses))
assert not bad, "statuses not in exactly one analyzer: %s" % bad
assert statuses["attitude_controller: control loop"] == statuses["sim_node: simulation"] == "none", statuses
assert statuses["vn100_node: imu"].startswith("VN-100 SN "), statuses["vn100_node: imu"]
PY
EOS
}
run_check() {
  write_check
  env -i HOME="$SCRATCH" PATH=/usr/bin:/bin LANG=C.UTF-8 bash "$SCRATCH/from_$SPACE_NAME.sh" || fail "from the $SPACE_NAME space"
  # (a traceback while the nodes shut down on SIGINT is not this check's concern: start-up errors and deaths are)
  grep -E "cannot read|process has died" "$LOG/roslaunch_$SPACE_NAME.log" && fail "errors in the $SPACE_NAME launch log"
}
run_check
SPACE_NAME=install SPACE="$PREFIX" SHARE="$PREFIX/share/underwater_quadruped" PYROOT="$PREFIX/"
run_check
echo "install_space: OK (a copy of the repository in a fresh workspace's src/ built with catkin_make; sim.launch ran from devel/setup.bash and from a temporary install prefix)"
