"""The bridge node's start and shutdown, on stand-ins for rospy (no ROS master needed).

A peer withdrawing its footprint while this bridge's node shuts down is no error (its fleet_robots topic is
already closed and nobody is left to tell); the same failure while the node runs still is one: only rospy's
shutdown flag and the publisher differ. A subscriber connecting while the node starts is taken."""
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


def test_a_handler_subscribing_while_the_bridge_node_starts_is_taken(monkeypatch):
    """A subscriber may connect to a publisher as soon as it registers, before the node's constructor has finished:
    fleet_state's listener read ``_started`` before it was set (the handler's node had the same fault, which lost a
    robot's layer its obstacles in a Stage bench run). Each stand-in publisher with a listener has a subscriber
    connect while it is made, as rospy's TCP server may."""
    connected = []

    def connecting_publisher(topic, _msg_class, subscriber_listener=None, **_kwargs):
        if subscriber_listener is not None:
            subscriber_listener.peer_subscribe(topic, None, None)
            connected.append(topic)
        return types.SimpleNamespace(publish=lambda _msg: None, get_num_connections=lambda: 0)
    for name, stand_in in (("Publisher", connecting_publisher), ("Subscriber", lambda *a, **k: None),
                           ("Timer", lambda *a, **k: None), ("get_time", lambda: 10.0)):
        monkeypatch.setattr(node.rospy, name, stand_in)
    made = node.BridgeNode(node.BridgeConfig("robot_0"))
    assert connected == ["fleet_state"] and made._started is False
