#!/usr/bin/python3
"""Child process of test_publisher_links.py (not a test itself).

``pub``: publishes std_msgs/String on /link_probe at 20 Hz until killed.
``sub``: subscribes to /link_probe with the first publisherUpdate for it dropped. That is what
rospy's registration race does to a subscriber (the master's update lost behind the stale
registration reply); the race itself cannot be forced on demand, so the probe drops the update
at the same place. Prints "ready" once subscribed, then one JSON line: messages received within
``--wait`` s, and how many updates were dropped. ``--no-watch``: without PublisherLinkWatch.
"""
import argparse
import json
import sys
import time


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("mode", choices=("pub", "sub"))
    parser.add_argument("--no-watch", action="store_true")
    parser.add_argument("--wait", type=float, default=30.0)
    args = parser.parse_args()
    import rospy
    from std_msgs.msg import String
    if args.mode == "pub":
        rospy.init_node("link_probe_pub", disable_signals=True)
        publisher = rospy.Publisher("/link_probe", String, queue_size=10)
        while not rospy.is_shutdown():
            publisher.publish(String(data="hi"))
            time.sleep(0.05)
        return

    from rospy.impl import masterslave
    original = masterslave.ROSHandler.publisherUpdate
    dropped = []

    def drop_first_update(self, caller_id, topic, publishers):
        if topic == "/link_probe" and publishers and not dropped:
            dropped.append(list(publishers))
            return 1, "", 0
        return original(self, caller_id, topic, publishers)

    masterslave.ROSHandler.publisherUpdate = drop_first_update
    rospy.init_node("link_probe_sub", disable_signals=True)
    received = []
    rospy.Subscriber("/link_probe", String, lambda m: received.append(m.data))
    watch = None
    if not args.no_watch:
        from sharing_msgs.publisher_links import PublisherLinkWatch
        watch = PublisherLinkWatch("link_probe_sub", period=0.5).start()
    print("ready", flush=True)
    deadline = time.monotonic() + args.wait
    while not received and time.monotonic() < deadline:
        time.sleep(0.05)
    if received and watch:
        time.sleep(3 * watch.period)  # the next checks see the link and count it mended
    print(json.dumps({"received": len(received), "dropped": len(dropped),
                      "mended": watch.book.mended if watch else None}), flush=True)
    rospy.signal_shutdown("done")


if __name__ == "__main__":
    sys.exit(main())
