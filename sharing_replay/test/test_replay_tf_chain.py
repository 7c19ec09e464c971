"""The replay's transform chain: tf2's answers where tf2 has them, and explicit gap reports."""
import math

import pytest
import rospy
from geometry_msgs.msg import TransformStamped

from sharing_replay.errors import TransformError
from sharing_replay.tf_chain import TransformChain, yaw_of


def tf(t, parent, child, x=0.0, y=0.0, yaw=0.0, z=0.0):
    m = TransformStamped()
    m.header.stamp = rospy.Time.from_sec(t)
    m.header.frame_id, m.child_frame_id = parent, child
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = x, y, z
    m.transform.rotation.z, m.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return m


def stage_chain():
    """The recorded bag's tree: map -> odom (-90 deg) -> base_footprint -> base_link -> base_laser_link."""
    c = TransformChain(max_gap=1.0, tolerance=0.2)
    c.add(tf(0.0, "base_link", "base_laser_link", x=0.275, z=0.25), static=True)
    for i in range(11):
        t = 10.0 + 0.1 * i
        c.add(tf(t, "/map", "odom", yaw=-math.pi / 2))
        c.add(tf(t, "odom", "base_footprint", x=-21.2 + i * 0.1, y=16.0, yaw=math.pi / 2))
        c.add(tf(t, "base_footprint", "base_link"))
    return c


def test_composition_matches_the_recorded_bag_geometry():
    c = stage_chain()
    tr = c.lookup("map", "base_laser_link", 10.0)
    # map (x, y) = Stage (y, -x): the robot at Stage (-21.2, 16.0) facing +y is at map (16.0, 21.2) facing +x.
    assert tr[:3] == pytest.approx((16.0 + 0.275, 21.2, 0.25))
    assert yaw_of(tr) == pytest.approx(0.0, abs=1e-9)
    # The inverse direction and a lookup between two leaves.
    inv = c.lookup("base_laser_link", "map", 10.0)
    assert inv[:3] == pytest.approx((-16.275, -21.2, -0.25))
    back = c.lookup("odom", "base_laser_link", 10.0)
    assert back[:2] == pytest.approx((-21.2, 16.0 + 0.275))


def test_interpolation_between_samples():
    c = stage_chain()
    tr = c.lookup("map", "base_link", 10.05)
    # odom x goes -21.2 -> -21.1 between 10.0 and 10.1: half way, map y = -odom x.
    assert tr[1] == pytest.approx(21.15)


def test_gap_extrapolation_and_unconnected_are_reported():
    c = stage_chain()
    c.add(tf(13.0, "map", "odom", yaw=-math.pi / 2))    # map->odom jumps 1.9 s after its last sample
    with pytest.raises(TransformError) as err:
        c.lookup("map", "base_link", 12.0)
    assert err.value.reason in ("tf_gap",)
    with pytest.raises(TransformError) as err:
        c.lookup("map", "base_link", 9.0)
    assert err.value.reason == "tf_extrapolation"
    # Within the tolerance the nearest sample is used (fake_localization's future-dating).
    assert c.lookup("map", "base_link", 9.85)[1] == pytest.approx(21.2)
    with pytest.raises(TransformError) as err:
        c.lookup("map", "robot_1/base_laser_link", 10.0)
    assert err.value.reason == "tf_unconnected"
    assert not c.ready("map", "robot_1/base_laser_link", 10.0)
    assert c.ready("map", "base_laser_link", 10.0) and not c.ready("map", "base_laser_link", 10.5 + 3)


def test_bad_transforms_are_rejected_and_counted():
    c = TransformChain()
    bad = tf(1.0, "map", "odom")
    bad.transform.rotation.w = 0.0
    assert not c.add(bad)
    nan = tf(1.0, "map", "odom", x=float("nan"))
    assert not c.add(nan)
    assert not c.add(tf(1.0, "map", "map"))
    assert c.rejected == 3 and c.frames() == []
    with pytest.raises(ValueError):
        TransformChain(max_gap=0.0)
