#!/usr/bin/env bash
# Runs every test: the Python 3.8 compatibility check, pytest for the pure modules, and the rostest
# suite of the node graph. Does its own set-up first (scripts/setup.sh). Extra arguments go to pytest.
# Ends with one summary line "N passed, N failed" over pytest and rostest.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"

RESULTS="$ROOT/build/test_results"
rm -rf "$RESULTS"; mkdir -p "$RESULTS"
failures=0

echo "== Python 3.8 compatibility (vermin) =="
PY_SOURCES=(quadruped_common quadruped_control quadruped_drivers nodes cfg/AttitudeController.cfg setup.py)
if ! vermin -q -t=3.8- --no-tips --violations --eval-annotations \
     --exclude-regex '\.venv|build/' "${PY_SOURCES[@]}"; then
  echo "vermin: sources need a Python newer than 3.8"; failures=$((failures + 1))
fi

# Steps that are not pytest or rostest cases each count as one case of the closing line.
steps_passed=0; steps_failed=0
run_step() {  # run_step NAME COMMAND...: output to the console and to $RESULTS/NAME.log
  local name="$1"; shift
  if "$@" 2>&1 | tee "$RESULTS/$name.log"; then
    steps_passed=$((steps_passed + 1)); echo "   $name: ok"
  else
    steps_failed=$((steps_failed + 1)); failures=$((failures + 1)); echo "   $name: FAILED"
  fi
}

echo "== catkin_lint -W2 (the package, as the workspace sees it) =="
if command -v catkin_lint >/dev/null; then
  run_step catkin_lint catkin_lint -W2 --strict "$UQ_WS/src/underwater_quadruped"
else
  echo "catkin_lint: SKIPPED: not installed (scripts/setup.sh installs Debian's catkin-lint; pip install catkin-lint)"
fi

echo "== import-linter: the floors of the code base (.importlinter) =="
if command -v lint-imports >/dev/null; then
  run_step lint_imports lint-imports --no-cache --no-logo
else
  echo "lint-imports: SKIPPED: not installed (requirements.txt pins import-linter)"
fi

echo "== pure core under Python 3.8 with requirements-jetson.txt =="
run_step python38 bash tests/python38.sh

echo "== pytest (pure modules) =="
python -m pytest -q -p no:cacheprovider --junitxml="$RESULTS/pytest.xml" tests "$@"
pytest_rc=$?
if [ "$pytest_rc" -ne 0 ]; then failures=$((failures + 1)); fi

echo "== rostest (node graph) =="
export ROS_HOME="$RESULTS/ros_home"; mkdir -p "$ROS_HOME"
export ROS_LOG_DIR="$ROS_HOME/log"
rostest_passed=0; rostest_failed=0
# rostest's exit status alone is not trusted: a test node that dies before reporting can still end in
# "OK". A .test file passes only when every test node wrote its rosunit-*.xml with tests and without
# failures or errors; the cases in those files are what the summary counts.
count_rostest_cases() {
  python - "$@" <<'PYEOF'
import sys, xml.etree.ElementTree as ET
tests = bad = 0
for path in sys.argv[1:]:
    try:
        root = ET.parse(path).getroot()
    except Exception:
        bad += 1
        continue
    suites = [root] if root.tag == "testsuite" else list(root)
    for suite in suites:
        tests += int(suite.get("tests", 0))
        bad += int(suite.get("failures", 0)) + int(suite.get("errors", 0))
print(tests - bad, bad)
PYEOF
}
# The lock-step closed-loop rostest saves its simulated trajectory here for the determinism check below.
export UQ_TRAJECTORY_FILE="$RESULTS/closed_loop_trajectory.npz"
for t in tests/rostest/*.test; do
  [ -e "$t" ] || continue
  name="$(basename "$t" .test)"
  echo "-- rostest $name"
  rm -rf "$ROS_HOME/test_results"
  timeout 900 rostest underwater_quadruped "$name.test" >"$RESULTS/rostest-$name.log" 2>&1
  rc=$?
  mapfile -t unit_files < <(find "$ROS_HOME/test_results" -name 'rosunit-*.xml' 2>/dev/null)
  expected="$(grep -c '<test ' "$t")"
  if [ "${#unit_files[@]}" -gt 0 ]; then
    read -r ok bad < <(count_rostest_cases "${unit_files[@]}")
  else
    ok=0; bad=1
  fi
  cp "${unit_files[@]}" "$RESULTS/" 2>/dev/null || true
  if [ "$rc" -eq 0 ] && [ "$bad" -eq 0 ] && [ "${#unit_files[@]}" -ge "$expected" ] && [ "$ok" -gt 0 ]; then
    rostest_passed=$((rostest_passed + ok)); echo "   ok ($ok cases)"
  else
    rostest_failed=$((rostest_failed + (bad > 0 ? bad : 1))); failures=$((failures + 1))
    echo "   FAILED (exit $rc, ${#unit_files[@]}/$expected result files, $bad failed cases); last lines of $RESULTS/rostest-$name.log:"
    tail -40 "$RESULTS/rostest-$name.log"
  fi
done

# Lock-step determinism: the closed loop again with both cores kept busy by other processes must give
# the same simulated trajectory (to 1e-6) as the run above.
echo "-- lock-step determinism (closed loop again under full CPU load)"
if [ -s "$UQ_TRAJECTORY_FILE" ] && ROS_HOME="$ROS_HOME" bash scripts/check_lockstep_determinism.sh "$UQ_TRAJECTORY_FILE" \
    >"$RESULTS/lockstep-determinism.log" 2>&1; then
  rostest_passed=$((rostest_passed + 1)); echo "   ok ($(grep -h "common samples" "$RESULTS/lockstep-determinism.log"))"
else
  rostest_failed=$((rostest_failed + 1)); failures=$((failures + 1))
  echo "   FAILED; last lines of $RESULTS/lockstep-determinism.log:"; tail -20 "$RESULTS/lockstep-determinism.log"
fi
unset UQ_TRAJECTORY_FILE

echo "== install space: catkin_make install into a temporary prefix, sim.launch from there =="
run_step install_space bash tests/install_space.sh

# Count pytest cases from its JUnit file so that the closing line covers the whole run.
read -r py_passed py_failed < <(python - "$RESULTS/pytest.xml" <<'PYEOF'
import sys, xml.etree.ElementTree as ET
try:
    root = ET.parse(sys.argv[1]).getroot()
except Exception:
    print(0, 1); raise SystemExit
suites = [root] if root.tag == "testsuite" else list(root)
tests = sum(int(s.get("tests", 0)) for s in suites)
bad = sum(int(s.get("failures", 0)) + int(s.get("errors", 0)) for s in suites)
skipped = sum(int(s.get("skipped", 0)) for s in suites)
print(tests - bad - skipped, bad)
PYEOF
)
echo "rostest: $rostest_passed passed, $rostest_failed failed"
echo "steps (catkin_lint, lint_imports, python38, install_space): $steps_passed passed, $steps_failed failed"
echo "$((py_passed + rostest_passed + steps_passed)) passed, $((py_failed + rostest_failed + steps_failed)) failed"
[ "$failures" -eq 0 ]
