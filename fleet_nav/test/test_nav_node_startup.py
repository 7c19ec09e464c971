"""fleet_nav's start-up with a bad parameter: one fatal line naming robot, parameter and value, exit 1.

rospy is replaced by a stand-in for the few calls main() makes before it would need a master, so
this runs without roscore.
"""
import os

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))

pytest.importorskip("rospy")
pytest.importorskip("fleet_nav.nav_core")
node = pytest.importorskip("fleet_nav.node")


class FakeRospy:
    def __init__(self, tree):
        self.tree = tree
        self.fatal = []
        self.info = []

    def install(self, monkeypatch):
        r = node.rospy
        monkeypatch.setattr(r, "init_node", lambda *a, **k: None)
        monkeypatch.setattr(r, "get_namespace", lambda: "/robot_3/")
        monkeypatch.setattr(r, "get_param", lambda name, default=None: self.tree if name == "~" else default)
        monkeypatch.setattr(r, "logfatal", lambda fmt, *args: self.fatal.append(fmt % args))
        monkeypatch.setattr(r, "loginfo", lambda fmt, *args: self.info.append(fmt % args if args else fmt))

        def no_master(*_a, **_k):
            raise AssertionError("main() reached ROS communication with a bad parameter")
        monkeypatch.setattr(r, "Publisher", no_master)
        monkeypatch.setattr(r, "Subscriber", no_master)
        monkeypatch.setattr(node.tf2_ros, "Buffer", no_master)


@pytest.mark.parametrize("tree,words", [
    ({"global_costmap": {"inflation_radius": -0.5}}, ["inflation_radius", "-0.5"]),
    ({"global_costmap": {"footprint": "[[0, 0], [1, 1]]"}}, ["footprint", "[[0, 0], [1, 1]]"]),
    ({"controller_frequency": "fast"}, ["controller_frequency", "fast"]),
    ({"TrajectoryPlannerROS": {"max_vel_x": 0.0}}, ["max_vel_x", "0.0"]),
    ({"planner_frequency": 400.0}, ["planner_frequency", "400"]),
])
def test_bad_parameter_stops_the_node_with_its_name_and_value(monkeypatch, tree, words):
    fake = FakeRospy(tree)
    fake.install(monkeypatch)
    with pytest.raises(SystemExit) as exit_info:
        node.main()
    assert exit_info.value.code == 1
    assert len(fake.fatal) == 1
    line = fake.fatal[0]
    assert "robot_3" in line and "cannot start" in line
    for word in words:
        assert word in line, line


def test_good_parameters_get_past_the_parameter_check(monkeypatch):
    fake = FakeRospy({"global_costmap": {"inflation_radius": 0.4}, "unknown_thing": 1})
    fake.install(monkeypatch)
    # With good values main() goes on to ROS communication, which the stand-in refuses.
    with pytest.raises(AssertionError, match="reached ROS communication"):
        node.main()
    assert fake.fatal == []
    assert any("unknown_thing" in line for line in fake.info), "unused parameters are listed at start-up"
