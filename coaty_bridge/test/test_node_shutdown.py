"""A peer withdrawing its footprint while this bridge's node shuts down is no error (its fleet_robots topic is
already closed and nobody is left to tell); the same failure while the node runs still is one. The node's method is
called on a stand-in for the node (no ROS master needed): only rospy's shutdown flag and the publisher differ."""
import types

import pytest
import rospy

from coaty_bridge import node


class ClosedTopic:
    def publish(self, _msg):
        raise rospy.ROSException("publish() to a closed topic")


def fake_node():
    fleet = types.SimpleNamespace(forget=lambda robot: True, robots=lambda: [])
    return types.SimpleNamespace(fleet=fleet, config=types.SimpleNamespace(robot_name="robot_0"),
                                 footprint_config=types.SimpleNamespace(robot_timeout=5.0), fleet_robots=ClosedTopic())


@pytest.mark.parametrize("shut_down, requested", [(True, True), (False, True)])
def test_a_withdrawal_during_shutdown_is_not_an_error(monkeypatch, shut_down, requested):
    # (False, True): rospy closes the topics while is_shutdown() is still false, as make demo's teardown showed
    monkeypatch.setattr(rospy, "is_shutdown", lambda: shut_down)
    monkeypatch.setattr(rospy.core, "is_shutdown_requested", lambda: requested)
    monkeypatch.setattr(rospy, "get_time", lambda: 10.0)
    node.BridgeNode._on_fleet_footprint_withdrawn(fake_node(), "robot_2", types.SimpleNamespace(source_id="x"))


def test_a_closed_topic_while_running_is_still_an_error(monkeypatch):
    monkeypatch.setattr(rospy, "is_shutdown", lambda: False)
    monkeypatch.setattr(rospy.core, "is_shutdown_requested", lambda: False)
    monkeypatch.setattr(rospy, "get_time", lambda: 10.0)
    with pytest.raises(rospy.ROSException):
        node.BridgeNode._on_fleet_footprint_withdrawn(fake_node(), "robot_2", types.SimpleNamespace(source_id="x"))
