# Source this file to get the stack's environment in a shell:  source scripts/env.sh
# (after `make setup`). It puts the venv first on PATH and sources the catkin workspace.
_uq_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ -f /opt/ros/noetic/setup.bash ]; then
  # shellcheck disable=SC1091
  source /opt/ros/noetic/setup.bash
fi
# shellcheck disable=SC1091
source "$_uq_root/.ws/devel/setup.bash"
export PATH="$_uq_root/.venv/bin:$PATH"
export VIRTUAL_ENV="$_uq_root/.venv"
export UQ_ROOT="$_uq_root"
export PYTHONDONTWRITEBYTECODE=1
unset _uq_root
