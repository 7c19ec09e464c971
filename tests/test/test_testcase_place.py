"""FleetTestCase.place: setting a scene up tries a robot's goal twice (move_base's controller may give up on a starved
machine before the test proper begins), and fails, naming the robot and goal, when the second try fails too. No ROS
master: a stand-in robot returns the goal results."""
import pytest

from fleet_tests import testcase


class StandInRobot:
    name = "robot_1"

    def __init__(self, results):
        self.results, self.sent = list(results), []

    def go(self, goal, timeout):
        self.sent.append(goal)
        return self.results.pop(0)


class Case(testcase.FleetTestCase):
    __test__ = False   # a stand-in, not a test of its own (its setUpClass would start a node)

    def runTest(self):
        pass

    def pictures(self, name):
        return "pictures of %s" % name


ABORTED = (True, "ABORTED", "Failed to find a valid control. Even after executing recovery behaviors.")
SUCCEEDED = (True, "SUCCEEDED", "")


def test_a_goal_given_up_once_is_sent_again():
    robot = StandInRobot([ABORTED, SUCCEEDED])
    Case().place(robot, "wait_1", 120.0)
    assert robot.sent == ["wait_1", "wait_1"]


def test_a_goal_not_reached_in_time_is_sent_again():
    robot = StandInRobot([(False, "ACTIVE", "This goal has been accepted by the simple action server"), SUCCEEDED])
    Case().place(robot, "start_1", 200.0)
    assert robot.sent == ["start_1", "start_1"]


def test_a_goal_reached_at_once_is_sent_once():
    robot = StandInRobot([SUCCEEDED])
    Case().place(robot, "wait_1", 120.0)
    assert robot.sent == ["wait_1"]


def test_a_goal_given_up_twice_fails_naming_robot_and_goal():
    robot = StandInRobot([ABORTED, (False, "ACTIVE", "timed out")])
    with pytest.raises(AssertionError, match="robot_1 did not reach wait_1: ACTIVE timed out"):
        Case().place(robot, "wait_1", 120.0)
