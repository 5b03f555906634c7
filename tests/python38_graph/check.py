"""Judge one rostest of tests/python38_graph.sh: did it pass, and did its nodes really run on Python 3.8?

Passes when (1) rostest exited 0 and every test node wrote its rosunit-*.xml with tests and without
failures or errors (as scripts/run_tests.sh counts them), and (2) each process roslaunch started (its
log: "process[NAME]: start w/ args [...]" then "started with pid [PID]") from the package's nodes/
came through the Python 3.8 overlay and left a record of its own (tests/python38_graph/node.py:
``RECORDS/<pid>.json``) saying Python 3.8 and an executable python3.8; the nodes named by --keep are
expected on the ROS Python instead; none was started twice (a respawn is a crash in a fault-free test),
but those named by --restarts-ok (killed by the test on purpose). Processes started by a roslaunch that
the test node runs itself (fault_campaign) are found in its roslaunch-*.log. Prints one line per
process, then "cases: N passed, M failed".
"""
import argparse
import ast
import glob
import json
import os
import re
import sys
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
START = re.compile(r"process\[(\S+)\]: start w/ args \[(\[.*\])\]$")
PID = re.compile(r"process\[(\S+)\]: started with pid \[(\d+)\]")


def rosunit_cases(results, test_file, rostest_exit):
    """(passed cases, failed cases, problems) of the rosunit files below ``results``."""
    files = sorted(glob.glob(os.path.join(results, "**", "rosunit-*.xml"), recursive=True))
    with open(test_file) as stream:
        expected = stream.read().count("<test ")
    tests = bad = 0
    for path in files:
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError:
            bad += 1
            continue
        for suite in [root] if root.tag == "testsuite" else list(root):
            tests += int(suite.get("tests", 0))
            bad += int(suite.get("failures", 0)) + int(suite.get("errors", 0))
    problems = []
    if rostest_exit != 0:
        problems.append("rostest exited %d" % rostest_exit)
    if len(files) < expected:
        problems.append("%d of %d test nodes wrote results" % (len(files), expected))
    if bad or tests - bad <= 0:
        problems.append("%d failed cases, %d passed" % (bad, tests - bad))
    return tests - bad, max(bad, 1 if problems else 0), problems


def started_processes(log_dir):
    """[(process name, command line, pid)] of every start roslaunch logged, respawns included, in order."""
    started = []
    logs = glob.glob(os.path.join(log_dir, "**", "rostest-*.log"), recursive=True)
    logs += glob.glob(os.path.join(log_dir, "**", "roslaunch-*.log"), recursive=True)  # roslaunch run by a test
    for path in sorted({os.path.realpath(log) for log in logs}):  # once each: log/latest links a run's folder
        commands = {}
        with open(path, errors="replace") as stream:
            for line in stream:
                match = START.search(line.rstrip("\n"))
                if match:
                    commands.setdefault(match.group(1), []).append(ast.literal_eval(match.group(2)))
                    continue
                match = PID.search(line)
                if match:
                    name = match.group(1)
                    command = commands.get(name, [None]).pop(0) if commands.get(name) else None
                    started.append(("%s (%s)" % (name, os.path.basename(path)) if "roslaunch-" in path else name,
                                    command, int(match.group(2))))
    return started


def judge_process(name, command, pid, args, test_types):
    """(line, ok, on 3.8) for one started process."""
    package_nodes = set(os.listdir(os.path.join(ROOT, "nodes")))
    overlay_dir = os.path.join(os.path.abspath(args.overlay), "lib", "underwater_quadruped") + os.sep
    if not command:
        return "%s pid %d: no command in roslaunch's log" % (name, pid), False, False
    # the executable roslaunch resolved, after a launch-prefix if any (e.g. chrt -f 20 in fault_campaign)
    resolved = [arg for arg in command if arg.startswith(overlay_dir) or os.path.basename(arg) in package_nodes
                or os.path.basename(arg) in test_types]
    command = resolved[0] if resolved else command[0]
    base = os.path.basename(command)
    if command.startswith(overlay_dir):
        if base in args.keep:
            return "%s pid %d: %s on the ROS Python, by design" % (name, pid, base), True, False
        path = os.path.join(args.records, "%d.json" % pid)
        if not os.path.exists(path):
            return "%s pid %d: %s left no Python 3.8 record (%s)" % (name, pid, base, path), False, False
        with open(path) as stream:
            record = json.load(stream)
        exe = os.path.basename(record["executable"])
        ok = (record["version"].startswith("3.8.") and exe.startswith("python3.8")
              and os.path.basename(record["script"]) == base)
        return ("%s pid %d: %s on Python %s, %s" % (name, pid, base, record["version"], record["executable"]),
                ok, ok)
    if base in package_nodes:
        return "%s pid %d: %s started without the 3.8 overlay: %s" % (name, pid, base, command), False, False
    if base in test_types:
        return "%s pid %d: test node %s on the ROS Python" % (name, pid, base), True, False
    return "%s pid %d: not a node of the package: %s" % (name, pid, command), True, False


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rostest-exit", type=int, required=True)
    parser.add_argument("--test-file", required=True)
    parser.add_argument("--results", required=True)
    parser.add_argument("--log-dir", required=True)
    parser.add_argument("--records", required=True)
    parser.add_argument("--overlay", required=True)
    parser.add_argument("--keep", nargs="*", default=[], help="nodes (nodes/ names) expected on the ROS Python")
    parser.add_argument("--restarts-ok", nargs="*", default=[],
                        help="process names (as in the launch file) the test kills on purpose; any: all")
    args = parser.parse_args()
    with open(args.test_file) as stream:
        test_types = set(re.findall(r"<test\b[^>]*\btype=\"([^\"]+)\"", stream.read()))
    passed, failed, problems = rosunit_cases(args.results, args.test_file, args.rostest_exit)
    on_38 = 0
    starts = {}
    started = started_processes(args.log_dir)
    for name, command, pid in started:
        line, ok, is_38 = judge_process(name, command, pid, args, test_types)
        print(line)
        on_38 += is_38
        if not ok:
            problems.append(line)
        starts[name] = starts.get(name, 0) + 1
    for name, count in sorted(starts.items()):
        launch_name = name.split(" ")[0].rsplit("-", 1)[0]
        if count > 1 and launch_name not in args.restarts_ok and "any" not in args.restarts_ok:
            problems.append("%s started %d times (a respawn: it died)" % (name, count))
    if not started:
        problems.append("no process start in roslaunch's log (%s)" % args.log_dir)
    elif on_38 == 0:
        problems.append("no node ran on Python 3.8")
    for problem in problems:
        print("PROBLEM: " + problem)
    if problems:
        failed = max(failed, 1)
    print("cases: %d passed, %d failed" % (passed, failed))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
