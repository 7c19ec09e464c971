#!/usr/bin/python3
"""Test node of nav_bad_input.test: fleet_nav without /map, then with goals it must refuse, then bad
fleet robots (fleet_robots) it must drop while keeping the good one."""
import math
import threading
import unittest

import actionlib
import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import Point32, PoseStamped
from move_base_msgs.msg import MoveBaseAction, MoveBaseGoal
from nav_msgs.msg import OccupancyGrid
from rosgraph_msgs.msg import Log
from sharing_msgs.msg import RobotFootprint, RobotFootprintArray

NODE = "/robot_7/move_base"


class NavBadInput(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("nav_bad_input_scenario")
        cls.lock = threading.Lock()
        cls.lines = []
        rospy.Subscriber("/rosout", Log, cls.on_log, queue_size=100)

    @classmethod
    def on_log(cls, msg):
        if msg.name == NODE:
            with cls.lock:
                cls.lines.append((msg.level, msg.msg))

    def wait_for_line(self, words, timeout):
        deadline = rospy.get_time() + timeout
        while rospy.get_time() < deadline and not rospy.is_shutdown():
            with self.lock:
                for level, text in self.lines:
                    if all(w in text for w in words):
                        return level, text
            rospy.sleep(0.05)
        with self.lock:
            self.fail("no log line of %s with %s; got %s" % (NODE, words, [t for _, t in self.lines][-5:]))

    def goal(self, x, y):
        goal = MoveBaseGoal()
        goal.target_pose.header.frame_id = "map"
        goal.target_pose.pose.position.x, goal.target_pose.pose.position.y = x, y
        goal.target_pose.pose.orientation.w = 1.0
        return goal

    def test_missing_map_then_bad_goals(self):
        # 1. No /map yet: fleet_nav says so, naming itself and the topic, and offers no action yet.
        self.wait_for_line(["robot_7", "waiting for /map"], 20.0)
        client = actionlib.SimpleActionClient("/robot_7/move_base", MoveBaseAction)
        self.assertFalse(client.wait_for_server(rospy.Duration(1.0)), "move_base action up before /map")

        # 2. A 10 m x 6 m room at 0.05 m with a wall at x = 5 m.
        grid = OccupancyGrid()
        grid.header.frame_id = "map"
        grid.info.resolution = 0.05
        grid.info.width, grid.info.height = 200, 120
        grid.info.origin.orientation.w = 1.0
        data = [0] * (200 * 120)
        for row in range(120):
            data[row * 200 + 100] = 100
        grid.data = data
        pub = rospy.Publisher("/map", OccupancyGrid, queue_size=1, latch=True)
        pub.publish(grid)
        self.wait_for_line(["robot_7", "map 200x120"], 20.0)
        self.assertTrue(client.wait_for_server(rospy.Duration(20.0)), "no move_base action after /map")

        # 3. Goals through the action: refused with the reason, the node keeps serving.
        for (x, y), reason in (((12.0, 3.0), "outside the map"), ((5.02, 3.0), "inside an obstacle"),
                               ((4.85, 3.0), "inscribed radius")):
            client.send_goal(self.goal(x, y))
            self.assertTrue(client.wait_for_result(rospy.Duration(10.0)), "no result for goal (%s, %s)" % (x, y))
            self.assertEqual(GoalStatus.ABORTED, client.get_state())
            text = client.get_goal_status_text()
            self.assertIn("goal rejected", text)
            self.assertIn(reason, text)
            self.assertIn("%.2f" % x, text)

        # 4. The same through move_base_simple/goal: a warning that names robot, goal and reason.
        simple = rospy.Publisher("/robot_7/move_base_simple/goal", PoseStamped, queue_size=1)
        pose = PoseStamped()
        pose.header.frame_id = "map"
        pose.pose.position.x, pose.pose.position.y = -1.0, 3.0
        pose.pose.orientation.w = 1.0
        deadline = rospy.get_time() + 10.0
        while simple.get_num_connections() == 0 and rospy.get_time() < deadline:
            rospy.sleep(0.05)
        simple.publish(pose)
        level, _ = self.wait_for_line(["robot_7", "move_base_simple/goal rejected", "-1.00", "outside the map"], 10.0)
        self.assertEqual(Log.WARN, level)

        # 5. Fleet robots from the bridge: bad entries are dropped with a warning naming the robot, the
        # good one is kept (its cells are never shared), this robot's own entry is ignored.
        def robot(name, points, frame="map"):
            r = RobotFootprint()
            r.header.frame_id = frame
            r.header.stamp = rospy.Time.now()
            r.robot = name
            r.footprint.points = [Point32(x, y, 0.0) for x, y in points]
            return r
        square = [(1.0, 1.0), (1.6, 1.0), (1.6, 1.6), (1.0, 1.6)]
        fleet = rospy.Publisher("/robot_7/fleet_robots", RobotFootprintArray, queue_size=1, latch=True)
        fleet.publish(RobotFootprintArray(robots=[
            robot("robot_bad_nan", [(float("nan"), 1.0), (2.0, 1.0), (2.0, 2.0)]),
            robot("robot_bad_empty", []),
            robot("robot_bad_frame", square, frame="nowhere"),
            robot("robot_bad_huge", [(0.0, 0.0), (90.0, 0.0), (0.0, 1.0)]),
            robot("robot_7", square),
            robot("robot_2", square)]))
        level, text = self.wait_for_line(["robot_7", "ignoring fleet robot", "robot_bad"], 10.0)
        self.assertEqual(Log.WARN, level)
        level, text = self.wait_for_line(["robot_7", "fleet robots never shared: robot_2"], 10.0)
        self.assertEqual(Log.INFO, level)
        self.assertNotIn("robot_bad", text)
        self.assertNotIn("robot_7,", text)
        self.assertTrue(client.wait_for_server(rospy.Duration(1.0)), "fleet_nav stopped serving")


if __name__ == "__main__":
    rostest.rosrun("fleet_nav", "nav_bad_input", NavBadInput)
