"""The handler node while it starts: a subscriber may connect to a publisher as soon as the publisher registers
(the layer of a move_base started first, a bench's probe), before the node's constructor has finished. The
publishers' subscribe listeners then ran on a half-built node: "'HandlerNode' object has no attribute 'handler'",
the subscriber's connection failed, and that subscriber never got an obstacle (a 5-robot bench run on Stage: one
robot's layer input never connected, its latency pairs all lost).

rospy's Publisher, Subscriber, Service and Timer are replaced here by stand-ins (no master runs in a pytest):
each publisher with a listener has a subscriber connect while it is being made, as rospy's TCP server may."""
import pytest

rospy = pytest.importorskip("rospy", reason="rospy (Debian's ROS 1) not installed")
try:
    from sharing_handler_py import node
except ImportError as err:   # sharing_msgs' generated messages: the workspace is not built or not sourced
    pytest.skip("sharing_handler_py.node not importable (%s): make build, then source scripts/env.sh" % err,
                allow_module_level=True)


class _ConnectingPublisher:
    """A rospy.Publisher whose first subscriber connects while it registers."""
    served = []

    def __init__(self, topic, msg_class, queue_size=None, latch=False, subscriber_listener=None, **_kwargs):
        self.topic = topic
        if subscriber_listener is not None:
            subscriber_listener.peer_subscribe(topic, self.publish,
                                               lambda msg: _ConnectingPublisher.served.append((topic, msg)))

    def publish(self, msg):
        pass

    def get_num_connections(self):
        return 0


@pytest.fixture
def starting_node(monkeypatch):
    _ConnectingPublisher.served = []
    for name, stand_in in (("Publisher", _ConnectingPublisher), ("Subscriber", lambda *a, **k: None),
                           ("Service", lambda *a, **k: None), ("Timer", lambda *a, **k: None),
                           ("get_time", lambda: 100.0), ("get_namespace", lambda: "/robot_0/"),
                           ("get_param", lambda name, default=None: default),
                           ("loginfo", lambda *a, **k: None), ("logwarn", lambda *a, **k: None)):
        monkeypatch.setattr(node.rospy, name, stand_in)
    monkeypatch.setattr(node.rospy.Time, "now", staticmethod(lambda: rospy.Time.from_sec(100.0)))
    return node


def test_a_subscriber_connecting_while_the_node_starts_is_served(starting_node):
    made = starting_node.HandlerNode(starting_node.read_params())
    assert made.handler.obstacles() == []
    topics = {topic for topic, _msg in _ConnectingPublisher.served}
    # nothing held yet: the layer and the bridge get nothing, the markers subscriber the (empty) markers
    assert topics == {"fleet_obstacle_markers"}, topics
