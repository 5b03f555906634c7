# Sourced by scripts/setup.sh and scripts/env.sh: where the venv and the catkin workspace live.
#
# The workspace is OUTSIDE this source tree (default: a sibling folder "<clone>_ws"; UQ_WS overrides):
# its src/ links back to the tree, and a workspace inside the tree made rosrun's `find -L` see every
# node several times (devel relays, build and install copies) and loop through the link.
UQ_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
UQ_VENV="$UQ_ROOT/.venv"
UQ_WS="${UQ_WS:-$(dirname "$UQ_ROOT")/$(basename "$UQ_ROOT")_ws}"
export UQ_ROOT UQ_WS
