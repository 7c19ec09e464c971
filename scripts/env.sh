# Sourced by the Makefile and scripts: the ROS environment of this workspace.
# Debian's /usr/bin/python3 must win over any other python3 on PATH, because
# only it can import rospy.
REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export PATH="/usr/bin:$PATH"
# ROS Noetic from its own packages (Ubuntu 20.04), where it is installed and not yet sourced.
if [ -z "${ROS_DISTRO:-}" ] && [ -f /opt/ros/noetic/setup.bash ]; then
  # shellcheck disable=SC1091
  source /opt/ros/noetic/setup.bash
fi
# The upstream navigation stack and Stage that `make setup` built where the distribution lacks them
# (upstream/README.md); only a complete build is ever sourced. This workspace, once built, carries the chain
# of workspaces it was built on (that upstream build): sourcing it alone gives exactly that chain, where
# sourcing both with --extend would put a stale chain first after a new upstream build.
export FLEET_UPSTREAM_CACHE="${FLEET_UPSTREAM_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/fleet_upstream}"
_fleet_upstream="$FLEET_UPSTREAM_CACHE/current"
if [ -f "$REPO_ROOT/catkin_ws/devel/setup.bash" ] && [ -z "${FLEET_ENV_UPSTREAM_ONLY:-}" ]; then
  # shellcheck disable=SC1091
  source "$REPO_ROOT/catkin_ws/devel/setup.bash"
  if [ -f "$_fleet_upstream/COMPLETE" ] && \
     ! tr ':' '\n' <<<"${CMAKE_PREFIX_PATH:-}" | grep -q "^$(cd "$_fleet_upstream" && pwd -P)/"; then
    echo "env.sh: catkin_ws was built on another upstream build than $(cd "$_fleet_upstream" && pwd -P); run 'make build'" >&2
  fi
elif [ -f "$_fleet_upstream/COMPLETE" ] && [ -f "$_fleet_upstream/devel_isolated/setup.bash" ]; then
  # shellcheck disable=SC1091
  source "$_fleet_upstream/devel_isolated/setup.bash" --extend
fi
unset _fleet_upstream
# One host by default: every node, master and broker on loopback. On a fleet of several hosts set
# ROS_IP (or ROS_HOSTNAME) and ROS_MASTER_URI to this host's address before sourcing this file.
export ROS_IP="${ROS_IP:-127.0.0.1}"
export ROS_HOSTNAME="${ROS_HOSTNAME:-$ROS_IP}"
export PYTHONDONTWRITEBYTECODE=1
# The reference data (real Stage worlds, move_base configs, bags) is in the repository's data/
# (data/README.md); a FLEET_SHARED_DATA set before sourcing this file points elsewhere instead.
export FLEET_SHARED_DATA="${FLEET_SHARED_DATA:-$REPO_ROOT/data}"
