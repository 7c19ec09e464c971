"""rospy adapter of the simulator: stage_ros names, /clock, block and snapshot services.

Parameters (private):
  ~world (str, required)             Stage .world file
  ~stage43_range_compat (bool=false) Stage 4.3's 5 m default instead of the world's range_max
  ~strict (bool=false)               refuse a world with any bad model instead of dropping it (a
                                     missing floorplan bitmap is always refused)
  ~robots (int=0)                    robots the launch drives (robot_0 ..): a world holding fewer is
                                     refused at start-up; 0: no check
  ~speedup (float)                   0 = as fast as possible, 1 = real time (default: the
                                     world's ``speedup``, else 1)
  ~seed (int=0)                      localisation-noise seed
  ~robot_prefix (str="robot_%d")     namespace of robot N; "" for none
  ~single_robot_no_prefix (bool=false) like stage_ros: no namespace with one robot
  ~watchdog_timeout (float=0.2)      s without cmd_vel before a robot stops
  ~transform_tolerance (float=0.1)   s that map→odom is stamped ahead of the simulated time, as
                                     fake_localization's (and amcl's) transform_tolerance does
  ~laser_rate (float=10)             Hz
  ~raycast_resolution (float)        grid cell size for lasers/collisions (default: world resolution)
  ~map_yaml | ~map_image + ~map_resolution   the map served to the graph; used to derive
                                     T_map_world from the floorplan (default: the floorplan
                                     bitmap at its native scale, origin 0, as the tutorials serve it)
  ~map_to_world ([x, y, yaw])        overrides the derived transform
  ~localisation_error/default, ~localisation_error/robot_N:
                                     {offset: [dx, dy, dyaw], std_xy: m, std_yaw: rad}
Topics per robot (prefix robot_N/): cmd_vel (in), odom, base_pose_ground_truth,
base_scan (base_scan_K with several rangers); tf odom→base_link→base_laser_link and
map→odom; /clock, published last in each step, after the step's odometry, scans and tf, as
stageros does. Services: ~add_block, ~move_block, ~remove_block, ~snapshot.
"""
import logging
import math
import threading
import time

import rospy
from geometry_msgs.msg import TransformStamped, Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage
from sharing_msgs import publisher_links

from fleet_sim import frames
from fleet_sim.errors import InvalidRequestError, SimError, WorldError
from fleet_sim.frames import yaw_quaternion
from fleet_sim.map_io import load_map_image, load_map_yaml
from fleet_sim.sim import LocalisationError, Simulation
from fleet_sim.snapshot import save_png
from fleet_sim.srv import (AddBlock, AddBlockResponse, MoveBlock, MoveBlockResponse, RemoveBlock,
                           RemoveBlockResponse, Snapshot, SnapshotResponse)
from fleet_sim.world import load_world, require_robots


class _RosoutHandler(logging.Handler):
    """Sends the pure modules' logging to rosout."""

    def emit(self, record):
        msg = self.format(record)
        if record.levelno >= logging.ERROR:
            rospy.logerr(msg)
        elif record.levelno >= logging.WARNING:
            rospy.logwarn(msg)
        elif record.levelno >= logging.INFO:
            rospy.loginfo(msg)
        else:
            rospy.logdebug(msg)


def _number_param(name, default, minimum):
    """A numeric parameter >= minimum, or SimError naming it and its value."""
    value = rospy.get_param(name, default)
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise SimError("parameter %s must be a number, got %r" % (name, value)) from None
    if not (math.isfinite(number) and number >= minimum):
        raise SimError("parameter %s must be >= %g, got %r" % (name, minimum, value))
    return number


def _tf(stamp, parent, child, t, z=0.0):
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    msg.transform.translation.x, msg.transform.translation.y = t[0], t[1]
    msg.transform.translation.z = z
    q = yaw_quaternion(t[2])
    (msg.transform.rotation.x, msg.transform.rotation.y,
     msg.transform.rotation.z, msg.transform.rotation.w) = q
    return msg


class SimNode:
    def __init__(self):
        for name in ("fleet_sim", "sharing_msgs"):  # sharing_msgs: the publisher link watch
            logger = logging.getLogger(name)
            logger.addHandler(_RosoutHandler())
            logger.setLevel(logging.DEBUG)
        world_path = rospy.get_param("~world")
        world = load_world(world_path,
                           stage43_range_compat=bool(rospy.get_param("~stage43_range_compat", False)),
                           strict=bool(rospy.get_param("~strict", False)),
                           log=self._log)
        self.errors = len(world.problems)
        require_robots(world, int(_number_param("~robots", 0, minimum=0)))
        if not world.robots:
            rospy.logwarn("%s: the world has no position model (robot)", world_path)
        map_from_world = self._map_from_world(world)
        default_speedup = world.speedup if world.speedup is not None else 1.0
        self.speedup = _number_param("~speedup", default_speedup, minimum=0.0)
        resolution = rospy.get_param("~raycast_resolution", None)
        self.sim = Simulation(world, seed=int(_number_param("~seed", 0, minimum=0)),
                              watchdog_timeout=_number_param("~watchdog_timeout", 0.2, minimum=1e-3),
                              laser_rate=_number_param("~laser_rate", 10.0, minimum=1e-3),
                              resolution=None if resolution is None else
                              _number_param("~raycast_resolution", 0.02, minimum=1e-3),
                              map_from_world=map_from_world)
        self._apply_localisation_params()
        # move_base looks map→odom up at the newest sim time it has heard; without the lead that
        # fake_localization gives it, a lookup between two steps fails with an extrapolation error
        # and the controller loses a cycle.
        self.transform_tolerance = _number_param("~transform_tolerance", 0.1, minimum=0.0)
        self.lock = threading.Lock()
        prefix = rospy.get_param("~robot_prefix", "robot_%d")
        if rospy.get_param("~single_robot_no_prefix", False) and len(world.robots) == 1:
            prefix = ""
        self.names = [self._prefix(prefix, i) for i in range(len(world.robots))]
        self.clock_pub = rospy.Publisher("/clock", Clock, queue_size=10)
        self.tf_pub = rospy.Publisher("/tf", TFMessage, queue_size=100)
        self.odom_pubs, self.gt_pubs, self.scan_pubs = [], [], []
        for i, r in enumerate(self.sim.robots):
            ns = self.names[i]
            self.odom_pubs.append(rospy.Publisher(ns + "odom", Odometry, queue_size=10))
            self.gt_pubs.append(rospy.Publisher(ns + "base_pose_ground_truth", Odometry, queue_size=10))
            several = len(r.spec.rangers) > 1
            self.scan_pubs.append([
                rospy.Publisher(ns + ("base_scan_%d" % k if several else "base_scan"), LaserScan,
                                queue_size=10)
                for k in range(len(r.spec.rangers))])
            rospy.Subscriber(ns + "cmd_vel", Twist, self._on_cmd_vel, callback_args=i, queue_size=10)
        rospy.Service("~add_block", AddBlock, self._on_add_block)
        rospy.Service("~move_block", MoveBlock, self._on_move_block)
        rospy.Service("~remove_block", RemoveBlock, self._on_remove_block)
        rospy.Service("~snapshot", Snapshot, self._on_snapshot)
        self.bad_commands = 0
        rospy.loginfo("fleet_sim: %s, %d robots (%s), %d blocks, dt %.3f s, speedup %s, grid %dx%d @ %.3f m",
                      world.path, len(world.robots), ", ".join(r.name for r in world.robots),
                      len(self.sim.blocks), self.sim.dt, self.speedup or "max",
                      self.sim.geom.size_x, self.sim.geom.size_y, self.sim.geom.resolution)

    @staticmethod
    def _prefix(fmt, i):
        if not fmt:
            return ""
        name = fmt % i if "%" in fmt else fmt + str(i)
        return name.rstrip("/") + "/"

    @staticmethod
    def _log(level, msg):
        {"debug": rospy.logdebug, "info": rospy.loginfo, "warn": rospy.logwarn,
         "error": rospy.logerr}[level](msg)

    def _map_from_world(self, world):
        override = rospy.get_param("~map_to_world", None)
        if override is not None:
            if not (isinstance(override, (list, tuple)) and len(override) == 3):
                raise SimError("~map_to_world must be [x, y, yaw], got %r" % (override,))
            return frames.inverse(tuple(float(v) for v in override))
        if not world.floorplans:
            return (0.0, 0.0, 0.0)
        fp = world.floorplans[0]
        if rospy.has_param("~map_yaml"):
            m = load_map_yaml(rospy.get_param("~map_yaml"))
        elif rospy.has_param("~map_image"):
            m = load_map_image(rospy.get_param("~map_image"), rospy.get_param("~map_resolution"))
        else:
            return frames.inverse(frames.world_from_map(fp.pose, fp.size))
        extent = (m.width * m.resolution, m.height * m.resolution)
        if abs(extent[0] - fp.size[0]) > m.resolution or abs(extent[1] - fp.size[1]) > m.resolution:
            rospy.logwarn("map %s covers %.2f x %.2f m but floorplan %s is %.2f x %.2f m: they cannot "
                          "line up exactly", m.image_path, extent[0], extent[1], fp.name, fp.size[0], fp.size[1])
        return frames.inverse(frames.world_from_map(fp.pose, fp.size, m.origin))

    def _apply_localisation_params(self):
        table = rospy.get_param("~localisation_error", {}) or {}
        for i in range(len(self.sim.robots)):
            entry = table.get("robot_%d" % i, table.get("default"))
            if entry is None:
                continue
            try:
                off = entry.get("offset", [0.0, 0.0, 0.0])
                err = LocalisationError(float(off[0]), float(off[1]), float(off[2]),
                                        float(entry.get("std_xy", 0.0)), float(entry.get("std_yaw", 0.0)))
            except (AttributeError, TypeError, ValueError, IndexError) as e:
                raise SimError("~localisation_error/robot_%d: %s (got %r)" % (i, e, entry)) from None
            self.sim.set_localisation_error(i, err)
            rospy.loginfo("robot_%d: localisation error %s", i, err)

    # --- callbacks: message -> validated value -> logic -------------------------
    def _on_cmd_vel(self, msg, index):
        try:
            with self.lock:
                self.sim.set_cmd_vel(index, msg.linear.x, msg.linear.y, msg.angular.z)
        except InvalidRequestError as err:
            self.bad_commands += 1
            rospy.logwarn_throttle(1.0, "%scmd_vel dropped (%d so far): %s" % (self.names[index], self.bad_commands, err))

    def _service(self, response_type, action):
        try:
            with self.lock:
                message = action()
            return response_type(True, message)
        except (InvalidRequestError, SimError) as err:
            rospy.logwarn("service call refused: %s", err)
            return response_type(False, str(err))
        except Exception as err:  # noqa: BLE001 - a service must never take the simulator down
            rospy.logerr("service call failed: %r", err)
            return response_type(False, "internal error: %r" % err)

    def _on_add_block(self, req):
        def act():
            b = self.sim.add_block(req.name, req.x, req.y, req.yaw, req.size_x, req.size_y)
            return "added block '%s' at (%.2f, %.2f)" % (b.name, b.pose[0], b.pose[1])
        return self._service(AddBlockResponse, act)

    def _on_move_block(self, req):
        def act():
            b = self.sim.move_block(req.name, req.x, req.y, req.yaw)
            return "moved block '%s' to (%.2f, %.2f)" % (b.name, b.pose[0], b.pose[1])
        return self._service(MoveBlockResponse, act)

    def _on_remove_block(self, req):
        def act():
            self.sim.remove_block(req.name)
            return "removed block '%s'" % req.name
        return self._service(RemoveBlockResponse, act)

    def _on_snapshot(self, req):
        def act():
            if not req.path:
                raise InvalidRequestError("snapshot needs a file path")
            if not (req.pixels_per_metre >= 0 and math.isfinite(req.pixels_per_metre)):
                raise InvalidRequestError("pixels_per_metre must be >= 0, got %r" % req.pixels_per_metre)
            try:
                w, h = save_png(self.sim, req.path, lasers=req.draw_lasers,
                                pixels_per_metre=req.pixels_per_metre or None)
            except (OSError, ValueError) as err:
                raise InvalidRequestError("cannot write %s: %s" % (req.path, err)) from None
            return "wrote %s (%dx%d)" % (req.path, w, h)
        return self._service(SnapshotResponse, act)

    # --- main loop ----------------------------------------------------------------
    def spin(self):
        start_wall = time.monotonic()
        start_steps = self.sim.steps
        self._publish(scans=True)
        while not rospy.is_shutdown():
            with self.lock:
                self.sim.step()
                scanned = self.sim.scan_time == self.sim.time
            self._publish(scans=scanned)
            if self.speedup > 0:
                due = start_wall + (self.sim.steps - start_steps) * self.sim.dt / self.speedup
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                elif delay < -1.0:     # cannot keep up: do not try to catch up later
                    start_wall, start_steps = time.monotonic(), self.sim.steps

    def _publish(self, scans):
        with self.lock:
            stamp = rospy.Time.from_sec(self.sim.time)
            out = build_messages(self.sim, self.names, stamp, scans, self.transform_tolerance)
        for publisher, message in stage_ros_order(self, out, stamp):
            publisher.publish(message)


def stage_ros_order(pubs, out, stamp):
    """(publisher, message) of one step in stageros's order: each robot's odometry, ground truth and
    scans, then tf, and the clock last, so that a node woken by the new time finds the transforms of
    that time already there. ``pubs`` holds odom_pubs, gt_pubs, scan_pubs, tf_pub and clock_pub."""
    for i, (odom, scan_msgs) in enumerate(zip(out.odoms, out.scans)):
        yield pubs.odom_pubs[i], odom
        yield pubs.gt_pubs[i], odom   # perfect odometry: ground truth is the same pose
        for k, scan in scan_msgs:
            yield pubs.scan_pubs[i][k], scan
    yield pubs.tf_pub, out.tf
    yield pubs.clock_pub, Clock(clock=stamp)


class Messages:
    """One step's messages: odoms[i], scans[i] = [(ranger index, LaserScan)], tf."""

    def __init__(self):
        self.odoms = []
        self.scans = []
        self.tf = TFMessage()


def build_messages(sim, names, stamp, with_scans, transform_tolerance=0.0):
    """stage_ros messages for the current state (pure function of the simulation); map→odom is
    stamped transform_tolerance s after the others, as fake_localization stamps it."""
    out = Messages()
    transforms = out.tf.transforms
    map_odom_stamp = stamp + rospy.Duration.from_sec(transform_tolerance)
    for i, r in enumerate(sim.robots):
        ns = names[i]
        odom = Odometry()
        odom.header.stamp = stamp
        odom.header.frame_id = ns + "odom"
        odom.child_frame_id = ns + "base_link"
        p = odom.pose.pose
        p.position.x, p.position.y = r.pose[0], r.pose[1]
        (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w) = yaw_quaternion(r.pose[2])
        odom.twist.twist.linear.x, odom.twist.twist.linear.y = r.velocity[0], r.velocity[1]
        odom.twist.twist.angular.z = r.velocity[2]
        out.odoms.append(odom)
        transforms.append(_tf(stamp, ns + "odom", ns + "base_link", r.pose))
        several = len(r.spec.rangers) > 1
        scans = []
        for k, ranger in enumerate(r.spec.rangers):
            link = ns + ("base_laser_link_%d" % k if several else "base_laser_link")
            # As stage_ros: the laser on top of the robot model (size z) plus its own pose z.
            transforms.append(_tf(stamp, ns + "base_link", link, ranger.pose, r.spec.height + ranger.z))
            if with_scans and k < len(r.scans):
                scan = LaserScan()
                scan.header.stamp = stamp
                scan.header.frame_id = link
                scan.angle_min = ranger.angle_min
                scan.angle_max = -ranger.angle_min
                scan.angle_increment = ranger.angle_increment
                scan.time_increment = 0.0
                scan.scan_time = sim.dt * sim.laser_every
                scan.range_min = ranger.range_min
                scan.range_max = ranger.range_max
                scan.ranges = r.scans[k].tolist()
                scans.append((k, scan))
        out.scans.append(scans)
        transforms.append(_tf(map_odom_stamp, "map", ns + "odom", sim.map_to_odom(i)))
    return out


def main():
    rospy.init_node("fleet_sim")
    try:
        node = SimNode()
    except (WorldError, SimError, KeyError, ImportError) as err:
        rospy.logfatal("fleet_sim cannot start: %s", err)
        raise SystemExit(1)
    publisher_links.start_watch(rospy.get_name())
    try:
        node.spin()
    except rospy.ROSInterruptException:
        pass
