#!/usr/bin/python3
"""Test node of nav_willow.test: drives robot_0 with the move_base action through fleet_nav."""
import math
import os
import tempfile
import unittest

import actionlib
import rospy
import rostest
import tf2_ros
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Twist
from move_base_msgs.msg import MoveBaseAction
from nav_msgs.msg import Path
from std_msgs.msg import Empty

from fleet_sim.srv import AddBlock, Snapshot
from sharing_msgs.msg import SharedObstacle
from fleet_nav.goals import move_base_goal


class NavWillow(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("nav_willow_scenario")
        cls.stuck = []
        cls.plans = []
        cls.proposals = []
        rospy.Subscriber("/robot_0/obstacle_proposals", SharedObstacle, cls.proposals.append)
        rospy.Subscriber("/robot_0/stuck_feedback", Empty, lambda _m: cls.stuck.append(rospy.get_time()))
        rospy.Subscriber("/robot_0/plan", Path, lambda m: cls.plans.append(
            [(p.pose.position.x, p.pose.position.y) for p in m.poses]))
        cls.tf = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.tf)
        cls.client = actionlib.SimpleActionClient("/robot_0/move_base", MoveBaseAction)
        assert cls.client.wait_for_server(rospy.Duration(120.0)), "robot_0/move_base action server never came up"
        rospy.wait_for_service("/fleet_sim/add_block", 60.0)
        cls.add_block = rospy.ServiceProxy("/fleet_sim/add_block", AddBlock)
        cls.move_robot_1_away()

    @classmethod
    def move_robot_1_away(cls):
        """robot_1 stands beside robot_0's start. In this world the lasers sit on top of the 0.25 m bodies, so
        (in Stage as in fleet_sim) neither robot sees the other, and robot_0, planning east, would drive into it:
        this test has no use for robot_1, so it drives robot_1 ~robot_1_away [dx, dy] m (map frame) off the way
        (cmd_vel; the pr2 is omnidirectional) and checks that it got there."""
        dx, dy = rospy.get_param("~robot_1_away")
        pub = rospy.Publisher("/robot_1/cmd_vel", Twist, queue_size=1)
        end = rospy.get_time() + 10.0
        while pub.get_num_connections() == 0 and rospy.get_time() < end:
            rospy.sleep(0.1)
        t1 = cls.tf.lookup_transform("map", "robot_1/base_link", rospy.Time(0), rospy.Duration(10.0)).transform
        start = (t1.translation.x, t1.translation.y)
        q = t1.rotation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        distance, speed = math.hypot(dx, dy), 0.3
        twist = Twist()   # the map-frame direction in robot_1's own frame
        twist.linear.x = speed * (math.cos(yaw) * dx + math.sin(yaw) * dy) / distance
        twist.linear.y = speed * (-math.sin(yaw) * dx + math.cos(yaw) * dy) / distance
        end = rospy.get_time() + distance / speed
        rate = rospy.Rate(20)
        while rospy.get_time() < end and not rospy.is_shutdown():
            pub.publish(twist)
            rate.sleep()
        pub.publish(Twist())
        t1 = cls.tf.lookup_transform("map", "robot_1/base_link", rospy.Time(0), rospy.Duration(10.0)).transform
        moved = math.hypot(t1.translation.x - start[0], t1.translation.y - start[1])
        assert moved > 0.8 * distance, "robot_1 moved %.2f m of %.2f off robot_0's way (a wall?)" % (moved, distance)

    def pose(self, frame="robot_0/base_link"):
        t = self.tf.lookup_transform("map", frame, rospy.Time(0), rospy.Duration(5.0))
        return t.transform.translation.x, t.transform.translation.y

    def go(self, x, y, yaw, timeout):
        self.client.send_goal(move_base_goal(x, y, yaw))
        finished = self.client.wait_for_result(rospy.Duration(timeout))
        state, text = self.client.get_state(), self.client.get_goal_status_text()
        if not finished or state != GoalStatus.SUCCEEDED:
            text += "; pictures: " + self.pictures("goal_%.0f_%.0f" % (x, y))
        return finished, state, text

    @staticmethod
    def cells(proposal):
        """World centres of a proposal's marked cells."""
        return [(proposal.origin_x + (i % proposal.size_x + 0.5) * proposal.resolution,
                 proposal.origin_y + (i // proposal.size_x + 0.5) * proposal.resolution)
                for i in proposal.marked_indexes]

    def pictures(self, name):
        """fleet_nav's view and the simulated world, for the failure message."""
        folder = os.environ.get("ROS_TEST_RESULTS_DIR") or tempfile.gettempdir()
        saved = []
        for service, path in (("/robot_0/move_base/snapshot", "nav_willow_%s_robot_0_view.png" % name),
                              ("/fleet_sim/snapshot", "nav_willow_%s_world.png" % name)):
            try:
                resp = rospy.ServiceProxy(service, Snapshot)(os.path.join(folder, path), False, 20.0)
                saved.append(resp.message)
            except (rospy.ServiceException, rospy.ROSException) as err:
                saved.append("%s failed: %s" % (service, err))
        return "; ".join(saved)

    def test_1_far_goal_then_blocked_corridor(self):
        start = self.pose()
        gx, gy, gyaw = rospy.get_param("~far_goal")
        finished, state, text = self.go(gx, gy, gyaw, 200.0)
        self.assertTrue(finished, "far goal not reached within 200 s of simulated time: %s" % text)
        self.assertEqual(GoalStatus.SUCCEEDED, state, "far goal: %s" % text)
        x, y = self.pose()
        self.assertLess(math.hypot(x - gx, y - gy), 0.3)
        self.assertEqual([], self.stuck, "stuck_feedback on a free route")
        # robot_1 stood beside robot_0's start and this test runs no Coaty bridge, so nothing tells robot_0's
        # layer that it is a robot; robot_0 does not see it (see move_robot_1_away) but could have before robot_1
        # moved off. A proposal before the block exists may only be robot_1's cells.
        r1x, r1y = self.pose("robot_1/base_link")
        for proposal in self.proposals:
            for cx, cy in self.cells(proposal):
                self.assertLess(max(abs(cx - r1x), abs(cy - r1y)), 0.6,
                                "proposed cell (%.2f, %.2f) on a free route is not robot_1 at (%.2f, %.2f)"
                                % (cx, cy, r1x, r1y))
        del self.proposals[:]

        # Close the corridor the robot came through (map (x, y) = Stage world (y, -x) in Willow).
        bx, by = rospy.get_param("~block_map_xy")
        size = rospy.get_param("~block_size")
        resp = self.add_block("corridor_block", -by, bx, 0.0, size, size)
        self.assertTrue(resp.success, resp.message)
        del self.plans[:]
        finished, state, text = self.go(start[0], start[1], 0.0, 300.0)
        first = self.plans[0] if self.plans else []
        self.assertTrue(first and min(math.hypot(px - bx, py - by) for px, py in first) < size,
                        "scenario: the first plan back (%d poses, from %s to %s) does not run through the "
                        "corridor at (%.2f, %.2f); %s" % (len(first), first[:1], first[-1:], bx, by, text))
        self.assertTrue(finished, "return goal not reached within 300 s of simulated time: %s" % text)
        self.assertEqual(GoalStatus.SUCCEEDED, state, "return goal: %s" % text)
        # move_base reroutes silently: its local planner fails in front of the block, the replan goes
        # round. Nothing in it publishes stuck_feedback.
        self.assertEqual([], self.stuck, "stuck_feedback %d times from a move_base with its defaults" % len(self.stuck))
        # With move_base's defaults the only trigger is the sharing layer's own plan-blocked one: it
        # proposes the block when its cells appear on the plan, and nothing else.
        self.assertTrue(self.proposals, "no obstacle proposed: the plan-blocked trigger did not fire")
        for proposal in self.proposals:
            for cx, cy in self.cells(proposal):
                self.assertLess(max(abs(cx - bx), abs(cy - by)), size / 2.0 + 0.15,
                                "proposed cell (%.2f, %.2f) is not on the block at (%.2f, %.2f)" % (cx, cy, bx, by))
        # The last plan goes round: it never comes within the block's half size of its centre.
        last = self.plans[-1]
        nearest = min(math.hypot(px - bx, py - by) for px, py in last)
        self.assertGreater(nearest, size / 2.0, "the final plan still runs through the block")


if __name__ == "__main__":
    rostest.rosrun("fleet_nav", "nav_willow", NavWillow)
