"""rospy adapter of fleet_nav (``rosrun fleet_nav fleet_nav`` in a robot namespace).

Reads move_base/costmap_2d parameters (see params.py), waits for /map, then runs the global
costmap (static + sharing layer + inflation) and move_base's state machine (navigator.py) at
controller_frequency. Interfaces (relative to the robot namespace): base_scan in, cmd_vel out,
move_base action + move_base_simple/goal, ~recovery_status out (move_base's RecoveryStatus, one per
recovery behaviour), stuck_feedback out only with stuck_feedback_on_local_failure (the thesis's
modified move_base), stuck_feedback and move_base/recovery_status in (the sharing layer's
triggers, as in the costmap_2d plugin), global_costmap/costmap, plan (and
move_base/NavfnROS/plan), shared_obstacle_markers, obstacle_proposals / obstacle_updates out,
shared_obstacles / expired_obstacles in, ~global_costmap/footprint out (move_base's footprint at the
robot's pose, which the Coaty bridge advertises) and fleet_robots in (the fleet robots the bridge heard:
their cells are never shared). Service ~snapshot (fleet_sim/Snapshot) writes a PNG of
this robot's view.
"""
import logging
import math
import threading
import time

import actionlib
import numpy as np
import rospy
import tf2_ros
from geometry_msgs.msg import Point32, PolygonStamped, PoseStamped, Twist
from move_base_msgs.msg import MoveBaseAction, MoveBaseFeedback, MoveBaseResult, RecoveryStatus
from nav_msgs.msg import OccupancyGrid, Path
from sharing_msgs.msg import RobotFootprintArray, SharedObstacle
from sharing_msgs import publisher_links
from std_msgs.msg import Empty, String
from visualization_msgs.msg import Marker, MarkerArray

from sharing_layer_cpp import core
from fleet_sim.frames import yaw_quaternion
from fleet_nav.costmap import GlobalCostmap
from fleet_nav.errors import GoalRejected, ParameterError
from fleet_nav.navigator import Event, Navigator
from fleet_nav.params import NavParams
from fleet_nav import snapshot

# costmap_2d's cost → OccupancyGrid translation (Costmap2DPublisher).
_COST_TO_OCC = np.array([0] + [1 + (97 * (i - 1)) // 251 for i in range(1, 253)] + [99, 100, -1], dtype=np.int8)


class _RosoutHandler(logging.Handler):
    def __init__(self, robot):
        super().__init__()
        self.robot = robot

    def emit(self, record):
        msg = "fleet_nav (%s): %s" % (self.robot, self.format(record))
        level = record.levelno
        (rospy.logerr if level >= logging.ERROR else rospy.logwarn if level >= logging.WARNING
         else rospy.loginfo if level >= logging.INFO else rospy.logdebug)(msg)


def _yaw(q):
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _to_message(update, frame):
    msg = SharedObstacle()
    msg.header.stamp = rospy.Time.from_sec(update.stamp)
    msg.header.frame_id = frame
    msg.uuid = update.uuid
    msg.marked_indexes = update.marked.tolist()
    msg.cleared_indexes = update.cleared.tolist()
    msg.deadline = update.deadline
    msg.rectangle_shape = list(update.rectangle)
    msg.source = update.source
    g = update.geometry
    msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y = (g.resolution, g.origin_x, g.origin_y,
                                                                          g.size_x, g.size_y)
    msg.version = update.version
    return msg


def _from_message(msg):
    geometry = core.GridGeometry(msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y)
    return core.ObstacleUpdate(msg.uuid, np.asarray(msg.marked_indexes, dtype=np.uint32),
                               np.asarray(msg.cleared_indexes, dtype=np.uint32), msg.deadline,
                               list(msg.rectangle_shape), msg.source, geometry, msg.version,
                               msg.header.stamp.to_sec())


class NavNode:
    def __init__(self):
        self.robot = rospy.get_namespace().strip("/") or "robot"
        handler = _RosoutHandler(self.robot)
        for name in ("fleet_nav", "sharing_msgs"):  # sharing_msgs: the publisher link watch
            logging.getLogger(name).addHandler(handler)
            logging.getLogger(name).setLevel(logging.INFO)
        self.params, unused = NavParams.from_dict(rospy.get_param("~", {}), self.robot)
        p = self.params
        if unused:
            rospy.loginfo("fleet_nav (%s): parameters not used by fleet_nav (move_base/costmap_2d features it "
                          "does not have): %s", self.robot, ", ".join(unused))
        self.layer_params = core.LayerParams(
            obstacle_range=p.obstacle_range, raytrace_range=p.raytrace_range,
            min_obstacle_height=p.min_obstacle_height, max_obstacle_height=p.max_obstacle_height,
            # the plan-blocked trigger looks within the robot's inscribed radius of the plan, as the
            # costmap_2d plugin does with its layered costmap's
            inscribed_radius=p.inscribed_radius, robot_name=self.robot, **p.sharing)
        rospy.loginfo("fleet_nav (%s): frames %s -> %s, obstacle_range %.2f, raytrace_range %.2f, inscribed %.3f m, "
                      "inflation %.2f m x %.1f, update %.1f Hz, planner %.2f Hz, controller %.1f Hz, sharing %s",
                      self.robot, p.global_frame, p.robot_base_frame, p.obstacle_range, p.raytrace_range,
                      p.inscribed_radius, p.inflation_radius, p.cost_scaling_factor, p.update_frequency,
                      p.planner_frequency, p.controller_frequency, "on" if p.sharing_enabled else "off")
        self.lock = threading.RLock()
        self.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(30.0))
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self.map_msg = None
        self.costmap = None
        self.navigator = None
        self.stuck_pending = None
        self.pose = None
        self.dropped = 0
        self.fleet_robots_dropped = 0
        self.fleet_robot_names = ()

        self.cmd_pub = rospy.Publisher("cmd_vel", Twist, queue_size=1)
        self.stuck_pub = rospy.Publisher("stuck_feedback", Empty, queue_size=10)
        # move_base announces each recovery behaviour on ~recovery_status (its private namespace).
        self.recovery_pub = rospy.Publisher("~recovery_status", RecoveryStatus, queue_size=10)
        self.costmap_pub = rospy.Publisher("global_costmap/costmap", OccupancyGrid, queue_size=1, latch=True)
        self.plan_pub = rospy.Publisher("plan", Path, queue_size=1, latch=True)
        self.navfn_plan_pub = rospy.Publisher("move_base/NavfnROS/plan", Path, queue_size=1, latch=True)
        self.marker_pub = rospy.Publisher("shared_obstacle_markers", MarkerArray, queue_size=1, latch=True)
        self.proposal_pub = rospy.Publisher("obstacle_proposals", SharedObstacle, queue_size=10)
        self.update_pub = rospy.Publisher("obstacle_updates", SharedObstacle, queue_size=100)
        # move_base's global costmap publishes the footprint at the robot's pose here (costmap_2d's
        # Costmap2DROS); the Coaty bridge advertises it so that no peer shares this robot
        self.footprint_pub = rospy.Publisher("~global_costmap/footprint", PolygonStamped, queue_size=1)
        rospy.Subscriber("/map", OccupancyGrid, self._on_map, queue_size=1)

    # --- start-up -----------------------------------------------------------------------------
    def wait_for_map(self):
        while self.map_msg is None and not rospy.is_shutdown():
            rospy.loginfo("fleet_nav (%s): waiting for /map (latched nav_msgs/OccupancyGrid, e.g. from "
                          "'rosrun fleet_sim map_server <map.yaml>'); not planning until it arrives", self.robot)
            deadline = rospy.get_time() + self.params.map_wait_log_period
            while self.map_msg is None and not rospy.is_shutdown() and rospy.get_time() < deadline:
                rospy.sleep(0.1)
        if rospy.is_shutdown():
            return False
        m = self.map_msg
        info = m.info
        if abs(_yaw(info.origin.orientation)) > 1e-6:
            rospy.logwarn("fleet_nav (%s): /map origin is rotated by %.3f rad; fleet_nav ignores the rotation "
                          "like costmap_2d's static layer", self.robot, _yaw(info.origin.orientation))
        geometry = core.GridGeometry(info.resolution, info.origin.position.x, info.origin.position.y,
                                     info.width, info.height)
        occupancy = np.frombuffer(bytes(np.asarray(m.data, dtype=np.int8).tobytes()), dtype=np.int8)
        self.costmap = GlobalCostmap(geometry, occupancy, self.params, self.layer_params)
        self.navigator = Navigator(self.params, self.costmap)
        rospy.loginfo("fleet_nav (%s): map %dx%d at %.3f m, origin (%.2f, %.2f)", self.robot, info.width,
                      info.height, info.resolution, info.origin.position.x, info.origin.position.y)
        return True

    def start(self):
        rospy.Subscriber("base_scan", _LaserScan, self._on_scan, queue_size=2)
        rospy.Subscriber("shared_obstacles", SharedObstacle, self._on_shared, queue_size=100)
        rospy.Subscriber("expired_obstacles", String, self._on_expired, queue_size=100)
        rospy.Subscriber("fleet_robots", RobotFootprintArray, self._on_fleet_robots, queue_size=2)
        rospy.Subscriber("stuck_feedback", Empty, self._on_stuck_feedback, queue_size=10)
        # Like the costmap_2d plugin: a recovery announced by this host or by a move_base beside it.
        rospy.Subscriber("move_base/recovery_status", rospy.AnyMsg, self._on_recovery_status, queue_size=10)
        rospy.Subscriber("move_base_simple/goal", PoseStamped, self._on_simple_goal, queue_size=1)
        self.server = actionlib.SimpleActionServer("move_base", MoveBaseAction, auto_start=False)
        self.server.register_goal_callback(self._on_action_goal)
        self.server.register_preempt_callback(self._on_preempt)
        self.server.start()
        from fleet_sim.srv import Snapshot
        rospy.Service("~snapshot", Snapshot, self._on_snapshot)

    # --- callbacks: message -> validated value -> logic ---------------------------------------------
    def _on_map(self, msg):
        if self.map_msg is not None:
            rospy.logwarn_once("fleet_nav (%s): a new /map arrived; fleet_nav keeps the first one" % self.robot)
            return
        if msg.info.width == 0 or msg.info.height == 0 or len(msg.data) != msg.info.width * msg.info.height:
            rospy.logerr("fleet_nav (%s): /map is %dx%d with %d cells of data; ignored", self.robot,
                         msg.info.width, msg.info.height, len(msg.data))
            return
        self.map_msg = msg

    def _lookup(self, target, source, stamp, timeout=0.2):
        # The wait is in wall time: under a fast simulated clock a sim-time timeout is over before
        # the transform published right after the scan has arrived.
        give_up = time.monotonic() + timeout
        while True:
            try:
                t = self.tf_buffer.lookup_transform(target, source, stamp)
                break
            except (tf2_ros.ExtrapolationException, tf2_ros.LookupException):
                if time.monotonic() >= give_up or rospy.is_shutdown():
                    raise
                time.sleep(0.005)
        tr = t.transform
        return tr.translation.x, tr.translation.y, tr.translation.z, _yaw(tr.rotation)

    def _on_scan(self, msg):
        try:
            # The pose at the scan's own stamp, not the newest one: a scan placed with a pose a step
            # later puts a turning robot's view of a face 0.1 m into free space, and that gets shared
            # (issue 26; fleet_tests' turn_share.test is red with rospy.Time(0) here).
            sx, sy, sz, syaw = self._lookup(self.params.global_frame, msg.header.frame_id, msg.header.stamp)
            points = core.scan_to_points(np.asarray(msg.ranges, dtype=np.float64), msg.angle_min,
                                         msg.angle_increment, msg.range_min, msg.range_max, sx, sy, syaw, sz)
        except (tf2_ros.TransformException, ValueError) as err:
            self.dropped += 1
            rospy.logwarn_throttle(5.0, "fleet_nav (%s): ignoring this laser scan from %s (%d dropped): %s"
                                   % (self.robot, msg.header.frame_id, self.dropped, err))
            return
        now = msg.header.stamp.to_sec()
        with self.lock:
            outcome = self.costmap.layer.process_scan((sx, sy, sz), points, now)
            if not outcome.origin_in_map:
                rospy.logwarn_throttle(5.0, "fleet_nav (%s): laser origin (%.2f, %.2f) is off the map; not clearing"
                                       % (self.robot, sx, sy))
            for update in outcome.updates:
                self.update_pub.publish(_to_message(update, self.params.global_frame))
            if not self.params.sharing_enabled:
                return
            x, y = (self.pose[0], self.pose[1]) if self.pose is not None else (sx, sy)
            if self.stuck_pending is not None:
                (source, stamp), self.stuck_pending = self.stuck_pending, None
                self._report(self.costmap.layer.trigger(source, stamp, x, y), now)
            # The plan-blocked trigger: newly marked cells on the plan ahead, before the replan hides them.
            if self.params.plan_trigger:
                self._report(self.costmap.layer.check_plan(x, y, now), now)

    def _report(self, report, now):
        """Publishes a trigger's proposals and logs it once (what it proposed, or why nothing)."""
        if report.reason == "none":
            return
        if report.log:
            rospy.loginfo("fleet_nav (%s): %s", self.robot, report.message)
        self._publish_proposals(report.proposals, now)

    def _publish_proposals(self, proposals, now):
        for proposal in proposals:
            msg = SharedObstacle()
            msg.header.stamp = rospy.Time.from_sec(now)
            msg.header.frame_id = self.params.global_frame
            msg.marked_indexes = proposal.cells.tolist()
            msg.rectangle_shape = list(proposal.rectangle)
            msg.source = self.robot
            g = self.costmap.geometry
            msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y = (
                g.resolution, g.origin_x, g.origin_y, g.size_x, g.size_y)
            msg.version = 0
            self.proposal_pub.publish(msg)

    def _on_stuck_feedback(self, _msg):
        self._trigger_pending("stuck_feedback")

    def _on_recovery_status(self, _msg):
        self._trigger_pending("recovery_status")

    def _trigger_pending(self, source):
        """A stuck trigger, run with the next scan (the layer proposes from what it has just seen)."""
        with self.lock:
            if self.stuck_pending is None:
                self.stuck_pending = (source, rospy.get_time())

    def _on_shared(self, msg):
        if not self.params.sharing_enabled:
            return
        try:
            update = _from_message(msg)
        except ValueError as err:
            rospy.logwarn_throttle(1.0, "fleet_nav (%s): ignoring shared obstacle %s from %s: %s"
                                   % (self.robot, msg.uuid, msg.source, err))
            return
        with self.lock:
            result = self.costmap.layer.apply_shared(update, rospy.get_time())
        if not result.ok:
            rospy.logwarn_throttle(1.0, "fleet_nav (%s): ignoring shared obstacle %s from %s: %s"
                                   % (self.robot, msg.uuid, msg.source, result.error))

    def _fleet_robot(self, robot):
        """One RobotFootprint -> (name, [(x, y)] in the global frame, stamp); ValueError says why not."""
        points = [(p.x, p.y) for p in robot.footprint.points]
        if not robot.robot:
            raise ValueError("no robot name")
        if not 1 <= len(points) <= 1000 or not all(math.isfinite(v) for p in points for v in p):
            raise ValueError("footprint of %d vertices, or not finite" % len(points))
        xs, ys = [x for x, _ in points], [y for _, y in points]
        if max(xs) - min(xs) > 50.0 or max(ys) - min(ys) > 50.0:
            raise ValueError("footprint wider than 50 m: not a robot")
        frame = robot.header.frame_id.lstrip("/") or self.params.global_frame
        if frame != self.params.global_frame:
            try:
                tx, ty, _, tyaw = self._lookup(self.params.global_frame, frame, rospy.Time(0), 0.05)
            except tf2_ros.TransformException as err:
                raise ValueError("cannot transform its footprint from %s to %s: %s"
                                 % (frame, self.params.global_frame, err)) from None
            c, s = math.cos(tyaw), math.sin(tyaw)
            points = [(tx + c * x - s * y, ty + s * x + c * y) for x, y in points]
        stamp = robot.header.stamp.to_sec() if not robot.header.stamp.is_zero() else rospy.get_time()
        return robot.robot, np.asarray(points, dtype=float), stamp

    def _on_fleet_robots(self, msg):
        """The fleet robots the bridge heard (the whole set): their cells are never shared."""
        if not self.params.sharing_enabled or self.costmap is None:
            return
        robots = []
        for robot in msg.robots:
            if robot.robot == self.robot:
                continue
            try:
                robots.append(self._fleet_robot(robot))
            except ValueError as err:
                self.fleet_robots_dropped += 1
                rospy.logwarn_throttle(5.0, "fleet_nav (%s): ignoring fleet robot %r (%d dropped): %s"
                                       % (self.robot, robot.robot[:40], self.fleet_robots_dropped, err))
        with self.lock:
            try:
                self.costmap.layer.fleet_robots.replace_all(robots)
            except ValueError as err:  # what the checks above let through, the core refuses whole
                self.fleet_robots_dropped += 1
                rospy.logwarn_throttle(5.0, "fleet_nav (%s): ignoring fleet_robots: %s" % (self.robot, err))
                return
        names = tuple(name for name, _, _ in robots)
        if names != self.fleet_robot_names:
            self.fleet_robot_names = names
            rospy.loginfo("fleet_nav (%s): fleet robots never shared: %s", self.robot, ", ".join(names) or "none")

    def _publish_footprint(self, x, y, yaw):
        msg = PolygonStamped()
        msg.header.frame_id = self.params.global_frame
        msg.header.stamp = rospy.Time.now()
        c, s = math.cos(yaw), math.sin(yaw)
        msg.polygon.points = [Point32(x + c * fx - s * fy, y + s * fx + c * fy, 0.0)
                              for fx, fy in self.params.footprint_polygon]
        self.footprint_pub.publish(msg)

    def _on_expired(self, msg):
        with self.lock:
            known = self.costmap.layer.expire(msg.data)
        if not known:
            rospy.logdebug("fleet_nav (%s): expired obstacle %s was not known", self.robot, msg.data)

    def _goal_from_pose(self, pose_stamped):
        """(x, y, yaw) in the global frame; raises GoalRejected with the reason."""
        frame = pose_stamped.header.frame_id.lstrip("/") or self.params.global_frame
        p, q = pose_stamped.pose.position, pose_stamped.pose.orientation
        if not all(math.isfinite(v) for v in (p.x, p.y, q.x, q.y, q.z, q.w)):
            raise GoalRejected("goal pose is not finite")
        if abs(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0) > 1e-2:
            raise GoalRejected("goal orientation is not a unit quaternion (%.3f, %.3f, %.3f, %.3f)"
                               % (q.x, q.y, q.z, q.w))
        x, y, yaw = p.x, p.y, _yaw(q)
        if frame != self.params.global_frame:
            try:
                tx, ty, _, tyaw = self._lookup(self.params.global_frame, frame, rospy.Time(0), 0.5)
            except tf2_ros.TransformException as err:
                raise GoalRejected("cannot transform the goal from %s to %s: %s"
                                   % (frame, self.params.global_frame, err)) from None
            x, y, yaw = (tx + math.cos(tyaw) * x - math.sin(tyaw) * y,
                         ty + math.sin(tyaw) * x + math.cos(tyaw) * y, yaw + tyaw)
        self.costmap.check_goal(x, y)
        return x, y, yaw

    def _start_goal(self, pose_stamped):
        with self.lock:
            x, y, yaw = self._goal_from_pose(pose_stamped)
            self.navigator.set_goal(x, y, yaw, rospy.get_time())
        rospy.loginfo("fleet_nav (%s): new goal (%.2f, %.2f, %.2f rad)", self.robot, x, y, yaw)

    def _on_action_goal(self):
        goal = self.server.accept_new_goal()
        try:
            self._start_goal(goal.target_pose)
        except GoalRejected as err:
            rospy.logwarn("fleet_nav (%s): goal rejected: %s", self.robot, err)
            self.server.set_aborted(MoveBaseResult(), text="goal rejected: %s" % err)

    def _on_simple_goal(self, msg):
        if self.server.is_active():
            self.server.set_preempted(MoveBaseResult(), text="replaced by a move_base_simple/goal")
        try:
            self._start_goal(msg)
        except GoalRejected as err:
            rospy.logwarn("fleet_nav (%s): move_base_simple/goal rejected: %s", self.robot, err)

    def _on_preempt(self):
        with self.lock:
            self.navigator.cancel()
            self.costmap.layer.set_plan(np.zeros((0, 2)))
        self.cmd_pub.publish(Twist())
        self.server.set_preempted(MoveBaseResult(), text="cancelled")

    def _on_snapshot(self, req):
        from fleet_sim.srv import SnapshotResponse
        try:
            with self.lock:
                costs = self.costmap.costs.copy()
                mask = self.costmap.shared_mask()
                plan = self.navigator.path_xy.copy()
                pose = self.pose
            scale = max(1, int(round((req.pixels_per_metre or 40.0) * self.costmap.geometry.resolution)))
            img = snapshot.render(costs, mask, self.costmap.geometry, pose, self.params.footprint_polygon, plan, scale)
            img.save(req.path)
            return SnapshotResponse(True, "wrote %s (%dx%d)" % (req.path, img.width, img.height))
        except (OSError, ValueError) as err:
            return SnapshotResponse(False, "cannot write %s: %s" % (req.path, err))

    # --- publishing -------------------------------------------------------------------------------
    def _publish_costmap(self):
        g = self.costmap.geometry
        msg = OccupancyGrid()
        msg.header.frame_id = self.params.global_frame
        msg.header.stamp = rospy.Time.now()
        msg.info.resolution = g.resolution
        msg.info.width, msg.info.height = g.size_x, g.size_y
        msg.info.origin.position.x, msg.info.origin.position.y = g.origin_x, g.origin_y
        msg.info.origin.orientation.w = 1.0
        msg.data = _COST_TO_OCC[self.costmap.costs.reshape(-1)].tolist()
        self.costmap_pub.publish(msg)

    def _publish_plan(self):
        path = Path()
        path.header.frame_id = self.params.global_frame
        path.header.stamp = rospy.Time.now()
        for x, y in self.navigator.path_xy[::2]:
            pose = PoseStamped()
            pose.header = path.header
            pose.pose.position.x, pose.pose.position.y = float(x), float(y)
            pose.pose.orientation.w = 1.0
            path.poses.append(pose)
        self.plan_pub.publish(path)
        self.navfn_plan_pub.publish(path)

    def _publish_markers(self):
        markers = MarkerArray()
        clear = Marker()
        clear.header.frame_id = self.params.global_frame
        clear.action = Marker.DELETEALL
        clear.pose.orientation.w = 1.0
        markers.markers.append(clear)
        g = self.costmap.geometry
        for i, uuid in enumerate(self.costmap.layer.shared_uuids()):
            m = Marker()
            m.header.frame_id = self.params.global_frame
            m.header.stamp = rospy.Time.now()
            m.ns, m.id, m.type, m.action = "shared_obstacles", i, Marker.CUBE_LIST, Marker.ADD
            m.scale.x = m.scale.y = g.resolution
            m.scale.z = 0.2
            m.color.r, m.color.g, m.color.b, m.color.a = 0.86, 0.12, 0.63, 0.9
            m.pose.orientation.w = 1.0  # (no text: RViz ignores it on a CUBE_LIST and warns)
            from geometry_msgs.msg import Point
            for x, y in self.costmap.cell_to_world(self.costmap.layer.shared_cells(uuid)):
                m.points.append(Point(float(x), float(y), 0.1))
            markers.markers.append(m)
        self.marker_pub.publish(markers)

    # --- main loop ----------------------------------------------------------------------------------
    def spin(self):
        p = self.params
        rate = rospy.Rate(p.controller_frequency)
        next_update = next_publish = 0.0
        shared_seen = None
        was_active = False
        self.costmap.request_full_update()
        while not rospy.is_shutdown():
            now = rospy.get_time()
            try:
                x, y, _, yaw = self._lookup(p.global_frame, p.robot_base_frame, rospy.Time(0))
            except tf2_ros.TransformException as err:
                rospy.logwarn_throttle(5.0, "fleet_nav (%s): no pose of %s in %s yet: %s"
                                       % (self.robot, p.robot_base_frame, p.global_frame, err))
                rate.sleep()
                continue
            with self.lock:
                self.pose = (x, y, yaw)
                if now >= next_update:
                    next_update = now + 1.0 / p.update_frequency
                    self.costmap.update(x, y)
                    self._publish_footprint(x, y, yaw)
                    shared = tuple((u, self.costmap.layer.shared_max_version(u))
                                   for u in self.costmap.layer.shared_uuids())
                    if shared != shared_seen:
                        shared_seen = shared
                        self._publish_markers()
                step = self.navigator.tick(now, self.pose)
            if now >= next_publish:
                next_publish = now + 2.0
                self._publish_costmap()
            self._handle(step)
            active = self.navigator.active
            if active or was_active:
                cmd = Twist()
                cmd.linear.x, cmd.angular.z = step.linear, step.angular
                self.cmd_pub.publish(cmd)
            was_active = active
            if active and self.server.is_active():
                fb = MoveBaseFeedback()
                fb.base_position.header.frame_id = p.global_frame
                fb.base_position.header.stamp = rospy.Time.now()
                fb.base_position.pose.position.x, fb.base_position.pose.position.y = x, y
                o = fb.base_position.pose.orientation
                o.x, o.y, o.z, o.w = yaw_quaternion(yaw)
                self.server.publish_feedback(fb)
            rate.sleep()

    def _publish_recovery_status(self, index, total, name):
        msg = RecoveryStatus()
        msg.pose_stamped.header.frame_id = self.params.global_frame
        msg.pose_stamped.header.stamp = rospy.Time.now()
        if self.pose is not None:
            msg.pose_stamped.pose.position.x, msg.pose_stamped.pose.position.y = self.pose[0], self.pose[1]
            o = msg.pose_stamped.pose.orientation
            o.x, o.y, o.z, o.w = yaw_quaternion(self.pose[2])
        msg.current_recovery_number = index
        msg.total_number_of_recoveries = total
        msg.recovery_behavior_name = name
        rospy.logwarn("fleet_nav (%s): recovery behaviour %d of %d: %s", self.robot, index + 1, total, name)
        self.recovery_pub.publish(msg)

    def _handle(self, step):
        for event in step.events:
            if event is Event.PLANNED:
                with self.lock:
                    if self.params.plan_trigger:
                        self.costmap.layer.set_plan(self.navigator.path_xy)
                self._publish_plan()
            elif event is Event.STUCK:
                rospy.logwarn("fleet_nav (%s): local controller failed (%d for this goal): %s; publishing "
                              "stuck_feedback (stuck_feedback_on_local_failure)", self.robot,
                              self.navigator.local_failures, step.reason)
                self.stuck_pub.publish(Empty())   # the subscription above hands it to the layer
            elif event is Event.RECOVERY:
                self._publish_recovery_status(*step.recovery)
            elif event is Event.SUCCEEDED:
                with self.lock:
                    self.costmap.layer.set_plan(np.zeros((0, 2)))
                    self.costmap.reset_obstacle_layer()
                rospy.loginfo("fleet_nav (%s): goal reached; obstacle layer reset (%d shared obstacles kept)",
                              self.robot, len(self.costmap.layer.shared_uuids()))
                if self.server.is_active():
                    self.server.set_succeeded(MoveBaseResult(), text="goal reached")
            elif event is Event.ABORTED:
                with self.lock:
                    self.costmap.layer.set_plan(np.zeros((0, 2)))
                rospy.logerr("fleet_nav (%s): goal aborted: %s", self.robot, step.reason)
                if self.server.is_active():
                    self.server.set_aborted(MoveBaseResult(), text=step.reason)


from sensor_msgs.msg import LaserScan as _LaserScan  # noqa: E402


def main():
    rospy.init_node("fleet_nav")
    try:
        node = NavNode()
    except (ParameterError, ValueError) as err:
        rospy.logfatal("fleet_nav (%s) cannot start: bad parameter: %s", rospy.get_namespace().strip("/"), err)
        raise SystemExit(1)
    publisher_links.start_watch(rospy.get_name())
    if not node.wait_for_map():
        return
    node.start()
    try:
        node.spin()
    except rospy.ROSInterruptException:
        pass
