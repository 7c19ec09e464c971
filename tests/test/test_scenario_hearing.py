"""Which fleet robots a scenario waits for each bridge to hear before it moves a robot: those that bridge hears for
sure at footprint_area_size (the 3 x 3 squares around it), not every robot of the fleet: with 5 m squares, ten robots
in the dead-end world never all hear each other, and the bench timed out waiting for it."""
from types import SimpleNamespace

import pytest

from fleet_tests.scenario import must_hear


def robot(name, x, y):
    return SimpleNamespace(name=name, pose=(x, y))


@pytest.mark.parametrize("dx, heard", [(4.5, True), (4.51, False), (-4.5, True), (-4.51, False)])
def test_a_robot_within_the_square_size_less_half_a_metre_along_each_axis_must_be_heard(dx, heard):
    listener, other = robot("robot_0", 10.0, 10.0), robot("robot_1", 10.0 + dx, 10.0)
    assert (must_hear([listener, other], listener, 5.0) == ["robot_1"]) is heard
    other.pose = (10.0, 10.0 + dx)
    assert (must_hear([listener, other], listener, 5.0) == ["robot_1"]) is heard


def test_without_areas_or_a_pose_every_other_robot_must_be_heard():
    listener, near, far = robot("robot_0", 0.0, 0.0), robot("robot_1", 1.0, 0.0), robot("robot_2", 40.0, 0.0)
    assert must_hear([listener, near, far], listener, 0.0) == ["robot_1", "robot_2"]
    far.pose = None
    assert must_hear([listener, near, far], listener, 5.0) == ["robot_1", "robot_2"]
    listener.pose = None
    assert must_hear([listener, near, far], listener, 5.0) == ["robot_1", "robot_2"]
