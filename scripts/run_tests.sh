#!/usr/bin/env bash
# Runs every test: the Python 3.8 compatibility check, pytest for the pure modules, and the rostest
# suite of the node graph. Does its own set-up first (scripts/setup.sh). Extra arguments go to pytest.
# Ends with one summary line "N passed, N failed" over pytest and rostest.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh || exit 1
set +u
# shellcheck disable=SC1091
source scripts/env.sh
set -u

RESULTS="$ROOT/build/test_results"
rm -rf "$RESULTS"; mkdir -p "$RESULTS"
failures=0

echo "== Python 3.8 compatibility (vermin) =="
PY_SOURCES=(quadruped_control quadruped_drivers nodes cfg/AttitudeController.cfg setup.py)
if ! vermin -q -t=3.8- --no-tips --violations --eval-annotations \
     --exclude-regex '\.venv|build/' "${PY_SOURCES[@]}"; then
  echo "vermin: sources need a Python newer than 3.8"; failures=$((failures + 1))
fi

echo "== pytest (pure modules) =="
python -m pytest -q -p no:cacheprovider --junitxml="$RESULTS/pytest.xml" tests "$@"
pytest_rc=$?
if [ "$pytest_rc" -ne 0 ]; then failures=$((failures + 1)); fi

echo "== rostest (node graph) =="
export ROS_HOME="$RESULTS/ros_home"; mkdir -p "$ROS_HOME"
export ROS_LOG_DIR="$ROS_HOME/log"
rostest_passed=0; rostest_failed=0
for t in tests/rostest/*.test; do
  [ -e "$t" ] || continue
  name="$(basename "$t" .test)"
  echo "-- rostest $name"
  if timeout 600 rostest --text underwater_quadruped "$name.test" \
       --results-filename "rostest-$name.xml" >"$RESULTS/rostest-$name.log" 2>&1; then
    rostest_passed=$((rostest_passed + 1)); echo "   ok"
  else
    rostest_failed=$((rostest_failed + 1)); failures=$((failures + 1))
    echo "   FAILED, last lines of $RESULTS/rostest-$name.log:"; tail -30 "$RESULTS/rostest-$name.log"
  fi
done

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
echo "$((py_passed + rostest_passed)) passed, $((py_failed + rostest_failed)) failed"
[ "$failures" -eq 0 ]
