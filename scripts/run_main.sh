#!/usr/bin/env bash
# The main job: the whole stack on the simulated robot, ending in a report.
# Does its own set-up first (scripts/setup.sh). Output goes to out/ (ignored by git).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
set +u
# shellcheck disable=SC1091
source scripts/env.sh
set -u
OUT="${UQ_OUT:-$ROOT/out}"
mkdir -p "$OUT"

echo "== Offline closed-loop simulation: the paper's simulation study (model + controller, no ROS) =="
python -m quadruped_control.simulate --study paper-sim --out "$OUT/paper-sim"
echo
echo "Report: $OUT/paper-sim (study.json, figure)"
