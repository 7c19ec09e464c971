"""The one validation of a SharedObstacle (sharing_msgs.obstacle_rules): each rule, its field and
kind, and that whatever passes can be serialised as a ROS message."""
import io
import math

import pytest

from sharing_msgs import obstacle_rules as rules

GOOD = dict(uuid="00000000-0000-4000-8000-000000000001", source="robot_1", version=3, stamp=100.5,
            frame_id="map", deadline=30, rectangle=[0.0, 0.0, 1.0, 1.0], resolution=0.05,
            origin_x=-5.0, origin_y=-2.5, size_x=200, size_y=100, marked=(5, 6), cleared=(7,))

BAD = [  # (changes, field, kind)
    (dict(uuid="x"), "uuid", rules.OUT_OF_RANGE),
    (dict(uuid=""), "uuid", rules.EMPTY),
    (dict(source=""), "source", rules.EMPTY),
    (dict(source="a/b"), "source", rules.OUT_OF_RANGE),
    (dict(source="r" * 257), "source", rules.OUT_OF_RANGE),
    (dict(frame_id="m\0p"), "frame_id", rules.OUT_OF_RANGE),
    # issue 27, item 8: lone UTF-16 surrogates are not UTF-8, so not a ROS string
    (dict(source="robot_\ud800"), "source", rules.OUT_OF_RANGE),
    (dict(frame_id="map\udfff"), "frame_id", rules.OUT_OF_RANGE),
    (dict(version=0), "version", rules.OUT_OF_RANGE),
    (dict(version=2 ** 63), "version", rules.OUT_OF_RANGE),
    (dict(version=2 ** 53), "version", rules.OUT_OF_RANGE),
    (dict(version=1.0), "version", rules.WRONG_TYPE),
    (dict(deadline=0), "deadline", rules.OUT_OF_RANGE),
    (dict(deadline=2 ** 32), "deadline", rules.OUT_OF_RANGE),
    (dict(stamp=float(2 ** 32)), "stamp", rules.OUT_OF_RANGE),
    (dict(stamp=4294967295.5), "stamp", rules.OUT_OF_RANGE),
    (dict(stamp=-0.5), "stamp", rules.OUT_OF_RANGE),
    (dict(stamp=math.inf), "stamp", rules.NON_FINITE),
    (dict(resolution=0.0), "resolution", rules.OUT_OF_RANGE),
    (dict(resolution=1e39), "resolution", rules.NON_FINITE),
    (dict(origin_x=math.nan), "origin_x", rules.NON_FINITE),
    (dict(size_x=0), "size_x", rules.OUT_OF_RANGE),
    (dict(size_x=2 ** 32), "size_x", rules.OUT_OF_RANGE),
    (dict(size_x=2 ** 17, size_y=2 ** 16, marked=(1,), cleared=()), "size_x", rules.OUT_OF_RANGE),
    (dict(rectangle=[0.0, 0.0, 1.0]), "rectangle_shape", rules.WRONG_TYPE),
    (dict(rectangle=[1.0, 0.0, 0.0, 1.0]), "rectangle_shape", rules.OUT_OF_RANGE),
    (dict(rectangle=[-1e39, 0.0, 1.0, 1.0]), "rectangle_shape", rules.NON_FINITE),
    (dict(rectangle=[-1e38, -1e38, 1e38, 1e38]), "rectangle_shape", rules.OUTSIDE_GRID),
    (dict(rectangle=[4.0, 0.0, 5.2, 1.0]), "rectangle_shape", rules.OUTSIDE_GRID),
    (dict(marked=(200 * 100,)), "marked_indexes", rules.OUT_OF_RANGE),
    (dict(cleared=(-1,)), "cleared_indexes", rules.OUT_OF_RANGE),
    (dict(marked=(True,)), "marked_indexes", rules.WRONG_TYPE),
    (dict(size_x=2, size_y=2, rectangle=[-5.0, -2.5, -4.9, -2.4], marked=(0, 1, 2, 3, 0)),
     "marked_indexes", rules.TOO_MANY),
    (dict(marked=(), cleared=()), "marked_indexes", rules.EMPTY),
]


@pytest.mark.parametrize("changes,field,kind", BAD, ids=["%s-%s" % (f, k) for _, f, k in BAD])
def test_each_bad_field_is_named_with_its_kind_and_value(changes, field, kind):
    values = dict(GOOD, **changes)
    with pytest.raises(rules.ObstacleFieldError) as caught:
        rules.check_fleet(**values)
    assert (caught.value.field, caught.value.kind) == (field, kind)
    assert field in str(caught.value)


def test_good_message_passes_and_a_rectangle_may_reach_one_cell_past_the_edge():
    rules.check_fleet(**GOOD)
    rules.check_fleet(**dict(GOOD, rectangle=[-5.05, -2.55, 5.05, 2.55]))
    rules.check_fleet(**dict(GOOD, stamp=4294967294.999, version=2 ** 53 - 1, deadline=2 ** 32 - 1))


def test_a_proposal_passes_the_value_level_but_not_the_fleet_level():
    proposal = dict(GOOD, uuid="", version=0, deadline=0)
    rules.check_values(**proposal)
    with pytest.raises(rules.ObstacleFieldError):
        rules.check_fleet(**proposal)


def test_whatever_passes_serialises_as_a_ros_message():
    """The point of the rules: a checked message cannot break a publisher."""
    msg_module = pytest.importorskip("sharing_msgs.msg", reason="workspace not built/sourced")
    import rospy
    for values in (GOOD, dict(GOOD, stamp=4294967294.999, version=2 ** 53 - 1,
                              deadline=2 ** 32 - 1, rectangle=[-5.05, -2.55, 5.05, 2.55])):
        rules.check_fleet(**values)
        msg = msg_module.SharedObstacle()
        msg.header.stamp = rospy.Time.from_sec(values["stamp"])
        msg.uuid, msg.source, msg.version = values["uuid"], values["source"], values["version"]
        msg.deadline, msg.rectangle_shape = values["deadline"], values["rectangle"]
        msg.resolution, msg.origin_x, msg.origin_y = values["resolution"], values["origin_x"], values["origin_y"]
        msg.size_x, msg.size_y = values["size_x"], values["size_y"]
        msg.marked_indexes, msg.cleared_indexes = list(values["marked"]), list(values["cleared"])
        msg.serialize(io.BytesIO())
