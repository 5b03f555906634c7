#!/usr/bin/env bash
# Idempotent set-up of everything the stack needs, called by `make run` and `make test`.
#
#  1. ROS 1: on the Jetson (Ubuntu 20.04 with /opt/ros/noetic) that installation is used as is;
#     on Debian 12 the archive's own ROS 1 packages are installed with apt (root).
#  2. A venv (.venv) from /usr/bin/python3 with --system-site-packages, so Debian's/Noetic's rospy stays
#     visible, holding the pinned PyPI dependencies (requirements.txt, or requirements-jetson.txt on the robot).
#  3. A catkin workspace OUTSIDE this tree (scripts/paths.sh: UQ_WS, default the sibling folder
#     "<clone>_ws") whose src/ links to this tree, the one package underwater_quadruped (it also
#     generates the messages of quadruped_msgs/msg). Outside, so that rosrun / rospack / roscd see
#     exactly one copy of the package. Sourcing its devel/setup.bash gives everything the launch files need.
#
# Each step records a stamp (hash of its inputs) in .stamps/ and is skipped when nothing changed, so a
# second run takes about a second.
set -euo pipefail

# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/paths.sh"
ROOT="$UQ_ROOT"
STAMPS="$ROOT/.stamps"
VENV="$UQ_VENV"
WS="$UQ_WS"
mkdir -p "$STAMPS"

log() { printf '[setup] %s\n' "$*" >&2; }

stamp_matches() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

# Debian 12 packages: ROS 1 from the Debian archive, build tools, Python venv support.
DEBIAN_PACKAGES=(
  ros-core-dev catkin ros-message-generation ros-message-runtime rosbash
  python3-rospy python3-rostest python3-roslaunch python3-rosbag python3-rostopic python3-rosunit
  python3-std-msgs python3-sensor-msgs python3-geometry-msgs python3-std-srvs python3-diagnostic-msgs
  ros-std-msgs ros-sensor-msgs ros-geometry-msgs ros-std-srvs ros-diagnostic-msgs
  python3-dynamic-reconfigure libdynamic-reconfigure-config-init-mutex-dev python3-diagnostic-updater
  ros-robot-state-publisher python3-tf2-ros python3-visualization-msgs ros-visualization-msgs
  python3-dynamic-reconfigure python3-rosbag
  python3-venv python3-dev build-essential cmake
  catkin-lint
)

REQUIREMENTS_INCLUDED=()
if [ -f /opt/ros/noetic/setup.bash ]; then
  ROS_FLAVOUR=noetic
  # The robot installs what it runs; scripts/run_tests.sh asks for the tests' packages too.
  if [ "${UQ_WITH_TESTS:-0}" = 1 ]; then
    REQUIREMENTS="$ROOT/requirements-jetson-test.txt"
    REQUIREMENTS_INCLUDED=("$ROOT/requirements-jetson.txt")
  else
    REQUIREMENTS="$ROOT/requirements-jetson.txt"
  fi
else
  ROS_FLAVOUR=debian
  REQUIREMENTS="$ROOT/requirements.txt"
  missing=()
  for pkg in "${DEBIAN_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q 'install ok installed' || missing+=("$pkg")
  done
  if [ "${#missing[@]}" -gt 0 ]; then
    if [ "$(id -u)" != 0 ]; then
      log "missing Debian packages (run as root or install them): ${missing[*]}"
      exit 1
    fi
    log "installing ${#missing[@]} Debian packages"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
fi

# The venv. Its python is /usr/bin/python3, the interpreter the ROS packages were built for.
venv_key="$(hash_of "$REQUIREMENTS" "${REQUIREMENTS_INCLUDED[@]}")-$(/usr/bin/python3 --version 2>&1)"
if [ ! -x "$VENV/bin/python" ] || ! stamp_matches venv "$venv_key"; then
  log "creating venv and installing pinned dependencies from $(basename "$REQUIREMENTS")"
  rm -rf "$VENV"
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
  "$VENV/bin/pip" install -q --disable-pip-version-check -r "$REQUIREMENTS" 2>&1 | grep -v "^WARNING: Location" >&2 || true
  "$VENV/bin/python" -c "import numpy, yaml" || { log "venv installation failed"; exit 1; }
  echo "$venv_key" > "$STAMPS/venv"
fi

# The catkin workspace: message and dynamic_reconfigure generation, Python package relays. Built with
# the venv's python (which is /usr/bin/python3 plus the pinned packages): the node relays in devel/ get
# it as their interpreter, so nodes started by roslaunch see numpy, scipy and the Adafruit drivers.
build_inputs=("$ROOT/CMakeLists.txt" "$ROOT/package.xml" "$ROOT/setup.py" "$ROOT"/quadruped_msgs/msg/*.msg
              "$ROOT"/cfg/*.cfg "$ROOT"/env-hooks/*)
build_key="$(hash_of "${build_inputs[@]}")-venv-python-$( (ls "$ROOT/nodes" "$ROOT/tests/rostest" 2>/dev/null || true) | sha256sum | cut -d' ' -f1)-$WS"
# A workspace that earlier versions built inside the tree (.ws) makes rosrun see every node twice: gone.
if [ -f "$ROOT/.ws/.catkin_workspace" ]; then
  log "removing the old in-tree workspace $ROOT/.ws (the workspace is now $WS)"
  rm -rf "$ROOT/.ws"
fi
if [ ! -f "$WS/devel/setup.bash" ] || ! stamp_matches catkin "$build_key"; then
  log "building the catkin workspace in $WS"
  mkdir -p "$WS/src"
  ln -sfn "$ROOT" "$WS/src/underwater_quadruped"
  # Workspaces of earlier versions also linked quadruped_msgs/ as a package of its own: gone.
  rm -f "$WS/src/quadruped_msgs"
  # Keep another workspace or a ROS_PACKAGE_PATH that contains this folder from crawling into it.
  touch "$WS/CATKIN_IGNORE" "$WS/rospack_nosubdirs"
  (
    set +u
    if [ "$ROS_FLAVOUR" = noetic ]; then source /opt/ros/noetic/setup.bash; fi
    cd "$WS"
    catkin_make --force-cmake -DPYTHON_EXECUTABLE="$VENV/bin/python" -DCMAKE_BUILD_TYPE=Release >"$WS/catkin_make.log" 2>&1 \
      || { tail -40 "$WS/catkin_make.log" >&2; exit 1; }
  )
  echo "$build_key" > "$STAMPS/catkin"
fi
