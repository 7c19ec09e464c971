#!/usr/bin/env bash
# Installs everything the project needs on Debian 12, as root, without asking.
# Idempotent: when every package is already there it only checks and returns.
set -euo pipefail

PACKAGES=(
  # ROS 1 core from Debian's archive (ros_comm 1.15, Noetic level)
  ros-core-dev ros-base-dev catkin python3-catkin-pkg rosbash
  python3-rospy libroscpp-dev python3-rostest librostest-dev python3-rosbag
  pluginlib-dev libtf2-ros-dev python3-tf2-ros liblaser-geometry-dev libdiagnostic-updater-dev
  libnav-msgs-dev libmap-msgs-dev libmove-base-msgs-dev python3-actionlib
  # C++ core, bindings and tests
  build-essential cmake pybind11-dev libgtest-dev googletest
  # Python dependencies, all from Debian
  python3-numpy python3-scipy python3-pytest python3-hypothesis python3-yaml
  python3-pil python3-paho-mqtt python3-jsonschema
  # message packages the nodes use directly
  python3-diagnostic-msgs python3-visualization-msgs python3-std-srvs
  python3-move-base-msgs python3-nav-msgs python3-sensor-msgs python3-geometry-msgs
  python3-tf2-msgs python3-map-msgs libdiagnostic-msgs-dev libvisualization-msgs-dev
  # the MQTT broker, and Node.js/npm for the Coaty JS interop test
  mosquitto nodejs npm
  # openssl CLI: the TLS tests make a CA and per-robot certificates (coaty_bridge.pki)
  openssl
  # RViz (fleet.launch rviz:=true) and, headless, its config test and make demo's screenshot:
  # a virtual X server, Mesa's software OpenGL, a font for Qt, and imagemagick's `import`
  rviz xvfb libgl1-mesa-dri fonts-dejavu-core imagemagick
  # the fleet console: its server (WebSocket to the broker) and its test and demo screenshot in headless Chromium
  python3-websockets chromium chromium-driver python3-selenium
)

cd "$(dirname "$0")/.."
# What upstream/build_upstream.py needs to build move_base and Stage (nothing where the distribution
# has them or a complete build is cached).
mapfile -t UPSTREAM_PACKAGES < <(/usr/bin/python3 upstream/build_upstream.py --debian-packages)
ALL_PACKAGES=("${PACKAGES[@]}")
for pkg in "${UPSTREAM_PACKAGES[@]}"; do
  [ -n "$pkg" ] && ALL_PACKAGES+=("$pkg")
done

missing=()
for pkg in "${ALL_PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

# Node.js may come from elsewhere on the machine (e.g. a preinstalled node);
# only ask apt for it when there is no node/npm at all.
if command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1; then
  filtered=()
  for pkg in "${missing[@]+"${missing[@]}"}"; do
    [[ "$pkg" == nodejs || "$pkg" == npm ]] || filtered+=("$pkg")
  done
  missing=("${filtered[@]+"${filtered[@]}"}")
fi

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#ALL_PACKAGES[@]} Debian packages present"
elif [ "$(id -u)" -ne 0 ]; then
  echo "setup: missing packages: ${missing[*]}" >&2
  echo "setup: run 'make setup' as root (it uses apt-get) or install them yourself" >&2
  exit 1
else
  echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# The interop tests' outside implementations, pinned, from the npm registry, each into its own cache outside
# the repository (the tests read the same places): the Coaty JS library and vda-5050-lib (an independent
# VDA 5050 master control). Without npm or the registry this warns and goes on; those tests then skip, saying why.
npm_package() {  # cache folder, package name, version, extra npm flags...
  local cache="$1" name="$2" version="$3"
  shift 3
  if [ -f "$cache/node_modules/$name/package.json" ] && \
      grep -q "\"version\": *\"$version\"" "$cache/node_modules/$name/package.json"; then
    echo "setup: npm $name@$version present in $cache"
  elif ! command -v npm >/dev/null 2>&1; then
    echo "setup: WARNING: npm missing, $name@$version not installed (its interop test will skip)" >&2
  else
    mkdir -p "$cache"
    if npm install --prefix "$cache" --no-audit --no-fund "$@" "$name@$version" >"$cache/npm-install.log" 2>&1; then
      echo "setup: npm $name@$version installed into $cache"
    else
      echo "setup: WARNING: npm install $name@$version failed (its interop test will skip or fail, saying" \
        "why): $(tail -n 3 "$cache/npm-install.log")" >&2
    fi
  fi
}
npm_package "${FLEET_COATY_CACHE:-$HOME/.cache/fleet-coaty-interop}" @coaty/core 2.4.1 --legacy-peer-deps "rxjs@^6.6.7"
npm_package "${FLEET_VDA_CACHE:-$HOME/.cache/fleet-vda5050-interop}" vda-5050-lib 1.4.0

# Upstream move_base, costmap_2d, map_server, fake_localization and Stage: from the distribution, the
# cache, or built now from the pinned sources (upstream/README.md).
/usr/bin/python3 upstream/build_upstream.py
# The fleet console's browser scripts (mqtt.js, pinned in fleet_console/package-lock.json) from the npm registry,
# served by the console itself: the page fetches nothing from the internet at run time.
if [ ! -f fleet_console/node_modules/mqtt/dist/mqtt.min.js ]; then
  echo "setup: installing the fleet console's browser scripts (npm ci in fleet_console)"
  (cd fleet_console && npm ci --no-audit --no-fund --ignore-scripts)
fi
echo "setup: done"
