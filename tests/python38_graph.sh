#!/usr/bin/env bash
# CI step: the node graph under Python 3.8 (the Jetson's interpreter). Runs rostests with every node of
# the package on Python 3.8 (.venv38 of tests/python38.sh: requirements-jetson-test.txt and
# tests/python38_graph/requirements.txt), while roscore, roslaunch, rostest and the test nodes that judge
# stay on the machine's ROS Python (3.11 on Debian 12). Passes when each rostest passes (its rosunit
# results, as scripts/run_tests.sh counts them) AND every process roslaunch started from the package's
# nodes/ ran on 3.8, by the record that process wrote itself before the node's code ran (interpreter
# version, /proc/self/exe), matched by pid to roslaunch's log; a node that silently ran on 3.11 fails.
#
#   bash tests/python38_graph.sh [NAME...]   rostests tests/rostest/NAME.test (default: DEFAULT_TESTS; the
#                                            others work too, e.g. controller_restart fault_campaign, whose
#                                            kills are allowed by RESTARTS_BY_DESIGN)
#   env UQ_PY38_GRAPH_OUT: output folder (default build/python38_graph; run_tests.sh: its results folder)
#
# How: Debian's ROS Python packages are pure Python but live beside 3.11-only compiled modules, so a 3.8
# node sees them through a folder of symlinks to the pure ones only (tests/python38_graph/ros_path.py;
# its MANIFEST.txt lists what was left out). roslaunch finds a node's executable through catkin's
# workspaces first (CMAKE_PREFIX_PATH): an overlay workspace put in front holds, for each node, a
# wrapper that runs the node's script under 3.8 (tests/python38_graph/node.py, which writes the record).
# Launch and .test files are unchanged.
#
# Not on 3.8 (the node runs on 3.11, and the check expects that): visualization_node (launch/
# description.launch), because tf2_ros imports tf2_py, whose _tf2 module Debian compiled for 3.11 only.
#
# Prints "python38_graph: SKIPPED ..." and succeeds when no Python 3.8 interpreter is found.
# Starts rostest (a master of its own on a free port), but the simulations' socket paths are fixed per
# .test: do not run it beside the same rostest on 3.11 (run it under flock /tmp/uq-ros.lock on a shared machine).
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT" || exit 1
#: the fault-free rostests that, together, start every node of nodes/ (bag_record: maneuver_sequence records)
DEFAULT_TESTS=(sim_closed_loop maneuver_sequence controller_safety pwm_watchdog preflight)
#: nodes that stay on the machine's ROS Python, with the reason (the check requires them on it)
declare -A KEEP_ON_ROS_PYTHON=(
  [visualization_node]="tf2_ros needs tf2_py's compiled _tf2, built by Debian for Python 3.11 only"
)
#: processes each rostest kills on purpose (the check fails any other restart: a node that died)
declare -A RESTARTS_BY_DESIGN=([controller_restart]="attitude_controller" [fault_campaign]="any")
TESTS=("$@")
[ "${#TESTS[@]}" -gt 0 ] || TESTS=("${DEFAULT_TESTS[@]}")
for name in "${TESTS[@]}"; do
  [ -f "tests/rostest/$name.test" ] || { echo "python38_graph: no tests/rostest/$name.test" >&2; exit 2; }
done

py38="$(bash tests/python38.sh --venv-only)"; venv_rc=$?
if [ "$venv_rc" -eq 3 ]; then
  echo "python38_graph: SKIPPED: no Python 3.8 interpreter found (set UQ_PYTHON38, or install 3.8 with pyenv);"
  echo "python38_graph: the nodes did NOT run under Python 3.8 in this run"
  exit 0
fi
[ "$venv_rc" -eq 0 ] && [ -x "$py38" ] || { echo "python38_graph: FAILED: making .venv38 (tests/python38.sh --venv-only)"; exit 1; }

if [ -z "${UQ_WS:-}" ] || [ "${CMAKE_PREFIX_PATH:-}" = "${CMAKE_PREFIX_PATH#*"$UQ_WS/devel"}" ]; then
  export UQ_WITH_TESTS=1
  # shellcheck disable=SC1091
  source "$ROOT/scripts/prepare.sh"
fi
DEVEL_PY="$UQ_WS/devel/lib/python3/dist-packages"
SYSTEM_PYTHON="$(command -v python3)"  # the venv's, on the ROS Python (3.11 on Debian 12): runs the checks
if "$SYSTEM_PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 8))'; then
  echo "python38_graph: SKIPPED: ROS's own Python is 3.8 here (Noetic): the rostests of scripts/run_tests.sh"
  echo "python38_graph: already ran every node on Python 3.8"
  exit 0
fi

OUT="${UQ_PY38_GRAPH_OUT:-$ROOT/build/python38_graph}"
rm -rf "$OUT"; mkdir -p "$OUT"
ROS38="$OUT/ros38"          # symlinks to Debian's pure-Python ROS packages
OVERLAY="$OUT/overlay"      # catkin workspace overlay: lib/underwater_quadruped/<node> wrappers
RECORDS="$OUT/records"      # <pid>.json, written by each node process on 3.8
mkdir -p "$OVERLAY/lib/underwater_quadruped" "$RECORDS"
touch "$OVERLAY/.catkin"
/usr/bin/python3 tests/python38_graph/ros_path.py "$ROS38" "$py38" || { echo "python38_graph: FAILED: $ROS38"; exit 1; }

for script in nodes/*; do
  node="$(basename "$script")"
  wrapper="$OVERLAY/lib/underwater_quadruped/$node"
  if [ -n "${KEEP_ON_ROS_PYTHON[$node]:-}" ]; then
    ln -s "$UQ_WS/devel/lib/underwater_quadruped/$node" "$wrapper"  # catkin's relay: the ROS Python
    continue
  fi
  cat >"$wrapper" <<EOF
#!/bin/sh
# tests/python38_graph.sh: $node on Python 3.8, with ROS's pure-Python packages and the devel space
export PYTHONPATH="$ROS38:$DEVEL_PY" PYTHONDONTWRITEBYTECODE=1 UQ_PY38_RECORD="$RECORDS"
exec "$py38" "$ROOT/tests/python38_graph/node.py" "$ROOT/$script" "\$@"
EOF
  chmod +x "$wrapper"
done
echo "python38_graph: the nodes on $("$py38" --version) ($py38); rostests: ${TESTS[*]}"
echo "python38_graph: on the ROS Python ($("$SYSTEM_PYTHON" --version)): roscore, roslaunch, rostest, the test nodes;"
for node in "${!KEEP_ON_ROS_PYTHON[@]}"; do echo "python38_graph:   $node: ${KEEP_ON_ROS_PYTHON[$node]}"; done

failed=0; passed_cases=0; failed_cases=0
for name in "${TESTS[@]}"; do
  home="$OUT/$name"; mkdir -p "$home"
  start=$SECONDS
  ROS_HOME="$home" ROS_LOG_DIR="$home/log" CMAKE_PREFIX_PATH="$OVERLAY:$CMAKE_PREFIX_PATH" \
    timeout 900 rostest underwater_quadruped "$name.test" >"$OUT/rostest-$name.log" 2>&1
  rc=$?
  result="$("$SYSTEM_PYTHON" tests/python38_graph/check.py --rostest-exit "$rc" --test-file "tests/rostest/$name.test" \
      --results "$home/test_results" --log-dir "$home/log" --records "$RECORDS" --overlay "$OVERLAY" \
      --keep "${!KEEP_ON_ROS_PYTHON[@]}" --restarts-ok ${RESTARTS_BY_DESIGN[$name]:-})"
  check_rc=$?
  echo "$result" | sed "s/^/   /"
  read -r ok bad < <(echo "$result" | sed -n 's/^cases: \([0-9]*\) passed, \([0-9]*\) failed$/\1 \2/p')
  passed_cases=$((passed_cases + ${ok:-0})); failed_cases=$((failed_cases + ${bad:-1}))
  if [ "$check_rc" -eq 0 ]; then
    echo "   ok: $name ($((SECONDS - start)) s)"
  else
    failed=$((failed + 1))
    echo "   FAILED: $name ($((SECONDS - start)) s); last lines of $OUT/rostest-$name.log:"
    tail -30 "$OUT/rostest-$name.log"
  fi
done
echo "python38_graph: ${#TESTS[@]} rostests with the nodes on Python 3.8, $failed failed" \
  "($passed_cases cases passed, $failed_cases failed)"
[ "$failed" -eq 0 ]
