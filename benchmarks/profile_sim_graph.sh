#!/usr/bin/env bash
# Where the time goes in the simulated graph (real-time mode, headless, recording): runs the 45 deg roll
# maneuver for DURATION s (default 40) and, during its last DURATION-15 s, samples every node with py-spy
# (on-CPU samples only, 200 Hz, non-blocking: the nodes are not paused) and reads each process's CPU time
# from /proc. Prints per node: CPU use (% of one core) and the functions that use it (self time, and
# time including callees for the stack's own code), so that the cost of a 100 Hz cycle can be split into
# bus bridge round trips, the pty pump, rosbag, rospy transport, GC, the model and the controller.
# Usage: bash benchmarks/profile_sim_graph.sh [DURATION]; run it under flock /tmp/uq-ros.lock.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
DURATION="${1:-40}"
OUT="$(mktemp -d /tmp/uq_profile_graph.XXXXXX)"
UQ_ROS_PORT="${UQ_ROS_PORT:-11359}" bash scripts/sim_maneuver.sh "$OUT/run" "$DURATION" >/dev/null &
RUN_PID=$!
sleep 15  # start-up and the level hold
SAMPLE=$((DURATION - 15 > 5 ? DURATION - 20 : 5))
NODES=(sim_node vn100_node attitude_controller pwm_node servo_feedback_node recorder)
declare -A PIDS
for node in "${NODES[@]}"; do
  pid="$(pgrep -f "__name:=$node( |$)" | head -1 || true)"
  [ -n "$pid" ] && PIDS[$node]="$pid"
done
cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat" 2>/dev/null || echo 0; }
declare -A START
for node in "${!PIDS[@]}"; do
  START[$node]="$(cpu_ticks "${PIDS[$node]}")"
  py-spy record --nonblocking --format raw --rate 200 --duration "$SAMPLE" --pid "${PIDS[$node]}" \
    --output "$OUT/$node.txt" >/dev/null 2>&1 &
done
sleep "$SAMPLE"
TICK="$(getconf CLK_TCK)"
for node in "${!PIDS[@]}"; do
  echo "$node $(( $(cpu_ticks "${PIDS[$node]}") - START[$node] ))" >>"$OUT/cpu.txt"
done
wait $RUN_PID || true
python - "$OUT" "$SAMPLE" "$TICK" <<'PYEOF'
import collections, os, re, sys
out, seconds, tick = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
cpu = dict(line.split() for line in open(os.path.join(out, "cpu.txt")))
OURS = re.compile(r"quadruped_(control|drivers)/")
def short(frame):
    m = re.match(r"(.*) \((.*):(\d+)\)$", frame)
    return "%s (%s)" % (m.group(1), os.path.basename(m.group(2))) if m else frame
for node in sorted(cpu, key=lambda n: -int(cpu[n])):
    share = 100.0 * int(cpu[node]) / tick / seconds
    path = os.path.join(out, node + ".txt")
    self_time, ours = collections.Counter(), collections.Counter()
    total = 0
    if os.path.exists(path):
        for line in open(path):
            stack, _, count = line.rstrip("\n").rpartition(" ")
            if not stack:
                continue
            count = int(count)
            frames = stack.split(";")
            total += count
            self_time[short(frames[-1])] += count
            for frame in set(f for f in frames if OURS.search(f)):
                ours[short(frame)] += count
    print("%s: %.1f %% of one core (%d py-spy samples)" % (node, share, total))
    for name, count in self_time.most_common(8):
        print("    self %5.1f %%  %s" % (100.0 * count / max(total, 1), name))
    for name, count in ours.most_common(6):
        print("    incl %5.1f %%  %s" % (100.0 * count / max(total, 1), name))
PYEOF
echo "(raw py-spy stacks and the run in $OUT)"
