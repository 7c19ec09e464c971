"""The common frame of the thesis's Tests 1-3: one rospy node, the two-robot fleet, and failure
messages that name the pictures of both robots' views and the world at the moment of failure."""
import os
import tempfile
import unittest

import rospy

from fleet_tests.scenario import Fleet, load_facility


class FleetTestCase(unittest.TestCase):
    NODE = None            # the rospy node name, e.g. "test1_share"
    PICTURE_PREFIX = None  # picture file names start with it, e.g. "test1"
    GOAL_TIMEOUT = 300.0   # s to reach a goal in reach()

    @classmethod
    def setUpClass(cls):
        rospy.init_node(cls.NODE)
        # The launch's layout (fleet.launch sets /fleet/goals): its goals, corridors and blocks.
        cls.fleet = Fleet(2, load_facility(rospy.get_param("/fleet/goals", None)))
        cls.fleet.wait_ready(120.0)

    def pictures(self, name):
        """Saves both robots' views and the world; returns where, for a failure message."""
        folder = os.environ.get("ROS_TEST_RESULTS_DIR") or tempfile.gettempdir()
        prefix = os.path.join(folder, "%s_%s" % (self.PICTURE_PREFIX, name))
        out = [r.snapshot("%s_%s_view.png" % (prefix, r.name)).message for r in self.fleet.robots]
        out.append(self.fleet.world_snapshot(prefix + "_world.png").message)
        return "; ".join(out)

    def assert_succeeded(self, robot, goal, result, picture_name=None):
        """result: (finished, state, text) of a goal; on failure the pictures are saved and named."""
        finished, state, text = result
        self.assertTrue(finished and state == "SUCCEEDED", "%s did not reach %s: %s %s; %s"
                        % (robot.name, goal, state, text, self.pictures(picture_name or robot.name)))

    def reach(self, robot, goal):
        self.assert_succeeded(robot, goal, robot.go(goal, self.GOAL_TIMEOUT), robot.name + "_" + goal)
