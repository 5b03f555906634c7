#!/usr/bin/env bash
# CI step: the tests of what the robot imports (common, drivers, model, control, the nodes' pure parts)
# under Python 3.8 (the Jetson's interpreter) with the Jetson's pinned dependencies
# (requirements-jetson-test.txt), in a venv of its own (.venv38, no system site packages, so no rospy:
# tests that need ROS skip themselves). The studies and the simulator are not on the robot: not here. Prints "python38: SKIPPED ..." and succeeds when no 3.8
# interpreter is found: UQ_PYTHON38, python3.8 on PATH, or pyenv's $PYENV_ROOT/versions/3.8.*.
# Extra arguments go to pytest. With --venv-only: only make (or refresh) the venv, print its python and stop
# (tests/python38_graph.sh, the node graph under 3.8, uses the same venv); exit 3 when no 3.8 is found.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv38"
REQUIREMENTS="$ROOT/requirements-jetson-test.txt"
# What the ROS nodes need besides Debian's pure-Python ROS packages (tests/python38_graph.sh): netifaces.
GRAPH_REQUIREMENTS="$ROOT/tests/python38_graph/requirements.txt"
VENV_ONLY=0
if [ "${1:-}" = --venv-only ]; then VENV_ONLY=1; shift; fi
ROBOT_TESTS=(tests/common tests/drivers tests/control/model tests/control/control tests/control/ros)

py38=""
for candidate in "${UQ_PYTHON38:-}" "$(command -v python3.8 || true)" \
                 "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.8.*/bin/python; do
  if [ -n "$candidate" ] && [ -x "$candidate" ] \
     && "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 8))' 2>/dev/null; then
    py38="$candidate"; break
  fi
done
if [ -z "$py38" ]; then
  if [ "$VENV_ONLY" = 1 ]; then exit 3; fi
  echo "python38: SKIPPED: no Python 3.8 interpreter found (set UQ_PYTHON38, or install 3.8 with pyenv);"
  echo "python38: the pure core was NOT tested under Python 3.8 in this run (vermin still checks the syntax)"
  exit 0
fi

key="$(cat "$REQUIREMENTS" "$ROOT/requirements-jetson.txt" "$GRAPH_REQUIREMENTS" | sha256sum | cut -d' ' -f1)-$("$py38" --version 2>&1)"
if [ ! -x "$VENV/bin/python" ] || [ "$(cat "$VENV/.uq_stamp" 2>/dev/null)" != "$key" ]; then
  echo "python38: creating $VENV from $py38 with $(basename "$REQUIREMENTS") and tests/python38_graph/requirements.txt" >&2
  rm -rf "$VENV"
  "$py38" -m venv "$VENV" || exit 1
  "$VENV/bin/pip" install -q --disable-pip-version-check -r "$REQUIREMENTS" -r "$GRAPH_REQUIREMENTS" 2>&1 \
    | grep -v "^WARNING: Location" >&2
  "$VENV/bin/python" -c "import numpy, scipy, yaml, rosbags, netifaces" || { echo "python38: venv installation failed" >&2; exit 1; }
  echo "$key" > "$VENV/.uq_stamp"
fi
if [ "$VENV_ONLY" = 1 ]; then echo "$VENV/bin/python"; exit 0; fi
echo "python38: $("$VENV/bin/python" --version) from $py38, $(basename "$REQUIREMENTS")"
cd "$ROOT" || exit 1
# The ROS environment is left out on purpose: this is what the pure core needs and nothing more.
env -u PYTHONPATH -u ROS_PACKAGE_PATH -u CMAKE_PREFIX_PATH PATH="$VENV/bin:/usr/bin:/bin" \
  "$VENV/bin/python" -m pytest -q -p no:cacheprovider "${ROBOT_TESTS[@]}" "$@"
