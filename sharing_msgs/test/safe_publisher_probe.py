#!/usr/bin/python3
"""Child process of test_safe_publisher.py (not a test itself): publishes SharedObstacles with
header stamps 100, 2**32 (cannot be serialised) and 300 s to its own subscriber, and prints the
stamps that arrived as one JSON line. ``--raw`` uses a plain rospy.Publisher instead of a
SafePublisher (and swallows its exception), showing the failure SafePublisher prevents;
``--no-precheck`` lets the bad message reach rospy, exercising SafePublisher's repair."""
import json
import sys
import time

import rospy
from sharing_msgs.msg import SharedObstacle
from sharing_msgs.safe_publisher import SafePublisher


def main():
    raw = "--raw" in sys.argv
    rospy.init_node("safe_publisher_probe", anonymous=True, disable_signals=True)
    received = []
    rospy.Subscriber("probe_topic", SharedObstacle, lambda m: received.append(m.header.stamp.secs))
    make = lambda: rospy.Publisher("probe_topic", SharedObstacle, queue_size=10)  # noqa: E731
    publisher = make() if raw else SafePublisher(make, topic="probe_topic",
                                                 precheck="--no-precheck" not in sys.argv)
    deadline = time.monotonic() + 10
    while publisher.get_num_connections() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    errors = []
    for secs in (100, 2 ** 32, 300):
        msg = SharedObstacle(uuid="stamp %d" % secs)
        msg.header.stamp = rospy.Time(secs)
        try:
            publisher.publish(msg)
        except Exception as err:  # noqa: BLE001 - the raw mode shows what happens after this
            errors.append(type(err).__name__)
        time.sleep(0.2)
    deadline = time.monotonic() + 5
    while len(received) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)  # anything else that was going to arrive
    print(json.dumps({"received": received, "errors": errors,
                      "counted": getattr(publisher, "errors", None),
                      "repaired": getattr(publisher, "repaired", None)}), flush=True)
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    main()
