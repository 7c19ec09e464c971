"""The stage_ros messages the node publishes, built without a ROS master."""
import math

import pytest
import rospy

import sim_test_helpers as h
from fleet_sim.sim import LocalisationError, Simulation
from fleet_sim.errors import SimError
from fleet_sim.sim_node import SimNode, _number_param, build_messages, stage_ros_order
from fleet_sim.world import load_world


def _yaw(q):
    return 2.0 * math.atan2(q.z, q.w)


def _tfs(out):
    return {(t.header.frame_id, t.child_frame_id): t.transform for t in out.tf.transforms}


def test_room_messages_have_stage_ros_names_and_geometry():
    sim = h.room_sim(localisation={1: LocalisationError(dx=0.2)})
    sim.set_cmd_vel(0, 0.5, 0.0, 0.1)
    sim.step()
    names = [SimNode._prefix("robot_%d", i) for i in range(2)]
    out = build_messages(sim, names, rospy.Time.from_sec(sim.time), True)
    odom = out.odoms[0]
    assert (odom.header.frame_id, odom.child_frame_id) == ("robot_0/odom", "robot_0/base_link")
    assert odom.header.stamp.to_sec() == pytest.approx(0.1)
    assert odom.pose.pose.position.x == pytest.approx(sim.robots[0].pose[0])
    assert _yaw(odom.pose.pose.orientation) == pytest.approx(0.01)
    assert odom.twist.twist.linear.x == 0.5 and odom.twist.twist.angular.z == 0.1
    ((k, scan),) = out.scans[0]
    assert k == 0 and scan.header.frame_id == "robot_0/base_laser_link"
    assert scan.angle_min == pytest.approx(-math.pi / 2) and scan.angle_max == pytest.approx(math.pi / 2)
    assert scan.angle_increment == pytest.approx(math.pi / 180)
    assert (scan.range_min, scan.range_max) == (0.0, 30.0)
    assert scan.ranges == pytest.approx(sim.robots[0].scans[0].tolist())
    tfs = _tfs(out)
    assert set(tfs) == {("robot_0/odom", "robot_0/base_link"), ("robot_0/base_link", "robot_0/base_laser_link"),
                        ("map", "robot_0/odom"), ("robot_1/odom", "robot_1/base_link"),
                        ("robot_1/base_link", "robot_1/base_laser_link"), ("map", "robot_1/odom")}
    assert tfs[("robot_0/base_link", "robot_0/base_laser_link")].translation.x == pytest.approx(0.1)
    # stage_ros's height: the robot model's size z plus the ranger's pose z (costmap_2d filters by height)
    spec = sim.robots[0].spec
    assert tfs[("robot_0/base_link", "robot_0/base_laser_link")].translation.z == pytest.approx(
        spec.height + spec.rangers[0].z)
    assert tfs[("map", "robot_0/odom")].translation.x == pytest.approx(5.0)
    assert tfs[("map", "robot_1/odom")].translation.x == pytest.approx(5.2)     # the configured error
    no_scans = build_messages(sim, names, rospy.Time.from_sec(sim.time), False)
    assert no_scans.scans == [[], []] and len(no_scans.tf.transforms) == 6


def test_several_rangers_and_no_prefix_like_stage_ros():
    sim = Simulation(load_world(h.SIMPLE, log=lambda *a: None), raycast=h.raycaster())
    out = build_messages(sim, ["", "r1/"], rospy.Time(0), True)
    assert [s.header.frame_id for _, s in out.scans[0]] == ["base_laser_link_0", "base_laser_link_1"]
    assert [len(s.ranges) for _, s in out.scans[0]] == [1, 180]
    assert ("odom", "base_link") in _tfs(out) and ("r1/odom", "r1/base_link") in _tfs(out)
    assert SimNode._prefix("", 0) == "" and SimNode._prefix("agv", 3) == "agv3/"


def test_willow_map_to_odom_is_the_minus_90_degree_turn():
    sim = Simulation(load_world(h.WILLOW, log=lambda *a: None), raycast=h.raycaster())
    out = build_messages(sim, ["robot_0/", "robot_1/"], rospy.Time(0), False)
    t = _tfs(out)[("map", "robot_0/odom")]
    assert _yaw(t.rotation) == pytest.approx(-math.pi / 2)
    assert (t.translation.x, t.translation.y) == pytest.approx((0.0, 0.0), abs=1e-9)


def test_map_to_odom_is_stamped_ahead_by_the_transform_tolerance_as_fake_localization_does():
    sim = h.room_sim()
    sim.step()
    stamp = rospy.Time.from_sec(sim.time)
    out = build_messages(sim, ["robot_0/", "robot_1/"], stamp, False, transform_tolerance=0.1)
    for t in out.tf.transforms:
        ahead = (t.header.stamp - stamp).to_sec()
        if t.header.frame_id == "map":
            assert ahead == pytest.approx(0.1), t.child_frame_id
        else:
            assert ahead == 0.0, (t.header.frame_id, t.child_frame_id)
    assert [o.header.stamp for o in out.odoms] == [stamp, stamp]


def test_a_step_is_published_in_stageros_order_with_the_clock_last():
    class Pubs:
        odom_pubs, gt_pubs = ["odom0", "odom1"], ["gt0", "gt1"]
        scan_pubs = [["scan0"], ["scan1"]]
        tf_pub, clock_pub = "tf", "clock"
    sim = h.room_sim()
    sim.step()
    stamp = rospy.Time.from_sec(sim.time)
    out = build_messages(sim, ["robot_0/", "robot_1/"], stamp, True)
    order = list(stage_ros_order(Pubs, out, stamp))
    assert [pub for pub, _ in order] == ["odom0", "gt0", "scan0", "odom1", "gt1", "scan1", "tf", "clock"]
    assert order[-1][1].clock == stamp and order[-2][1] is out.tf


@pytest.mark.parametrize("value", [-0.1, float("nan"), "soon", None])
def test_a_bad_transform_tolerance_is_refused_naming_it(monkeypatch, value):
    monkeypatch.setattr(rospy, "get_param", lambda name, default=None: value)
    with pytest.raises(SimError, match=r"~transform_tolerance"):
        _number_param("~transform_tolerance", 0.1, minimum=0.0)
