"""RViz without a screen: runs rviz (Debian's rviz 1.14) on a config under a virtual X server, reports
what is wrong with the config, and takes screenshots (the RViz test, make demo's report).

    with RvizSession(config, workdir) as rviz:     # Xvfb on a display it picks itself, then rviz
        rviz.wait_ready(60)                         # rviz's services are up (config loaded)
        rviz.screenshot("rviz.png")                 # `import -window root` (imagemagick)
        problems = rviz.config_problems()           # [] when the config loaded cleanly

Needs a ROS master (ROS_MASTER_URI of the environment): rviz is a ROS node. What counts as a
config problem (``config_problems``):
  - an ERROR or WARN line in rviz's output (a display or tool class that does not exist, a plugin
    that fails to load, ...), except the lines listed in BENIGN;
  - a display whose class is not a known display class, or whose name appears twice;
  - a property that rviz does not keep: after loading, rviz saves its configuration (its
    ``save_config`` service) and every key and value of the config must come back unchanged.
    rviz silently ignores a misspelt property name or a value it cannot parse (it keeps the
    default), so this is the only way to see those.
"""
import math
import os
import shutil
import signal
import struct
import subprocess
import time

import genpy
import rosgraph
import rospy
import yaml

from fleet_tests.processes import stop as stop_process

# rviz's output lines that are not about the config: Debian's rviz asks rospack for the
# media_export package (Ogre media of ROS's own packaging), which Debian does not have; rviz then
# uses its own media folder (the shapes and textures of the displays still load). When the first
# map arrives, Mesa's GLSL linker complains about the Map display's palette shader under Ogre 1.12
# ("active samplers with a different type refer to the same texture image unit", known upstream:
# OGRECave/ogre#1252, ros2/rviz#1279); the map is drawn all the same (see make demo's screenshot).
BENIGN = ("XDG_RUNTIME_DIR not set", "[rospack] Error: no such package media_export",
          "[librospack]: error while executing command", "rviz/glsl120/indexed_8bit_image.vert")
# rviz 1.14's default display plugins (plugin_description.xml of rviz); others need their package.
KNOWN_DISPLAYS = {
    "rviz/" + n for n in (
        "AccelStamped", "Axes", "Camera", "DepthCloud", "Effort", "FluidPressure", "Grid", "GridCells",
        "Group", "Illuminance", "Image", "InteractiveMarkers", "LaserScan", "Map", "Marker", "MarkerArray",
        "Odometry", "Path", "PointCloud", "PointCloud2", "PointStamped", "Polygon", "Pose", "PoseArray",
        "PoseWithCovariance", "Range", "RelativeHumidity", "RobotModel", "TF", "Temperature",
        "TwistStamped", "WrenchStamped")}


class RvizError(Exception):
    """RViz or the X server could not be started, or did not answer."""


class _PathRequest(genpy.Message):
    """rviz/SendFilePath request (std_msgs/String path); Debian ships no rviz srv for Python.
    md5sum "*" is roscpp's wildcard: the server accepts it."""
    _md5sum = "*"
    _type = "rviz/SendFilePathRequest"
    _has_header = False
    _full_text = "std_msgs/String path\n"
    __slots__ = ["path"]
    _slot_types = ["std_msgs/String"]

    def __init__(self, path=""):
        self.path = path

    def serialize(self, buff):
        data = self.path.encode("utf-8")
        buff.write(struct.pack("<I", len(data)) + data)

    def deserialize(self, data):
        (n,) = struct.unpack("<I", data[:4])
        self.path = data[4:4 + n].decode("utf-8")
        return self


class _PathResponse(genpy.Message):
    _md5sum = "*"
    _type = "rviz/SendFilePathResponse"
    _has_header = False
    _full_text = "bool success\n"
    __slots__ = ["success"]
    _slot_types = ["bool"]

    def __init__(self, success=False):
        self.success = success

    def serialize(self, buff):
        buff.write(struct.pack("<B", 1 if self.success else 0))

    def deserialize(self, data):
        self.success = bool(data[0]) if data else False
        return self


class _SendFilePath:
    _type = "rviz/SendFilePath"
    _md5sum = "*"
    _request_class = _PathRequest
    _response_class = _PathResponse


def tools_missing():
    """Names of the programs this module needs that are not installed (make setup installs them)."""
    return [p for p in ("Xvfb", "rviz", "import") if shutil.which(p) is None]


class RvizSession:
    def __init__(self, config, workdir, width=None, height=None, node_name="rviz"):
        self.config = os.path.abspath(config)
        self.workdir = workdir
        self.node_name = node_name
        try:
            with open(self.config) as f:
                self.doc = yaml.safe_load(f)
        except (OSError, yaml.YAMLError) as err:
            raise RvizError("cannot read the RViz config %s: %s" % (config, err)) from None
        if not isinstance(self.doc, dict):
            raise RvizError("%s is not an RViz config (a YAML mapping)" % config)
        geometry = self.doc.get("Window Geometry") or {}
        # the screen is the window's size, so that a screenshot of the screen is the window
        self.width = int(width or geometry.get("Width", 1200))
        self.height = int(height or geometry.get("Height", 800))
        self.display = None
        self.xvfb = self.rviz = None
        self.log_path = os.path.join(workdir, "rviz.log")

    # --- processes ----------------------------------------------------------------------------------
    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()
        return False

    def start(self, timeout=30.0):
        missing = tools_missing()
        if missing:
            raise RvizError("not installed: %s (make setup installs rviz, xvfb and imagemagick)" % ", ".join(missing))
        os.makedirs(self.workdir, exist_ok=True)
        # -displayfd: Xvfb picks a free display itself and writes its number, no race with others
        read_fd, write_fd = os.pipe()
        self.xvfb = subprocess.Popen(
            ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "%dx%dx24" % (self.width, self.height),
             "-nolisten", "tcp", "-noreset"], pass_fds=(write_fd,), stdout=subprocess.DEVNULL,
            stderr=open(os.path.join(self.workdir, "xvfb.log"), "w"), start_new_session=True)
        os.close(write_fd)
        number = b""
        end = time.time() + timeout
        with os.fdopen(read_fd, "rb", buffering=0) as pipe:
            while time.time() < end and not number.endswith(b"\n"):
                chunk = pipe.read(16)
                if not chunk:
                    break
                number += chunk
        if not number.strip().isdigit():
            self.stop()
            raise RvizError("Xvfb did not start (see %s)" % os.path.join(self.workdir, "xvfb.log"))
        self.display = ":" + number.strip().decode()
        runtime = os.path.join(self.workdir, "xdg")
        os.makedirs(runtime, mode=0o700, exist_ok=True)
        env = dict(os.environ, DISPLAY=self.display, XDG_RUNTIME_DIR=runtime)
        self.rviz = subprocess.Popen(["rviz", "-d", self.config, "__name:=" + self.node_name],
                                     stdout=open(self.log_path, "w"), stderr=subprocess.STDOUT, env=env,
                                     start_new_session=True)

    def stop(self):
        stop_process(self.rviz, signal.SIGINT)
        stop_process(self.xvfb, signal.SIGTERM)
        self.rviz = self.xvfb = None

    def wait_ready(self, timeout=60.0, settle=3.0):
        """Until rviz's save_config service is up (it comes after the config is loaded), then settle
        seconds for the first frames to be drawn."""
        service = "/%s/save_config" % self.node_name
        master = rosgraph.Master("/fleet_rviz_check")
        end = time.time() + timeout
        while time.time() < end:
            if self.rviz.poll() is not None:
                raise RvizError("rviz exited with %s before it was ready:\n%s" % (self.rviz.returncode, self.output()))
            try:
                master.lookupService(service)
                time.sleep(settle)
                return
            except Exception:  # not registered yet, or the master is still starting
                time.sleep(0.5)
        raise RvizError("rviz did not offer %s within %.0f s:\n%s" % (service, timeout, self.output()))

    def output(self):
        try:
            with open(self.log_path, errors="replace") as f:
                return f.read()
        except OSError:
            return ""

    def screenshot(self, path):
        """The whole virtual screen (= the RViz window) as PNG."""
        proc = subprocess.run(["import", "-display", self.display, "-window", "root", "png:" + path],
                              capture_output=True, text=True, timeout=60)
        if proc.returncode != 0 or not os.path.exists(path):
            raise RvizError("screenshot failed: %s" % proc.stderr.strip())
        return path

    def save_config(self, path, timeout=20.0):
        """The configuration rviz holds now, saved by rviz itself; the parsed YAML."""
        service = "/%s/save_config" % self.node_name
        rospy.wait_for_service(service, timeout)
        if not rospy.ServiceProxy(service, _SendFilePath)(os.path.abspath(path)).success:
            raise RvizError("rviz refused to save its config to %s" % path)
        with open(path) as f:
            return yaml.safe_load(f)

    # --- the check ------------------------------------------------------------------------------------
    def config_problems(self):
        """What is wrong with the config, one line each ([] = it loaded cleanly)."""
        problems = log_problems(self.output())
        problems += display_problems(self.doc)
        saved = self.save_config(os.path.join(self.workdir, "saved.rviz"))
        problems += ["%s: %s" % (where, what) for where, what in lost_properties(self.doc, saved)]
        return problems


def log_problems(text):
    out = []
    for line in text.splitlines():
        plain = line.replace("\x1b[0m", "").replace("\x1b[31m", "").replace("\x1b[33m", "").strip()
        if not plain or any(b in plain for b in BENIGN):
            continue
        if "ERROR" in plain or "WARN" in plain or "rror:" in plain:
            out.append("rviz says: " + plain)
    return out


def display_problems(doc):
    out = []
    manager = doc.get("Visualization Manager") or {}
    names = []
    for d in _displays(manager.get("Displays") or []):
        names.append(d.get("Name"))
        if d.get("Class") not in KNOWN_DISPLAYS:
            out.append("display %r: unknown display class %r" % (d.get("Name"), d.get("Class")))
    for name in sorted({n for n in names if names.count(n) > 1}, key=str):
        out.append("display name %r is used %d times (RViz tells displays apart by name)" % (name, names.count(name)))
    return out


def _displays(items):
    for d in items:
        if isinstance(d, dict):
            yield d
            if d.get("Class") == "rviz/Group":
                yield from _displays(d.get("Displays") or [])


def _same(a, b):
    if isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-6)
    return str(a).strip() == str(b).strip()


def lost_properties(mine, saved, where="config"):
    """(where, what) for every key of mine that saved lacks or holds with another value. Displays and
    tools are matched by Name/Class, not by position."""
    out = []
    if isinstance(mine, dict):
        if not isinstance(saved, dict):
            return [(where, "is %r in the saved config" % (saved,))]
        for key, value in mine.items():
            if key not in saved:
                out.append((where, "property %r is not kept by rviz (misspelt, or not a property of this "
                                   "display)" % key))
                continue
            out += lost_properties(value, saved[key], "%s/%s" % (where, key))
    elif isinstance(mine, list):
        if not isinstance(saved, list):
            return [(where, "is %r in the saved config" % (saved,))]
        for i, item in enumerate(mine):
            label = item.get("Name") or item.get("Class") if isinstance(item, dict) else None
            match = None
            if isinstance(item, dict):
                candidates = [s for s in saved if isinstance(s, dict) and s.get("Class") == item.get("Class")
                              and (item.get("Name") is None or s.get("Name") == item.get("Name"))
                              and (item.get("Topic") is None or s.get("Topic") == item.get("Topic"))]
                match = candidates[0] if candidates else None
            elif i < len(saved):
                match = saved[i]
            if match is None:
                out.append((where, "entry %s is missing from the saved config" % (label or i)))
            else:
                out += lost_properties(item, match, "%s/%s" % (where, label or i))
    elif not _same(mine, saved):
        out.append((where, "%r became %r (rviz did not accept the value)" % (mine, saved)))
    return out
