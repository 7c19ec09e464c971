#!/usr/bin/env bash
# make build: this repository's catkin workspace, on top of the upstream navigation stack and Stage
# (the distribution's, or the one make setup built). catkin records the underlay when it configures
# the workspace, so when the underlay changes (a first upstream build, new pins) the workspace is
# configured anew; otherwise sharing_layer_cpp would stay built without its costmap_2d plugin.
set -eo pipefail
cd "$(dirname "$0")/.."
# The underlay alone (upstream and the distribution), not a workspace chain the calling shell sourced before:
# catkin records what it finds at configure time, and a stale chain would come first.
unset CMAKE_PREFIX_PATH ROS_PACKAGE_PATH PYTHONPATH LD_LIBRARY_PATH PKG_CONFIG_PATH ROSLISP_PACKAGE_DIRECTORIES
export FLEET_ENV_UPSTREAM_ONLY=1
# shellcheck disable=SC1091
source scripts/env.sh
unset FLEET_ENV_UPSTREAM_ONLY
JOBS="${JOBS:-2}"
WS=catkin_ws
underlay="$(tr ":" "\n" <<<"${CMAKE_PREFIX_PATH:-}" | grep -v "^$" | sort -u | paste -sd: -)"
stamp="$WS/build/fleet_underlay"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" != "$underlay" ]; then
  echo "build: the underlay changed (was: $(cat "$stamp"); now: ${underlay:-none}); configuring $WS anew"
  rm -rf "$WS/build" "$WS/devel"
fi
if [ -n "${FLEET_UPSTREAM_CACHE:-}" ] && [ -f "$FLEET_UPSTREAM_CACHE/current/COMPLETE" ]; then
  echo "build: on the upstream stack in $(cd "$FLEET_UPSTREAM_CACHE/current" && pwd -P)"
fi
catkin_make -C "$WS" -j"$JOBS" -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release \
  -DCATKIN_ENABLE_TESTING=ON
catkin_make -C "$WS" -j"$JOBS" tests
mkdir -p "$WS/build"
printf '%s' "$underlay" > "$stamp"
# The plugin must be there wherever costmap_2d is: a build without it would test the stand-ins only.
if rospack find costmap_2d >/dev/null 2>&1 && [ ! -e "$WS/devel/lib/libsharing_layer_plugin.so" ]; then
  echo "build: costmap_2d is installed but sharing_layer_cpp's plugin was not built (see the cmake output above)" >&2
  exit 1
fi
