# Sourced by the Makefile and scripts: the ROS environment of this workspace.
# Debian's /usr/bin/python3 must win over any other python3 on PATH, because
# only it can import rospy.
REPO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export PATH="/usr/bin:$PATH"
if [ -f "$REPO_ROOT/catkin_ws/devel/setup.bash" ]; then
  # shellcheck disable=SC1091
  source "$REPO_ROOT/catkin_ws/devel/setup.bash"
fi
export ROS_IP=127.0.0.1
export ROS_HOSTNAME=127.0.0.1
export PYTHONDONTWRITEBYTECODE=1
# The shared data (real Stage worlds, move_base configs, bags) lives beside the repository.
if [ -z "${FLEET_SHARED_DATA:-}" ] && [ -d "$REPO_ROOT/../shared/data" ]; then
  FLEET_SHARED_DATA="$(cd "$REPO_ROOT/../shared/data" && pwd)"
  export FLEET_SHARED_DATA
fi
