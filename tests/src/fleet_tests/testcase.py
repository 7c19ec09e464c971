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

    def place(self, robot, goal, timeout):
        """Drives ``robot`` to ``goal`` to set a scene up: a second try when move_base gives up on the way (its controller
        finds no valid control on a starved machine: seen at load 6.8 on robot_1's way to wait_1, 0.6 m short) or has
        not arrived by ``timeout`` (base_local_planner turning in place for ever 0.4 m short of start_1, at load 7;
        the new goal gives it a new plan). Where a robot stands before the test begins is not what the test is of;
        what it then does is, and is asserted."""
        result = robot.go(goal, timeout)
        if not (result[0] and result[1] == "SUCCEEDED"):
            rospy.logwarn("%s: %s not reached (%s %s); sending it again", robot.name, goal, result[1], result[2])
            result = robot.go(goal, timeout)
        self.assert_succeeded(robot, goal, result)

    def reach(self, robot, goal):
        self.assert_succeeded(robot, goal, robot.go(goal, self.GOAL_TIMEOUT), robot.name + "_" + goal)
