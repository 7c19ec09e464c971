#!/usr/bin/python3
"""ROS side of test_fleet_crashes.py (not a test file itself): watches a running fleet.launch.

Usage: crash_probe.py robot_0 robot_1 ...
Prints JSON lines:
  {"event": "list", "robot": r, "obstacles": {uuid: [cells...]}, "sources": {uuid: source}}  every shared_obstacle_list
  {"event": "pose", "robot": r, "x": x, "y": y}                   base_pose_ground_truth, at most once per s
  {"event": "reply", "id": i, "success": b, "message": m, "uuid": u}   answer to a command
  {"event": "ready"}
Commands (one JSON object per stdin line):
  {"cmd": "add", "id": i, "robot": r, "rect": [min_x, min_y, max_x, max_y]}   call <robot>/add_obstacle
"""
import json
import sys
import threading
import time

import rospy
from nav_msgs.msg import Odometry
from sharing_msgs.msg import SharedObstacleArray
from sharing_msgs.srv import AddObstacle

_out = threading.Lock()


def emit(event):
    with _out:
        sys.stdout.write(json.dumps(event) + "\n")
        sys.stdout.flush()


def main():
    rospy.init_node("crash_probe", anonymous=True, disable_signals=True)
    last_pose = {}
    for robot in sys.argv[1:]:
        rospy.Subscriber("/%s/shared_obstacle_list" % robot, SharedObstacleArray, lambda msg, r=robot: emit(
            {"event": "list", "robot": r, "obstacles": {o.uuid: sorted(o.marked_indexes) for o in msg.obstacles},
             "sources": {o.uuid: o.source for o in msg.obstacles}}))

        def on_pose(msg, r=robot):
            now = time.monotonic()
            if now - last_pose.get(r, 0.0) >= 1.0:
                last_pose[r] = now
                emit({"event": "pose", "robot": r, "x": msg.pose.pose.position.x, "y": msg.pose.pose.position.y})
        rospy.Subscriber("/%s/base_pose_ground_truth" % robot, Odometry, on_pose)
    emit({"event": "ready"})
    for line in sys.stdin:
        cmd = json.loads(line)
        if cmd["cmd"] == "add":
            name = "/%s/add_obstacle" % cmd["robot"]
            try:
                rospy.wait_for_service(name, timeout=30)
                reply = rospy.ServiceProxy(name, AddObstacle)(rectangle_shape=cmd["rect"], marked_indexes=[],
                                                              deadline=0)
                emit({"event": "reply", "id": cmd["id"], "success": reply.success, "message": reply.message,
                      "uuid": reply.uuid})
            except (rospy.ROSException, rospy.ServiceException) as err:
                emit({"event": "reply", "id": cmd["id"], "success": False, "message": str(err), "uuid": ""})
    rospy.signal_shutdown("stdin closed")


if __name__ == "__main__":
    main()
