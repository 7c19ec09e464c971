"""The bag's other robots, placed for the exclusion: pose from tf, shape from a recorded footprint or the
parameters, the last pose held for robot_timeout."""
import math

import numpy as np
import pytest
import rospy
from geometry_msgs.msg import Point32, PolygonStamped

from sharing_replay.other_robots import OtherRobots, place
from sharing_replay.tf_chain import TransformChain
from test_replay_tf_chain import tf

SQUARE = [(-0.3, -0.3), (-0.3, 0.3), (0.3, 0.3), (0.3, -0.3)]


def chain_with(robot, samples):
    """map -> <robot>/base_link at (t, x, y, yaw) samples."""
    c = TransformChain(max_gap=1.0, tolerance=0.2)
    for t, x, y, yaw in samples:
        c.add(tf(t, "map", robot + "/base_link", x=x, y=y, yaw=yaw))
    return c


def footprint(stamp, points, frame="map"):
    msg = PolygonStamped()
    msg.header.stamp = rospy.Time.from_sec(stamp)
    msg.header.frame_id = frame
    msg.polygon.points = [Point32(x, y, 0.0) for x, y in points]
    return msg


def test_place_rotates_then_moves():
    placed = place(np.array([[1.0, 0.0], [0.0, 2.0]]), 10.0, 5.0, math.pi / 2)
    assert placed == pytest.approx(np.array([[10.0, 6.0], [8.0, 5.0]]))


def test_robots_are_placed_at_the_scan_stamp_and_never_for_themselves():
    c = chain_with("robot_1", [(10.0, 2.0, 3.0, 0.0), (11.0, 3.0, 3.0, 0.0)])
    others = OtherRobots(c, "map", {"robot_0": "robot_0/base_link", "robot_1": "robot_1/base_link"}, SQUARE, 3.0)
    placed = others.placed(10.5, "robot_0")
    assert [name for name, _fp, _t in placed] == ["robot_1"]
    name, polygon, stamp = placed[0]
    assert stamp == 10.5
    assert polygon.mean(axis=0) == pytest.approx((2.5, 3.0))       # interpolated half way
    assert others.unplaced == {}
    assert others.placed(10.5, "robot_1") == []                     # robot_0 has no pose at all
    assert others.unplaced == {"robot_0": 1}


@pytest.mark.parametrize("age, held", [(2.99, True), (3.01, False)])
def test_the_last_pose_is_held_for_robot_timeout(age, held):
    # tf for robot_1 ends at 11.0; a lookup is then answered up to the chain's tolerance (0.2 s) and
    # beyond it from the last pose found, for robot_timeout (3 s) after that pose's stamp.
    c = chain_with("robot_1", [(10.0, 2.0, 3.0, 0.0), (11.0, 3.0, 3.0, 0.0)])
    others = OtherRobots(c, "map", {"robot_0": "robot_0/base_link", "robot_1": "robot_1/base_link"}, SQUARE, 3.0)
    assert others.placed(11.0, "robot_0")
    placed = others.placed(11.0 + age, "robot_0")
    assert bool(placed) == held
    if held:
        assert placed[0][1].mean(axis=0) == pytest.approx((3.0, 3.0))


def test_timeout_zero_holds_the_last_pose_for_ever():
    c = chain_with("robot_1", [(10.0, 2.0, 3.0, 0.0), (11.0, 3.0, 3.0, 0.0)])
    others = OtherRobots(c, "map", {"robot_0": "robot_0/base_link", "robot_1": "robot_1/base_link"}, SQUARE, 0.0)
    others.placed(11.0, "robot_0")
    assert others.placed(1000.0, "robot_0")


def test_recorded_footprint_gives_the_shape_relative_to_the_pose():
    # robot_1 at (2, 3) facing +y; its recorded footprint is a 1 x 0.4 m rectangle along its heading.
    c = chain_with("robot_1", [(10.0, 2.0, 3.0, math.pi / 2), (11.0, 2.0, 4.0, math.pi / 2)])
    others = OtherRobots(c, "map", {"robot_0": "robot_0/base_link", "robot_1": "robot_1/base_link"}, SQUARE, 3.0)
    assert others.footprint_source("robot_1") == "parameters"
    assert others.on_footprint("robot_1", footprint(10.0, [(1.8, 2.5), (2.2, 2.5), (2.2, 3.5), (1.8, 3.5)])) is None
    assert others.footprint_source("robot_1") == "recorded footprint"
    shape = others.shapes["robot_1"]
    assert shape == pytest.approx(np.array([[-0.5, 0.2], [-0.5, -0.2], [0.5, -0.2], [0.5, 0.2]]))
    # At 11.0 the robot is one metre further up: the shape moves with it.
    polygon = others.placed(11.0, "robot_0")[0][1]
    assert polygon.min(axis=0) == pytest.approx((1.8, 3.5)) and polygon.max(axis=0) == pytest.approx((2.2, 4.5))


def test_a_footprint_before_its_tf_waits_and_a_bad_one_is_counted():
    c = chain_with("robot_1", [(10.0, 2.0, 3.0, 0.0), (11.0, 3.0, 3.0, 0.0)])
    others = OtherRobots(c, "map", {"robot_0": "robot_0/base_link", "robot_1": "robot_1/base_link"}, SQUARE, 3.0)
    assert others.on_footprint("robot_1", footprint(5.0, SQUARE)) is None       # no tf yet: not used, no fault
    assert others.shapes == {} and others.bad_footprints == {}
    line = others.on_footprint("robot_1", footprint(10.0, [(float("nan"), 0.0), (1.0, 1.0), (0.0, 1.0)]))
    assert "robot_1" in line and others.bad_footprints == {"robot_1": 1} and others.shapes == {}
    assert others.on_footprint("robot_7", footprint(10.0, SQUARE)) is None        # not a robot of the bag
