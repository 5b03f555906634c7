#!/usr/bin/env bash
# The main job: the whole stack on the simulated robot, ending in a report.
# Does its own set-up first (scripts/setup.sh). Output goes to out/ (ignored by git), or $UQ_OUT.
#
#  1. The paper's simulation study, offline (model + controller, no ROS): out/paper-sim.
#  2. The pre-dive check on the simulated robot (lock-step, a simulated operator on the stand): out/preflight,
#     its report also beside the maneuver's.
#  3. The ROS graph on the simulated robot (sim.launch, headless: sim_node behind the fake PCA9685 /
#     ADS1115 / TCA9548A / VN-100, the unchanged driver nodes, the attitude controller), armed, level
#     for 5 s, then a 45 degree roll maneuver for UQ_DURATION s (default 120), recorded to a bag.
#  4. The report made from the bag: the paper's metrics, a figure, the stack's health (rates, loop
#     jitter, IMU-to-PWM latency, error counters): out/sim-maneuver/report.md.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
OUT="${UQ_OUT:-$ROOT/out}"
DURATION="${UQ_DURATION:-120}"
mkdir -p "$OUT"

echo "== 1/4 Offline closed-loop simulation: the paper's simulation study (no ROS) =="
python -m quadruped_control.simulate --study paper-sim --jobs 2 --no-resume --out "$OUT/paper-sim"

echo
echo "== 2/4 The pre-dive check on the simulated robot =="
bash scripts/sim_preflight.sh "$OUT/preflight"

echo
echo "== 3/4 The ROS stack on the simulated robot: 45 deg roll maneuver, ${DURATION} s, recorded =="
bash scripts/sim_maneuver.sh "$OUT/sim-maneuver" "$DURATION"
cp "$OUT"/preflight/preflight_*.md "$OUT/sim-maneuver/preflight.md"

echo
echo "== 4/4 Report from the bag =="
python -m quadruped_control.analysis.bag_report "$OUT"/sim-maneuver/bags/*.bag --out "$OUT/sim-maneuver" \
  --title "Simulated robot through the full ROS stack: 45 deg roll"
echo
echo "Reports: $OUT/paper-sim (study.json, paper_sim.png), $OUT/sim-maneuver (report.md, metrics.json, attitude.png,"
echo "         preflight.md: the pre-dive check before the maneuver)"
