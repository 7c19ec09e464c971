"""SafePublisher: one message that cannot be delivered is dropped, logged once and counted, and
the next message still gets through (issue 15: a stamp >= 2**32 s used to leave rospy's
publisher sending garbage, so nothing arrived any more)."""
import json
import logging
import os
import subprocess
import sys

import pytest

from sharing_msgs.safe_publisher import ERROR, OK, PUBLISH_FAILED, SERIALIZATION, WARN, SafePublisher

HERE = os.path.dirname(os.path.abspath(__file__))


class FakeMsg:
    def __init__(self, name, serialisable=True):
        self.name, self.serialisable = name, serialisable

    def serialize(self, buff):
        if not self.serialisable:
            raise ValueError("secs out of range")
        buff.write(self.name.encode())


class FakePublisher:
    """Has no rospy ``impl.buff``: a failed publish makes SafePublisher replace it."""

    def __init__(self, fail_times=0):
        self.sent, self.fail_times, self.unregistered = [], fail_times, False

    def publish(self, msg):
        if self.fail_times:
            self.fail_times -= 1
            raise RuntimeError("broken buffer")
        self.sent.append(msg.name)

    def unregister(self):
        self.unregistered = True

    def get_num_connections(self):
        return 1


def test_unserialisable_message_is_dropped_once_and_the_next_goes_out(caplog):
    made = []
    safe = SafePublisher(lambda: made.append(FakePublisher()) or made[-1], topic="robot_0/from_fleet")
    with caplog.at_level(logging.ERROR, logger="sharing_msgs"):
        assert safe.publish(FakeMsg("a"))
        assert not safe.publish(FakeMsg("bad", serialisable=False), "robot_0: obstacle u1 v2 from robot_1")
        assert safe.publish(FakeMsg("c"))
    assert made[0].sent == ["a", "c"] and len(made) == 1
    assert safe.errors == {SERIALIZATION: 1} and safe.consecutive_errors == 0 and safe.delivered == 2
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "obstacle u1 v2 from robot_1" in lines[0] and "robot_0/from_fleet" in lines[0]


def test_a_publisher_that_failed_is_replaced_and_the_next_message_gets_through():
    made = []
    safe = SafePublisher(lambda: made.append(FakePublisher(fail_times=1 if not made else 0)) or made[-1])
    assert not safe.publish(FakeMsg("lost"))
    assert safe.consecutive_errors == 1 and safe.errors == {PUBLISH_FAILED: 1}
    assert safe.publish(FakeMsg("next"))
    assert len(made) == 2 and made[0].unregistered and made[1].sent == ["next"] and safe.recreated == 1


def test_report_warns_on_new_drops_and_errors_while_every_delivery_fails():
    safe = SafePublisher(FakePublisher, topic="robot_0/from_fleet")
    assert safe.report()[0] == OK
    safe.publish(FakeMsg("bad", serialisable=False))
    level, message, counts = safe.report()
    assert level == WARN and "1 messages dropped" in message and counts == {SERIALIZATION: 1}
    assert safe.report()[0] == OK  # nothing new since
    for _ in range(3):
        safe.publish(FakeMsg("bad", serialisable=False))
    level, message, counts = safe.report()
    assert level == ERROR and "last 4 deliveries failed" in message and counts == {SERIALIZATION: 4}
    assert safe.report()[0] == ERROR  # still failing: still an error
    safe.publish(FakeMsg("good"))
    assert safe.report()[0] == OK


def _probe(env, *args):
    proc = subprocess.run([sys.executable, os.path.join(HERE, "safe_publisher_probe.py")] + list(args),
                          env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=60)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    assert lines, (proc.returncode, proc.stdout[-500:], proc.stderr[-1500:])
    return json.loads(lines[-1])


def test_stamp_repro_through_real_rospy(ros_env):
    """Stamps 100, 2**32, 300: with SafePublisher 100 and 300 arrive; a plain rospy publisher
    (the failure of issue 15) loses 300 as well, which is why SafePublisher exists."""
    safe = _probe(ros_env)
    assert safe["received"] == [100, 300], safe
    assert safe["counted"] == {SERIALIZATION: 1} and safe["errors"] == []
    raw = _probe(ros_env, "--raw")
    assert raw["errors"] and raw["received"] == [100], raw


def test_when_rospy_itself_fails_the_buffer_is_repaired_and_the_next_message_arrives(ros_env):
    """Without the scratch serialisation the bad message reaches rospy and fails there; the
    partial bytes are discarded, subscribers stay connected and 300 still arrives."""
    repaired = _probe(ros_env, "--no-precheck")
    assert repaired["received"] == [100, 300], repaired
    assert repaired["counted"] == {PUBLISH_FAILED: 1} and repaired["repaired"] == 1


def test_a_publish_that_fails_while_the_node_shuts_down_is_no_error(caplog):
    """rospy closes a node's topics before is_shutdown() turns true: a peer's message arriving then is nobody's loss."""
    closing = [False]
    made = []
    safe = SafePublisher(lambda: made.append(FakePublisher(fail_times=2)) or made[-1], topic="robot_0/from_fleet",
                         shutting_down=lambda: closing[0])
    with caplog.at_level(logging.INFO, logger="sharing_msgs"):
        assert not safe.publish(FakeMsg("lost"), "obstacle u1 v2")        # a real failure: counted, ERROR
        closing[0] = True
        assert not safe.publish(FakeMsg("late"), "obstacle u1 v3")        # at shutdown: INFO only
    assert safe.errors == {PUBLISH_FAILED: 1} and safe.not_delivered_at_shutdown == 1
    levels = [(r.levelname, "u1 v3" in r.getMessage()) for r in caplog.records if r.name.startswith("sharing_msgs")]
    assert ("ERROR", False) in levels and ("INFO", True) in levels and ("ERROR", True) not in levels
