#!/usr/bin/python3
"""Node of move_base_corridors.test: the two-corridor scenario on the real stack (upstream move_base,
stageros, map_server, fake_localization; fleet_launch/move_base_fleet.launch).

robot_0 is sent from the bottom hall to goal_0 in the top hall; its plan runs up the short corridor,
which block_short (a Stage model, not in the map) closes. With sharing, its layer shares the block as
soon as newly marked cells lie on its plan ahead (the plan_blocked trigger: upstream move_base
publishes no stuck_feedback, and a recovery comes later), and robot_0 takes the long corridor. When
robot_0 has reached goal_0, robot_1 is sent from the bottom hall to goal_1 (short of goal_0, so it
never has to pass robot_0): it must hold robot_0's obstacle (over MQTT), no plan of robot_1 and no
pose of its ground truth (stageros's base_pose_ground_truth) lies inside the short corridor, and it
reaches goal_1. One after the other, because in these worlds a robot's laser (on top of the 0.25 m
body) passes over the other robots: in real Stage they do not see each other.

With sharing:=false (costmap_2d::ObstacleLayer instead of the sharing layer) the same dispatch runs as
the baseline: nothing is shared, and the figures are logged without the corridor assertions.

Each run logs one line "move_base_corridors: RESULT ..." (times in simulated s) for the README's table.
With ~picture:=FILE.png (rostest ... picture:=FILE.png) it also draws the run: the map, the block, the
cells robot_0 shared and both robots' ground-truth trails (fleet_tests.run_picture).
Upstream move_base names its plan move_base/NavfnROS/plan; Stage has no block services, so the world
stays as it was loaded (fleet_tests.scenario.Fleet is used for its observers only).
"""
import math
import threading
import unittest

import rospy
import rostest
from nav_msgs.msg import Path
from rosgraph_msgs.msg import Log

from fleet_tests.ground_truth import distance_to_block, precision
from fleet_tests.run_picture import draw_run
from fleet_tests.scenario import Fleet, ScenarioError, cell_centre, entered, load_facility, wait_for_sim_time


class MoveBaseCorridors(unittest.TestCase):
    GOAL_TIMEOUT = 300.0   # s of simulated time (Stage runs in real time)
    SHARE_TIMEOUT = 60.0

    @classmethod
    def setUpClass(cls):
        wait_for_sim_time()
        rospy.init_node("move_base_corridors")
        cls.sharing = bool(rospy.get_param("~sharing", True))
        cls.fleet = Fleet(2, load_facility(rospy.get_param("/fleet/goals", None)))
        cls.lock = threading.Lock()
        cls.plans = {r.name: [] for r in cls.fleet.robots}     # (sim time, [(x, y)]) of navfn's plans
        cls.triggers = {r.name: [] for r in cls.fleet.robots}  # (sim time, message) of the layers' trigger lines
        for r in cls.fleet.robots:
            rospy.Subscriber("/%s/move_base/NavfnROS/plan" % r.name, Path, cls._on_plan(r.name), queue_size=10)
        rospy.Subscriber("/rosout", Log, cls._on_log, queue_size=1000)
        for r in cls.fleet.robots:
            r.wait_ready(180.0)
            if cls.sharing:
                rospy.wait_for_service(r.list_srv.resolved_name, 180.0)
        cls.fleet.wait_until(lambda: all(r.pose for r in cls.fleet.robots), 60.0, "both robots' ground truth")

    @classmethod
    def _on_plan(cls, name):
        def cb(msg):
            with cls.lock:
                cls.plans[name].append((rospy.get_time(), [(p.pose.position.x, p.pose.position.y) for p in msg.poses]))
        return cb

    @classmethod
    def _on_log(cls, msg):
        for name in cls.triggers:
            if msg.name == "/%s/move_base" % name and " trigger at " in msg.msg:
                with cls.lock:
                    cls.triggers[name].append((rospy.get_time(), msg.msg))
                rospy.loginfo("move_base_corridors: %s: %s", name, msg.msg)

    def arrival(self, robot, goal, since):
        """Sim s from `since` to the first ground-truth pose within 0.3 m of the goal (None: never)."""
        gx, gy, _yaw = self.fleet.goal(goal)
        with self.fleet.lock:
            times = [t for t, x, y in robot.track if t >= since and math.hypot(x - gx, y - gy) <= 0.3]
        return times[0] - since if times else None

    def test_robot_sent_after_the_share_never_enters_the_blocked_corridor(self):
        fleet = self.fleet
        r0, r1 = fleet.robots
        short = fleet.corridor("short")
        self.outcome = "robot_0 did not arrive"
        self.addCleanup(self.draw)  # on a failure too: the picture shows where a robot stalled

        start0 = r0.send("goal_0")
        first = shared_at = None
        if self.sharing:
            try:
                shares = fleet.wait_until(r0.shares, self.SHARE_TIMEOUT, "robot_0 to share block_short")
            except ScenarioError as err:
                with self.lock:
                    triggers = list(self.triggers["robot_0"])
                self.fail("%s; robot_0 at %s, its layer's trigger lines: %s" % (err, r0.pose, triggers))
            shared_at, first = shares[0]
            with self.lock:
                proposing = [m for t, m in self.triggers["robot_0"] if t <= shared_at + 1.0 and "proposed" in m]
            rospy.loginfo("move_base_corridors: robot_0 shared %s %.1f s after its dispatch, at (%.2f, %.2f): "
                          "%d cells in %s", first.uuid, shared_at - start0, r0.pose[0], r0.pose[1],
                          len(first.marked_indexes), [round(v, 2) for v in first.rectangle_shape])
            self.assertTrue(proposing and "): plan_blocked trigger" in proposing[-1],
                            "robot_0's share did not come from the plan_blocked trigger; trigger lines: %s" % proposing)
        result0 = r0.wait(max(1.0, start0 + self.GOAL_TIMEOUT - rospy.get_time()))
        time0 = self.arrival(r0, "goal_0", start0)
        self.assertTrue(result0[0] and result0[1] == "SUCCEEDED", "robot_0 did not reach goal_0: %s %s; at %s"
                        % (result0[1], result0[2], r0.pose))
        if self.sharing:
            self.assertIn(first.uuid, r1.obstacles(), "robot_1's handler does not hold robot_0's obstacle %.1f s "
                          "after the share, when robot_1 is sent" % (rospy.get_time() - shared_at))
        self.outcome = "robot_1 did not arrive"
        sent = r1.send("goal_1")
        result1 = r1.wait(self.GOAL_TIMEOUT)
        with fleet.lock:
            track = [(t, x, y) for t, x, y in r1.track if t >= sent]
            distance1 = sum(math.hypot(b[1] - a[1], b[2] - a[2]) for a, b in zip(track, track[1:]))
        with self.lock:
            plans = [(t, p) for t, p in self.plans["robot_1"] if t >= sent]
            own1 = [m for _t, m in self.triggers["robot_1"] if "proposed" in m]
        inside = entered(track, short)
        time1 = self.arrival(r1, "goal_1", sent)
        latency = fleet.latencies()
        rospy.loginfo("move_base_corridors: RESULT sharing=%s robot_1: %s, time to goal %s s, %.1f m, %d plans "
                      "(%d through the short corridor), %d poses in it, %d recoveries, %d own shares; robot_0: %s, "
                      "time to goal %s s, %d recoveries; share %s s after robot_0's dispatch; latency to robot_1's "
                      "layer %s ms", self.sharing, result1[1], "%.1f" % time1 if time1 is not None else "-", distance1,
                      len(plans), sum(1 for _t, p in plans if entered(p, short)), len(inside), len(r1.recoveries),
                      len(own1), result0[1], "%.1f" % time0 if time0 is not None else "-", len(r0.recoveries),
                      "%.1f" % (shared_at - start0) if shared_at is not None else "-",
                      ", ".join("%.0f" % (v * 1000) for v in latency) or "-")

        self.outcome = "robot_1 %s%s" % (result1[1], " in %.1f s" % time1 if time1 is not None else "")
        if self.sharing:
            self.assert_every_shared_cell_on_the_block()
            self.assertEqual([], inside[:5], "robot_1, sent after the share, entered the blocked short corridor %s "
                             "(first poses shown)" % (short,))
            for t, plan in plans:
                self.assertEqual([], entered(plan, short)[:3], "robot_1's plan %.1f s after its dispatch runs "
                                 "through the blocked short corridor" % (t - sent))
            self.assertTrue(plans, "no plan of robot_1 seen on move_base/NavfnROS/plan")
        self.assertTrue(result1[0] and result1[1] == "SUCCEEDED", "robot_1 did not reach goal_1: %s %s; at %s"
                        % (result1[1], result1[2], r1.pose))

    def assert_every_shared_cell_on_the_block(self):
        """Every cell either robot marked in a message it sent (first shares and follow-up updates) lies on
        the block where Stage has it (precision 1 against ground truth, per message: issue 49)."""
        blocks = self.fleet.present_blocks()
        with self.fleet.lock:
            sent = [(t, r.name, m) for r in self.fleet.robots for t, m in r.to_fleet if m.source == r.name
                    and m.marked_indexes]
        off = []
        cells = 0
        for t, name, m in sent:
            points = [cell_centre(m, i) for i in m.marked_indexes]
            cells += len(points)
            share, missed = precision(points, m.resolution, blocks)
            if missed:
                off.append("%s v%d from %s at %.1f s: %d of %d cells off the block, e.g. (%.2f, %.2f), %.2f m away"
                           % (m.uuid[:8], m.version, name, t, len(missed), len(points), missed[0][0], missed[0][1],
                              min(distance_to_block(missed[0][0], missed[0][1], b) for b in blocks)))
        rospy.loginfo("move_base_corridors: PRECISION %d messages, %d marked cells, %d messages with cells off the "
                      "block", len(sent), cells, len(off))
        self.assertTrue(sent, "no message with marked cells was sent")
        self.assertEqual([], off, "shared cells in free space (against Stage's ground truth)")

    def draw(self):
        path = rospy.get_param("~picture", "")
        if not path:
            return
        fleet = self.fleet
        with fleet.lock:
            grid = fleet.map
            trails = {r.name: list(r.track) for r in fleet.robots}
            shared = [m for r in fleet.robots for _t, m in r.to_fleet if m.source == r.name]
        if grid is None:
            rospy.logwarn("move_base_corridors: no /map received, no picture drawn")
            return
        title = "upstream move_base + stageros, sharing %s: %s" % ("on" if self.sharing else "off", self.outcome)
        try:
            draw_run(path, grid, fleet.facility, trails, shared, title)
            rospy.loginfo("move_base_corridors: picture of the run in %s", path)
        except (OSError, ValueError) as err:
            rospy.logwarn("move_base_corridors: cannot write the picture %s: %s", path, err)


if __name__ == "__main__":
    rostest.rosrun("fleet_tests", "move_base_corridors", MoveBaseCorridors)
