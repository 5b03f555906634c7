# Convenience for an interactive shell:  source scripts/env.sh   (after scripts/setup.sh)
# It is `source <workspace>/devel/setup.bash` (which also puts the venv's tools first on PATH, through the
# package's catkin env-hook) for the workspace scripts/setup.sh built; the workspace path is printed by
# the set-up and defaults to the sibling folder "<clone>_ws" (scripts/paths.sh).
# shellcheck disable=SC1091
source "$(dirname "${BASH_SOURCE[0]}")/paths.sh"
if [ ! -f "$UQ_WS/devel/setup.bash" ]; then
  echo "env.sh: no workspace at $UQ_WS; run: bash $UQ_ROOT/scripts/setup.sh" >&2
  return 1 2>/dev/null || exit 1
fi
# shellcheck disable=SC1091
source "$UQ_WS/devel/setup.bash"
export PYTHONDONTWRITEBYTECODE=1
