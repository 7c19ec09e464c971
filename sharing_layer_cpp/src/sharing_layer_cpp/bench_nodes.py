"""The layer and the handler as the robots run them, for the benches that need them as nodes (issue 48): a private
ROS master, the a-priori map and the transforms, the global costmap of move_base_robot.launch with the sharing layer
in it (layer_host: move_base's Costmap2DROS and nothing else of move_base), the real sharing_handler node, a laser,
the CPU time of a process, and the layer's and the handler's /diagnostics.

Used by sharing_layer_cpp/scripts/bench_layer_updates and coaty_bridge/scripts/bench_flood (and only by benches:
it imports rospy, which the rest of the package does not). Needs the workspace built (`make build`: layer_host is
built with the plugin) and sourced (scripts/env.sh).
"""
import math
import os
import socket
import subprocess
import sys
import threading
import time

import rospy
import tf2_ros
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import OccupancyGrid
from sensor_msgs.msg import LaserScan
from std_msgs.msg import UInt32MultiArray

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__)))))
MOVE_BASE_CONFIG = os.path.join(ROOT, "launch", "config", "move_base")
HANDLER = os.path.join(ROOT, "sharing_handler_py", "scripts", "sharing_handler")
LAYER_HOST = os.path.join(ROOT, "catkin_ws", "devel", "lib", "sharing_layer_cpp", "layer_host")
# The global costmap's layers in move_base_robot.launch with sharing, and the layer alone (no static map layer, no
# inflation: what the sharing layer itself costs, beside the costmap's own reset of the master over the bounds).
REAL_PLUGINS = [{"name": "static_layer", "type": "costmap_2d::StaticLayer"},
                {"name": "sharing_layer", "type": "sharing_layer::SharingLayer"},
                {"name": "inflation_layer", "type": "costmap_2d::InflationLayer"}]
LAYER_ONLY = [{"name": "sharing_layer", "type": "sharing_layer::SharingLayer"}]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid):
    """CPU time of every thread of a process so far, in s (the scheduler's nanoseconds, not the 10 ms ticks of
    /proc/PID/stat); threads that ended are not counted, so measure differences while the threads live."""
    total = 0
    try:
        tasks = os.listdir("/proc/%d/task" % pid)
    except OSError:
        return float("nan")
    for task in tasks:
        try:
            with open("/proc/%d/task/%s/schedstat" % (pid, task)) as f:
                total += int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            pass
    return total * 1e-9


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def load_text():
    return " ".join("%.2f" % x for x in os.getloadavg())


class Graph:
    """A private rosmaster on a free port and the nodes started on it; stop() ends them all."""

    def __init__(self, log_dir):
        self.port = free_port()
        self.env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % self.port, ROS_IP="127.0.0.1",
                        ROS_HOSTNAME="127.0.0.1", ROS_LOG_DIR=log_dir, PYTHONUNBUFFERED="1")
        os.environ.update(ROS_MASTER_URI=self.env["ROS_MASTER_URI"], ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1",
                          ROS_LOG_DIR=log_dir)
        self.log_dir = log_dir
        self.procs = []
        self.master = self.start("rosmaster", ["rosmaster", "--core", "-p", str(self.port)])
        deadline = time.time() + 20
        while time.time() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    break
            time.sleep(0.1)
        else:
            raise RuntimeError("rosmaster did not start on port %d" % self.port)

    def start(self, name, cmd, stdout=None):
        log = open(os.path.join(self.log_dir, name + ".log"), "w")
        proc = subprocess.Popen(cmd, env=self.env, stdout=stdout or log, stderr=log if stdout else subprocess.STDOUT,
                                text=True, start_new_session=True)
        self.procs.append(proc)
        return proc

    def stop(self):
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(2)
        for proc in reversed(self.procs):
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
                proc.wait()


def set_params(namespace, values):
    for key, value in values.items():
        rospy.set_param(namespace.rstrip("/") + "/" + key, value)


def load_yaml(name):
    with open(os.path.join(MOVE_BASE_CONFIG, name)) as f:
        return yaml.safe_load(f)


def global_costmap_params(robot, plugins, layer_params=None):
    """The parameters move_base_robot.launch gives the global costmap of `robot`: costmap_common_params.yaml in
    global_costmap and in the marking layer's namespace, global_costmap_params.yaml, robot_base_frame <robot>/base_link,
    and the plugins; layer_params go to the sharing layer's namespace on top."""
    common = load_yaml("costmap_common_params.yaml")
    params = dict(common)
    params.update(load_yaml("global_costmap_params.yaml")["global_costmap"])
    params["robot_base_frame"] = robot + "/base_link"
    params["plugins"] = plugins
    layer = dict(common)
    layer.update(layer_params or {})
    params["sharing_layer"] = layer
    return params


def occupancy_grid(resolution, size_x, size_y):
    """An a-priori map with every cell free, as map_server publishes it."""
    grid = OccupancyGrid()
    grid.header.frame_id = "map"
    grid.header.stamp = rospy.Time.now()
    grid.info.resolution = resolution
    grid.info.width, grid.info.height = size_x, size_y
    grid.info.origin.orientation.w = 1.0
    grid.data = bytes(size_x * size_y)
    return grid


def robot_transforms(robot, x, y):
    """A robot's frames at (x, y), as static transforms: map -> <robot>/odom (fake_localization's) -> <robot>/base_link
    (the odometry's) -> <robot>/base_laser_link 0.1 m up. The layer compares odometry with localisation every cycle."""
    stamp = rospy.Time.now()

    def frame(parent, child, tx, ty, tz):
        t = TransformStamped()
        t.header.stamp = stamp
        t.header.frame_id, t.child_frame_id = parent, child
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = tx, ty, tz
        t.transform.rotation.w = 1.0
        return t

    return [frame("map", robot + "/odom", 0.0, 0.0, 0.0), frame(robot + "/odom", robot + "/base_link", x, y, 0.0),
            frame(robot + "/base_link", robot + "/base_laser_link", 0.0, 0.0, 0.1)]


class World:
    """What the robots find on the master before their nodes start: the a-priori map on /map (latched, every cell
    free, as map_server publishes it) and each robot's static transforms (robot -> (x, y))."""

    def __init__(self, resolution, size_x, size_y, poses):
        self.tf = tf2_ros.StaticTransformBroadcaster()
        transforms = []
        for robot, (x, y) in poses.items():
            transforms += robot_transforms(robot, x, y)
        self.tf.sendTransform(transforms)
        self.map_pub = rospy.Publisher("/map", OccupancyGrid, queue_size=1, latch=True)
        self.map_pub.publish(occupancy_grid(resolution, size_x, size_y))


class Laser:
    """The navigation tutorials' laser (1081 beams over 270 degrees, 30 m) on <robot>/base_scan at `rate` Hz, seeing
    a ring of wall `radius` m around the robot (beyond obstacle_range: it clears to raytrace_range every scan)."""

    def __init__(self, robot, rate=10.0, radius=8.0):
        self.pub = rospy.Publisher("/%s/base_scan" % robot, LaserScan, queue_size=2)
        self.msg = LaserScan()
        self.msg.header.frame_id = robot + "/base_laser_link"
        self.msg.angle_min, self.msg.angle_max = -0.75 * math.pi, 0.75 * math.pi
        self.msg.angle_increment = (self.msg.angle_max - self.msg.angle_min) / 1080
        self.msg.range_min, self.msg.range_max = 0.1, 30.0
        self.msg.ranges = [radius] * 1081
        self.rate = rate
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.wait(1.0 / self.rate) and not rospy.is_shutdown():
            self.msg.header.stamp = rospy.Time.now()
            self.pub.publish(self.msg)

    def stop(self):
        self._stop.set()


class Diagnostics:
    """The newest value of each /diagnostics status, by name."""

    def __init__(self):
        self._lock = threading.Lock()
        self.values = {}
        rospy.Subscriber("/diagnostics", DiagnosticArray, self._on)

    def _on(self, msg):
        with self._lock:
            for status in msg.status:
                self.values[status.name] = {kv.key: kv.value for kv in status.values}

    def get(self, name, key, default=None):
        with self._lock:
            return self.values.get(name, {}).get(key, default)

    def count(self, name, key):
        value = self.get(name, key)
        return int(value) if value is not None and value.isdigit() else -1

    def wait_count(self, name, key, predicate, timeout):
        deadline = time.time() + timeout
        while time.time() < deadline:
            if predicate(self.count(name, key)):
                return True
            time.sleep(0.1)
        return False


def layer_status(robot):
    return "sharing_layer: %s (global_costmap/sharing_layer)" % robot


def handler_status(robot):
    return "sharing_handler (%s)" % robot


class LayerHost:
    """layer_host for `robot`, its probe's output read in a thread: cell -> wall time it first read lethal."""

    def __init__(self, graph, robot):
        if not os.path.exists(LAYER_HOST):
            raise RuntimeError("%s is not built (make build builds it where costmap_2d is installed)" % LAYER_HOST)
        self.robot = robot
        self.proc = graph.start(robot + "_layer_host", [LAYER_HOST, "__ns:=" + robot, "__name:=move_base",
                                                        "map:=/map"], stdout=subprocess.PIPE)
        self.lethal = {}
        self.ready = threading.Event()
        self._watch = rospy.Publisher("/%s/move_base/watch" % robot, UInt32MultiArray, queue_size=100)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            parts = line.split()
            if parts == ["ready"]:
                self.ready.set()
            elif len(parts) == 3 and parts[0] == "lethal":
                self.lethal.setdefault(int(parts[1]), float(parts[2]))

    def watch(self, cells):
        self._watch.publish(UInt32MultiArray(data=list(cells)))

    @property
    def pid(self):
        return self.proc.pid


def start_handler(graph, robot, params=None):
    args = ["_%s:=%s" % (k, v) for k, v in (params or {}).items()]
    return graph.start(robot + "_handler", [sys.executable, HANDLER, "__ns:=" + robot, "__name:=sharing_handler"] +
                       args)
