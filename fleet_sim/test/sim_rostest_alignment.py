#!/usr/bin/python3
"""rostest node for sim_willow_alignment.test: Willow scans land on /map walls through tf."""
import math
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from nav_msgs.msg import OccupancyGrid
from sensor_msgs.msg import LaserScan

from fleet_sim.srv import RemoveBlock


def yaw_of(q):
    return 2.0 * math.atan2(q.z, q.w)


class WillowAlignmentTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("sim_willow_alignment_test")
        cls.lock = threading.Lock()
        cls.map = None
        cls.scans = {}
        rospy.Subscriber("/map", OccupancyGrid, cls._on_map, queue_size=1)
        for i in range(2):
            rospy.Subscriber("robot_%d/base_scan" % i, LaserScan, cls._on_scan, callback_args=i, queue_size=2)
        cls.tf_buffer = tf2_ros.Buffer(cache_time=rospy.Duration(30))
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)
        rospy.wait_for_service("/fleet_sim/remove_block", timeout=20)
        cls.remove = rospy.ServiceProxy("/fleet_sim/remove_block", RemoveBlock)

    @classmethod
    def _on_map(cls, msg):
        with cls.lock:
            cls.map = msg

    @classmethod
    def _on_scan(cls, msg, i):
        with cls.lock:
            cls.scans[i] = msg

    def wait_for(self, what, timeout=20.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                value = what()
            if value is not None:
                return value
            time.sleep(0.05)
        self.fail("timed out waiting")

    def tf(self, parent, child, stamp):
        t = self.tf_buffer.lookup_transform(parent, child, stamp, rospy.Duration(5.0)).transform
        return t.translation.x, t.translation.y, yaw_of(t.rotation)

    def test_scans_line_up_with_the_map(self):
        grid = self.wait_for(lambda: self.map)
        self.assertEqual((grid.info.width, grid.info.height), (584, 526))
        self.assertAlmostEqual(grid.info.resolution, 0.1, places=6)
        occ = np.array(grid.data, dtype=np.int8).reshape(grid.info.height, grid.info.width) == 100
        near = occ.copy()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                near |= np.roll(np.roll(occ, dr, axis=0), dc, axis=1)
        res = self.remove("block:0")          # the red block is not in the map
        self.assertTrue(res.success, res.message)
        after = self.wait_for(lambda: self.scans.get(0)).header.stamp + rospy.Duration(0.25)
        for i in range(2):
            scan = self.wait_for(lambda: self.scans.get(i) if i in self.scans and
                                 self.scans[i].header.stamp > after else None)
            self.assertEqual(len(scan.ranges), 1081)
            self.assertAlmostEqual(scan.range_max, 30.0, places=5)     # the world's range_max
            sx, sy, syaw = self.tf("map", scan.header.frame_id, scan.header.stamp)
            ox, oy, _ = self.tf("map", "robot_%d/base_link" % (1 - i), scan.header.stamp)
            r = np.array(scan.ranges, dtype=np.float64)
            a = syaw + scan.angle_min + scan.angle_increment * np.arange(len(r))
            keep = r < scan.range_max
            xs, ys = sx + r[keep] * np.cos(a[keep]), sy + r[keep] * np.sin(a[keep])
            wall = np.hypot(xs - ox, ys - oy) > 0.6          # beams that hit the other robot
            xs, ys = xs[wall], ys[wall]
            self.assertGreater(len(xs), 500)
            col = np.floor((xs - grid.info.origin.position.x) / grid.info.resolution).astype(int)
            row = np.floor((ys - grid.info.origin.position.y) / grid.info.resolution).astype(int)
            inside = (col >= 0) & (col < grid.info.width) & (row >= 0) & (row < grid.info.height)
            hits = np.zeros(len(xs), dtype=bool)
            hits[inside] = near[row[inside], col[inside]]
            rospy.loginfo("robot_%d: %.1f%% of %d endpoints within a cell of a map wall",
                          i, 100 * hits.mean(), len(xs))
            self.assertGreaterEqual(hits.mean(), 0.95)
        # the Willow floorplan is rotated: map→odom is the -90° turn fake_localization needs
        mx, my, myaw = self.tf("map", "robot_0/odom", rospy.Time(0))
        self.assertAlmostEqual(myaw, -math.pi / 2, places=6)
        self.assertAlmostEqual(mx, 0.0, places=6)
        self.assertAlmostEqual(my, 0.0, places=6)


if __name__ == "__main__":
    rostest.rosrun("fleet_sim", "sim_willow_alignment", WillowAlignmentTest)
