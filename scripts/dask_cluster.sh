#!/usr/bin/env bash
# A Dask scheduler or worker that can run this package's studies (python -m quadruped_control.simulate
# --study ... --dask-scheduler tcp://HOST:8786):
#
#   bash scripts/dask_cluster.sh scheduler [dask scheduler options, e.g. --port 8786]
#   bash scripts/dask_cluster.sh worker tcp://HOST:8786 [dask worker options, e.g. --nworkers 2 --nthreads 1]
#
# Why a launcher: the scheduler unpickles every task graph a client sends (distributed >= 2023.4), so it
# must import quadruped_control just as the workers do. A `dask scheduler` started from a plain shell
# cannot, and every trial fails with "Error during deserialization of the task graph". This script runs
# both from the project's environment (scripts/env.sh: the catkin workspace built by scripts/setup.sh and
# its venv), on every machine of the cluster (each needs a clone set up with scripts/setup.sh).
set -eo pipefail  # not -u: ROS's setup.bash reads unset variables
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
role="${1:-}"
case "$role" in
  scheduler|worker)
    shift
    exec "$UQ_ROOT/.venv/bin/dask" "$role" "$@"
    ;;
  *)
    echo "usage: $0 scheduler [options] | worker ADDRESS [options]" >&2
    exit 2
    ;;
esac
