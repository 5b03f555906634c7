#!/usr/bin/env bash
# Runs the tests. Does its own set-up first (scripts/setup.sh).
#
#   bash scripts/run_tests.sh                  the full tier (what CI runs): Python 3.8 check, lint,
#                                              pytest, every rostest, lock-step determinism, install space,
#                                              the fault-free rostests with the nodes on Python 3.8
#   bash scripts/run_tests.sh --fast [PATH..]  the fast tier, after every edit: the unit tests of common,
#                                              drivers, model, control, bring-up, analysis; no kernels
#                                              (UQ_NO_JIT=1) and no test marked slow; PATHs run instead
#   bash scripts/run_tests.sh --rostest NAME   one rostest, tests/rostest/NAME.test
#
# Other arguments go to pytest. Ends with one summary line "N passed, N failed".
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

usage() { awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; }
TIER=full; ROSTEST_ONLY=""
case "${1:-}" in
  --fast) TIER=fast; shift ;;
  --rostest)
    [ $# -ge 2 ] || { usage >&2; exit 2; }
    TIER=rostest; ROSTEST_ONLY="$2"; shift 2
    [ -f "tests/rostest/$ROSTEST_ONLY.test" ] || {
      echo "run_tests.sh: no tests/rostest/$ROSTEST_ONLY.test; the rostests are:" \
        "$(cd tests/rostest && ls ./*.test | sed 's|^./||; s|\.test$||' | tr '\n' ' ')" >&2; exit 2; } ;;
  -h|--help) usage; exit 0 ;;
esac

#: the fast tier: the robot's pure code, the analysis, and the README's and the layers' checks
FAST_PATHS=(tests/common tests/drivers tests/control/model tests/control/control tests/control/bringup tests/control/analysis
            tests/test_readme.py tests/test_code_shape.py tests/test_layers.py tests/test_package_manifest.py)

section() { echo "== $* [at $((SECONDS / 60))m$((SECONDS % 60))s] =="; }

export UQ_WITH_TESTS=1  # on the robot, setup.sh installs the tests' packages too
source "$ROOT/scripts/prepare.sh"

if [ "$TIER" = fast ]; then
  paths=()
  for arg in "$@"; do if [ -e "${arg%%::*}" ]; then paths+=("$arg"); fi; done  # a file or test id, not -k EXPR
  if [ "${#paths[@]}" -eq 0 ]; then set -- "${FAST_PATHS[@]}" "$@"; fi
  UQ_NO_JIT=1 exec python -m pytest -q -p no:cacheprovider -m "not slow" "$@"
fi

RESULTS="$ROOT/build/test_results"
rm -rf "$RESULTS"; mkdir -p "$RESULTS"
failures=0

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

if [ "$TIER" = full ]; then
# The batched simulator's kernels compile once, here, beside the lint steps; the pytest workers then load
# them from numba's on-disk cache instead of each compiling them (quadruped_common/jit.py).
if python -c "import numba" 2>/dev/null; then
  section "compiled kernels: one short batch on each plant, started beside the lint steps"
  ( python -m quadruped_control.simulate --study paper-experiments --engine batch --duration 0.5 --jobs 1 \
      --no-resume --quiet --out "$RESULTS/kernels-tank" \
    && python -m quadruped_control.simulate --study paper-experiments --plant paper --engine batch --duration 0.5 \
      --jobs 1 --no-resume --quiet --out "$RESULTS/kernels-paper" ) >"$RESULTS/kernels.log" 2>&1 &
  kernels_pid=$!
fi

section "Python 3.8 compatibility (vermin)"
PY_SOURCES=(quadruped_common quadruped_control quadruped_drivers nodes cfg/AttitudeController.cfg setup.py)
if ! vermin -q -t=3.8- --no-tips --violations --eval-annotations \
     --exclude-regex '\.venv|build/' "${PY_SOURCES[@]}"; then
  echo "vermin: sources need a Python newer than 3.8"; failures=$((failures + 1))
fi

section "catkin_lint -W2 (the package, as the workspace sees it)"
if command -v catkin_lint >/dev/null; then
  run_step catkin_lint catkin_lint -W2 --strict "$UQ_WS/src/underwater_quadruped"
else
  echo "catkin_lint: SKIPPED: not installed (scripts/setup.sh installs Debian's catkin-lint; pip install catkin-lint)"
fi

section "import-linter: the floors of the code base (.importlinter)"
if command -v lint-imports >/dev/null; then
  run_step lint_imports lint-imports --no-cache --no-logo
else
  echo "lint-imports: SKIPPED: not installed (requirements.txt pins import-linter)"
fi

# The Python 3.8 step runs beside pytest (both pure Python).
section "the robot's code under Python 3.8 with requirements-jetson-test.txt: started beside pytest"
bash tests/python38.sh >"$RESULTS/python38-background.log" 2>&1 &
python38_pid=$!

if [ -n "${kernels_pid:-}" ] && ! wait "$kernels_pid"; then
  echo "   the kernels' warm-up failed (the tests compile them themselves); last lines of $RESULTS/kernels.log:"
  tail -5 "$RESULTS/kernels.log"
fi
# Both cores when pytest-xdist is installed (requirements.txt; not on the robot); an idle worker takes
# tests queued on the other (worksteal), so one long study test does not end the step alone.
workers=()
if python -c "import xdist" 2>/dev/null; then workers=(-n 2 --dist worksteal); fi

section "pytest (pure modules)"
python -m pytest -q -p no:cacheprovider "${workers[@]}" --junitxml="$RESULTS/pytest.xml" tests "$@"
pytest_rc=$?
if [ "$pytest_rc" -ne 0 ]; then failures=$((failures + 1)); fi

section "the robot's code under Python 3.8 (tests/python38.sh)"
python38_rc=0; wait "$python38_pid" || python38_rc=$?
run_step python38 bash -c 'cat "$1"; exit "$2"' _ "$RESULTS/python38-background.log" "$python38_rc"
fi

section "rostest (node graph)"
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
# Each rostest runs once: those the node graph under Python 3.8 runs (tests/python38_graph.sh, below) run
# there only, with the nodes on the robot's interpreter, when a 3.8 is found; sim_closed_loop runs here too
# (the determinism check below needs its trajectory).
ON_PY38=()
if [ -z "${ROSTEST_ONLY:-}" ] && bash tests/python38.sh --venv-only >/dev/null 2>&1; then
  mapfile -t ON_PY38 < <(sed -n 's/^DEFAULT_TESTS=(\(.*\))$/\1/p' tests/python38_graph.sh | tr ' ' '\n' \
                         | grep -vx sim_closed_loop)
fi
for t in tests/rostest/${ROSTEST_ONLY:-*}.test; do
  [ -e "$t" ] || continue
  name="$(basename "$t" .test)"
  if printf '%s\n' "${ON_PY38[@]}" | grep -qx "$name"; then
    echo "-- rostest $name: runs with the nodes on Python 3.8 (the python38_graph step)"
    continue
  fi
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

if [ "$TIER" = full ]; then
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

section "install space: catkin_make install into a temporary prefix, sim.launch from there"
run_step install_space bash tests/install_space.sh

section "the node graph under Python 3.8: fault-free rostests, every node on 3.8 (tests/python38_graph.sh)"
UQ_PY38_GRAPH_OUT="$RESULTS/python38_graph" run_step python38_graph bash tests/python38_graph.sh

fi

# Count pytest cases from its JUnit file so that the closing line covers the whole run.
py_passed=0; py_failed=0
[ "$TIER" = full ] && read -r py_passed py_failed < <(python - "$RESULTS/pytest.xml" <<'PYEOF'
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
echo "time: $((SECONDS / 60))m$((SECONDS % 60))s (set-up included)"
echo "rostest: $rostest_passed passed, $rostest_failed failed"
echo "steps (catkin_lint, lint_imports, python38, install_space, python38_graph): $steps_passed passed, $steps_failed failed"
echo "$((py_passed + rostest_passed + steps_passed)) passed, $((py_failed + rostest_failed + steps_failed)) failed"
[ "$failures" -eq 0 ]
