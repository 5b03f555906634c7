# Sourced by every entry script (run_main, run_tests, run_benchmarks, benchmarks, rviz_screenshot): the
# idempotent set-up (scripts/setup.sh), then the stack's environment (scripts/env.sh). Stops the calling
# script when the set-up fails.
bash "$(dirname "${BASH_SOURCE[0]}")/setup.sh" || exit 1
set +u  # ROS setup files read unset variables
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
set -u
