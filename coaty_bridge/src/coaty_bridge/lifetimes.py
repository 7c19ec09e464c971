"""Lifetimes on the wire (issue 15, item 2). Imports neither paho nor rospy.

An obstacle's ``deadline`` on the wire is the lifetime it has **left at the moment the message
is sent**, in whole seconds rounded down. A receiver expires it ``deadline`` seconds after it
arrives, so every copy expires when the original does, plus the transit time, never later
because of rounding. Whoever holds a message for a while before sending it (the offline queue,
an answer to a Discover made from the robot's list) ages it by the time it was held; a message
whose lifetime ran out while held is not sent at all.

Why relative and not absolute deadlines: robots need no synchronised clocks (their ROS time may
even be simulated), and a Coaty JS peer reads the field the way the thesis defined it.
"""
import dataclasses
import math

MIN_DEADLINE = 1  # a deadline of 0 is refused everywhere: it would expire on arrival


def aged_deadline(deadline, elapsed):
    """Seconds left after `elapsed` more seconds, rounded down; None when less than 1 s is left."""
    left = math.floor(deadline - max(0.0, elapsed))
    return left if left >= MIN_DEADLINE else None


def aged(update, elapsed):
    """The ObstacleUpdate as it must be sent `elapsed` seconds after its deadline was valid,
    or None when it has expired meanwhile."""
    left = aged_deadline(update.deadline, elapsed)
    if left is None:
        return None
    return update if left == update.deadline else dataclasses.replace(update, deadline=left)
