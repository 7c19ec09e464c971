#!/usr/bin/python3
"""ROS side of the coaty_bridge integration tests (not a test file itself).

Usage: bridge_probe.py robot_0 robot_1 ...
For each robot it subscribes <robot>/from_fleet and prints every message as one
JSON line {"event": "from_fleet", "robot": ..., "msg": {...}}. Commands, one JSON
object per stdin line:
  {"cmd": "to_fleet", "robot": r, "msg": {...}}   publish on <robot>/to_fleet
  {"cmd": "list", "robot": r, "msgs": [...]}      publish <robot>/shared_obstacle_list (latched)
  {"cmd": "footprint", "robot": r, "frame_id": f, "points": [[x, y], ...], "stamp": s}
                                                  publish <robot>/move_base/global_costmap/footprint
  {"cmd": "watch_state", "robot": r}              subscribe <robot>/fleet_state (the Resolves answering its
                                                  bridge's Discover: copies restoring state, not on from_fleet)
                                                  and print each as {"event": "fleet_state", "robot": r, "msg": ...};
                                                  opt-in, since a new subscriber of a started bridge's fleet_state
                                                  is a restarted handler to it (it asks the fleet again)
It also prints every <robot>/fleet_robots as {"event": "fleet_robots", "robot": r, "robots": [...]}.
Publishing waits until the bridge is subscribed, then prints {"event": "sent"}.
"""
import json
import sys
import threading

import rospy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Point32, PolygonStamped
from sharing_msgs.msg import RobotFootprintArray, SharedObstacle, SharedObstacleArray

FIELDS = ("uuid", "marked_indexes", "cleared_indexes", "deadline", "rectangle_shape", "source",
          "resolution", "origin_x", "origin_y", "size_x", "size_y", "version")
_out = threading.Lock()


def emit(event):
    with _out:
        sys.stdout.write(json.dumps(event) + "\n")
        sys.stdout.flush()


def to_dict(msg):
    data = {name: getattr(msg, name) for name in FIELDS}
    data["marked_indexes"] = list(msg.marked_indexes)
    data["cleared_indexes"] = list(msg.cleared_indexes)
    data["rectangle_shape"] = list(msg.rectangle_shape)
    data["stamp"] = msg.header.stamp.to_sec()
    data["frame_id"] = msg.header.frame_id
    data["types"] = {name: type(getattr(msg, name)).__name__ for name in ("resolution", "origin_x", "version")}
    return data


def from_dict(data):
    msg = SharedObstacle()
    for name in FIELDS:
        if name in data:
            setattr(msg, name, data[name])
    msg.header.stamp = rospy.Time.from_sec(data.get("stamp", 0.0))
    msg.header.frame_id = data.get("frame_id", "map")
    return msg


def wait_connected(publisher):
    deadline = rospy.get_time() + 10.0
    while publisher.get_num_connections() == 0 and rospy.get_time() < deadline:
        rospy.sleep(0.05)
    return publisher.get_num_connections() > 0


def main():
    rospy.init_node("bridge_probe", anonymous=True, disable_signals=True)
    robots = sys.argv[1:]
    to_fleet, lists, footprints = {}, {}, {}
    for robot in robots:
        rospy.Subscriber("/%s/fleet_robots" % robot, RobotFootprintArray, lambda msg, r=robot: emit(
            {"event": "fleet_robots", "robot": r, "stamp": msg.header.stamp.to_sec(), "robots": [
                {"robot": f.robot, "frame_id": f.header.frame_id, "stamp": f.header.stamp.to_sec(),
                 "points": [[p.x, p.y] for p in f.footprint.points]} for f in msg.robots]}))
        footprints[robot] = rospy.Publisher("/%s/move_base/global_costmap/footprint" % robot, PolygonStamped,
                                            queue_size=10)
        rospy.Subscriber("/%s/from_fleet" % robot, SharedObstacle,
                         lambda msg, r=robot: emit({"event": "from_fleet", "robot": r, "msg": to_dict(msg)}))
        to_fleet[robot] = rospy.Publisher("/%s/to_fleet" % robot, SharedObstacle, queue_size=10)
        lists[robot] = rospy.Publisher("/%s/shared_obstacle_list" % robot, SharedObstacleArray,
                                       queue_size=1, latch=True)
    rospy.Subscriber("/diagnostics", DiagnosticArray, lambda msg: emit(
        {"event": "diagnostics", "status": [{"name": s.name, "level": ord(s.level) if isinstance(s.level, bytes) else int(s.level),
                                             "message": s.message, "values": {kv.key: kv.value for kv in s.values}}
                                            for s in msg.status]}))
    emit({"event": "ready"})
    for line in sys.stdin:
        cmd = json.loads(line)
        if cmd["cmd"] == "to_fleet":
            publisher = to_fleet[cmd["robot"]]
            connected = wait_connected(publisher)
            publisher.publish(from_dict(cmd["msg"]))
            emit({"event": "sent", "connected": connected})
        elif cmd["cmd"] == "footprint":
            msg = PolygonStamped()
            msg.header.frame_id = cmd.get("frame_id", "map")
            msg.header.stamp = rospy.Time.from_sec(cmd.get("stamp", 0.0))
            msg.polygon.points = [Point32(float(x), float(y), 0.0) for x, y in cmd["points"]]
            connected = wait_connected(footprints[cmd["robot"]])
            footprints[cmd["robot"]].publish(msg)
            emit({"event": "sent", "connected": connected})
        elif cmd["cmd"] == "list":
            array = SharedObstacleArray(obstacles=[from_dict(m) for m in cmd["msgs"]])
            lists[cmd["robot"]].publish(array)
            emit({"event": "sent", "connected": True})
        elif cmd["cmd"] == "watch_state":
            rospy.Subscriber("/%s/fleet_state" % cmd["robot"], SharedObstacle, lambda msg, r=cmd["robot"]: emit(
                {"event": "fleet_state", "robot": r, "msg": to_dict(msg)}))
            emit({"event": "sent", "connected": True})
    rospy.signal_shutdown("stdin closed")


if __name__ == "__main__":
    main()
