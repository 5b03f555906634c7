#!/usr/bin/env bash
# Every benchmark (`make bench`): each prints its own figures. Not part of the test command: timing on a
# shared 2-core machine is noisy, so these are measured and reported, never asserted.
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
source "$ROOT/scripts/prepare.sh"
status=0
for bench in benchmarks/bench_*.py; do
  echo "== $bench"
  python "$bench" || status=1
  echo
done
echo "== benchmarks/bench_sim_graph.sh"
bash benchmarks/bench_sim_graph.sh || status=1
exit $status
