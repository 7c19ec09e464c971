#!/usr/bin/python3
"""rostest node for sim_interface.test (room.world: inner walls at x = ±4.9, y = ±3.9;
robot_0 0.4 m square at the origin facing +x, laser 0.1 m ahead, 181 beams over 180°)."""
import math
import os
import tempfile
import threading
import time
import unittest

import rospy
import rostest
import tf2_ros
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

from fleet_sim.srv import AddBlock, MoveBlock, RemoveBlock, Snapshot

FRONT = 90
TOL = 0.03


def yaw_of(q):
    return 2.0 * math.atan2(q.z, q.w)


class Latest:
    """Keeps the last message of a topic; ``wait_newer`` waits for one stamped after t."""

    def __init__(self, topic, msg_type):
        self.msg = None
        self.cond = threading.Condition()
        rospy.Subscriber(topic, msg_type, self._cb, queue_size=5)

    def _cb(self, msg):
        with self.cond:
            self.msg = msg
            self.cond.notify_all()

    def wait_newer(self, stamp=None, timeout=15.0):
        deadline = time.monotonic() + timeout
        with self.cond:
            while self.msg is None or (stamp is not None and self.msg.header.stamp <= stamp):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError("no message newer than %s within %.0f s" % (stamp, timeout))
                self.cond.wait(left)
            return self.msg


class SimInterfaceTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("sim_interface_test")
        cls.scan = Latest("robot_0/base_scan", LaserScan)
        cls.odom = Latest("robot_0/odom", Odometry)
        cls.truth = Latest("robot_0/base_pose_ground_truth", Odometry)
        cls.clock = Latest("/clock", Clock)
        cls.cmd = rospy.Publisher("robot_0/cmd_vel", Twist, queue_size=1)
        cls.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(30))
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)
        for name in ("add_block", "move_block", "remove_block", "snapshot"):
            rospy.wait_for_service("/fleet_sim/" + name, timeout=20)
        cls.add = rospy.ServiceProxy("/fleet_sim/add_block", AddBlock)
        cls.move = rospy.ServiceProxy("/fleet_sim/move_block", MoveBlock)
        cls.remove = rospy.ServiceProxy("/fleet_sim/remove_block", RemoveBlock)
        cls.snap = rospy.ServiceProxy("/fleet_sim/snapshot", Snapshot)
        cls.scan.wait_newer(timeout=20)
        cls.odom.wait_newer(timeout=20)

    def fresh_scan(self):
        """A scan made after everything done so far (two sim steps later)."""
        now = self.odom.wait_newer().header.stamp
        return self.scan.wait_newer(now + rospy.Duration(0.15))

    def tf(self, parent, child, stamp):
        t = self.tf_buffer.lookup_transform(parent, child, stamp, rospy.Duration(5.0)).transform
        return t.translation.x, t.translation.y, yaw_of(t.rotation)

    def drive_to(self, x_goal):
        deadline = time.monotonic() + 30
        while self.odom.wait_newer().pose.pose.position.x < x_goal:
            self.assertLess(time.monotonic(), deadline, "robot_0 did not reach x = %.2f" % x_goal)
            msg = Twist()
            msg.linear.x = 0.5
            self.cmd.publish(msg)
            time.sleep(0.02)
        # stop publishing: the watchdog must stop the robot on its own
        t0 = self.odom.wait_newer().header.stamp
        odom = self.odom.wait_newer(t0 + rospy.Duration(0.5))
        self.assertEqual(odom.twist.twist.linear.x, 0.0)
        again = self.odom.wait_newer(odom.header.stamp + rospy.Duration(0.3))
        self.assertAlmostEqual(again.pose.pose.position.x, odom.pose.pose.position.x, places=9)
        return again

    def test_1_scan_matches_the_room(self):
        scan = self.fresh_scan()
        self.assertEqual(scan.header.frame_id, "robot_0/base_laser_link")
        self.assertEqual(len(scan.ranges), 181)
        self.assertAlmostEqual(scan.range_max, 30.0, places=5)
        self.assertAlmostEqual(scan.angle_min, -math.pi / 2, places=5)
        self.assertAlmostEqual(scan.angle_increment, math.pi / 180, places=6)
        self.assertAlmostEqual(scan.ranges[FRONT], 4.8, delta=TOL)
        self.assertAlmostEqual(scan.ranges[0], 3.9, delta=TOL)
        self.assertAlmostEqual(scan.ranges[180], 3.9, delta=TOL)

    def test_2_cmd_vel_drives_odom_tf_and_scan_agree(self):
        odom = self.drive_to(1.0)
        x = odom.pose.pose.position.x
        self.assertGreater(x, 1.0)
        self.assertLess(x, 2.5)             # overshoot depends on load; the block test needs room ahead
        self.assertEqual(odom.header.frame_id, "robot_0/odom")
        self.assertEqual(odom.child_frame_id, "robot_0/base_link")
        self.assertAlmostEqual(odom.pose.pose.position.y, 0.0, places=6)
        truth = self.truth.wait_newer(odom.header.stamp - rospy.Duration(0.01))
        self.assertAlmostEqual(truth.pose.pose.position.x, x, places=6)
        # tf chain odom → base_link → base_laser_link, and map → odom (map corner at (-5, -4))
        lx, ly, lyaw = self.tf("robot_0/odom", "robot_0/base_laser_link", odom.header.stamp)
        self.assertAlmostEqual(lx, x + 0.1, places=6)
        self.assertAlmostEqual(ly, 0.0, places=6)
        mx, my, myaw = self.tf("map", "robot_0/base_link", odom.header.stamp)
        self.assertAlmostEqual(mx, x + 5.0, places=6)
        self.assertAlmostEqual(my, 4.0, places=6)
        # the distance to the wall ahead shrank by exactly the distance driven
        scan = self.fresh_scan()
        self.assertAlmostEqual(scan.ranges[FRONT], 4.9 - (x + 0.1), delta=TOL)

    def test_3_block_added_moved_and_removed_is_seen(self):
        x = self.odom.wait_newer().pose.pose.position.x
        res = self.add("crate", x + 2.0, 0.0, 0.0, 0.4, 0.4)
        self.assertTrue(res.success, res.message)
        self.assertAlmostEqual(self.fresh_scan().ranges[FRONT], 2.0 - 0.2 - 0.1, delta=TOL)
        # bad requests: refused with a reason, nothing changes, the simulation goes on
        res = self.move("crate", 20.0, 0.0, 0.0)
        self.assertFalse(res.success)
        self.assertIn("would leave the world", res.message)
        res = self.add("crate", 1.0, 1.0, 0.0, 0.4, 0.4)
        self.assertFalse(res.success)
        self.assertIn("exists already", res.message)
        res = self.add("flat", 1.0, 1.0, 0.0, -0.4, 0.4)
        self.assertFalse(res.success)
        self.assertIn("size must be positive", res.message)
        self.assertAlmostEqual(self.fresh_scan().ranges[FRONT], 1.7, delta=TOL)
        res = self.move("crate", x + 2.0, 3.0, 0.0)
        self.assertTrue(res.success, res.message)
        self.assertAlmostEqual(self.fresh_scan().ranges[FRONT], 4.9 - (x + 0.1), delta=TOL)
        res = self.move("crate", x + 1.0, 0.0, 0.0)
        self.assertTrue(res.success, res.message)
        self.assertAlmostEqual(self.fresh_scan().ranges[FRONT], 0.7, delta=TOL)
        res = self.remove("crate")
        self.assertTrue(res.success, res.message)
        self.assertAlmostEqual(self.fresh_scan().ranges[FRONT], 4.9 - (x + 0.1), delta=TOL)
        res = self.remove("crate")
        self.assertFalse(res.success)
        self.assertIn("no block named 'crate'", res.message)

    def test_4_localisation_offset_and_clock(self):
        stamp = self.odom.wait_newer().header.stamp
        mx, my, myaw = self.tf("map", "robot_1/odom", stamp)
        self.assertAlmostEqual(mx, 5.1, places=6)          # the configured 0.1 m error
        self.assertAlmostEqual(my, 4.0, places=6)
        c1 = self.clock.wait_newer().clock
        time.sleep(0.3)
        self.assertGreater(self.clock.msg.clock, c1)

    def test_5_bad_command_and_snapshot(self):
        bad = Twist()
        bad.linear.x = float("nan")
        self.cmd.publish(bad)
        self.fresh_scan()                                   # still running
        path = os.path.join(tempfile.mkdtemp(prefix="fleet_sim_"), "room.png")
        res = self.snap(path, True, 20.0)
        self.assertTrue(res.success, res.message)
        self.assertGreater(os.path.getsize(path), 100)
        with open(path, "rb") as handle:
            self.assertEqual(handle.read(8), b"\x89PNG\r\n\x1a\n")
        res = self.snap("/nonexistent_dir/x.png", False, 0.0)
        self.assertFalse(res.success)
        self.assertIn("cannot write", res.message)


if __name__ == "__main__":
    rostest.rosrun("fleet_sim", "sim_interface", SimInterfaceTest)
