#!/usr/bin/env bash
# The servo tracking watch on a healthy simulated robot: RUNS (default 20) runs of the main job's manoeuvre
# (scripts/sim_maneuver.sh: armed at start, level for 5 s, then a 45 deg roll) of DURATION s (default 30) each,
# one after the other. Prints, per run, how many times the controller named a joint in its "servo tracking"
# diagnostic (its WARN / ERROR log lines) and every joint's largest tracking-error RMS since arming (the last
# "servo tracking" status in the bag), then the total and the largest over the runs: the evidence for
# tracking.bound (config/safety.yaml). A healthy robot must give 0 reports.
# Usage: bash benchmarks/healthy_tracking.sh [DURATION [RUNS]]   (on a quiet machine)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
DURATION="${1:-30}"
RUNS="${2:-20}"
OUT="$(mktemp -d /tmp/uq_healthy_tracking.XXXXXX)"
for run in $(seq 1 "$RUNS"); do
  bash scripts/sim_maneuver.sh "$OUT/run$run" "$DURATION" >/dev/null
done
python - "$OUT" "$RUNS" <<'PY'
import glob, os, re, sys
from pathlib import Path
from rosbags.highlevel import AnyReader
out, runs = sys.argv[1], int(sys.argv[2])
total, largest = 0, 0.0
for run in range(1, runs + 1):
    folder = os.path.join(out, "run%d" % run)
    with open(os.path.join(folder, "launch.log"), errors="replace") as log:
        reports = sum(1 for line in log if "servo tracking:" in line)
    last = None
    with AnyReader([Path(p) for p in sorted(glob.glob(os.path.join(folder, "bags", "*.bag")))]) as reader:
        connections = [c for c in reader.connections if c.topic == "/diagnostics"]
        for connection, _, raw in reader.messages(connections=connections):
            for status in reader.deserialize(raw, connection.msgtype).status:
                if status.name.endswith("servo tracking") and status.message != "not armed: not judged":
                    last = status
    worst = max((float(re.search(r"largest since arming ([0-9.]+) deg", v.value).group(1)), v.key)
                for v in last.values) if last else (float("nan"), "-")
    total += reports
    largest = max(largest, worst[0])
    print("run %2d: %d tracking reports, largest RMS since arming %.2f deg (%s)" % (run, reports, worst[0], worst[1]))
print("%d runs of %s: %d tracking reports; largest RMS %.2f deg; folder %s" % (runs, "the manoeuvre", total, largest, out))
PY
