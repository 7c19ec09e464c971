"""rospy adapter of map_io: ``map_server <map.yaml>`` or ``map_server <image> <resolution>``.

Publishes /map (nav_msgs/OccupancyGrid) and /map_metadata latched, serves
static_map (nav_msgs/GetMap), with ~frame_id (default "map"). A bad file is one
error line and exit status 1.

With ``<image> <resolution>`` map_server's defaults apply (negate 0,
occupied_thresh 0.65, free_thresh 0.196, origin [0, 0, 0]); as an extension the
private parameters ~negate, ~occupied_thresh, ~free_thresh, ~origin and ~mode
override them (a YAML file always wins, as in map_server).
"""
import math
import sys

import rospy
from nav_msgs.msg import MapMetaData, OccupancyGrid
from nav_msgs.srv import GetMap, GetMapResponse

from fleet_sim.errors import MapError
from fleet_sim.map_io import load_map_args, load_map_image


def to_message(m, frame_id, stamp):
    msg = OccupancyGrid()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    info = msg.info
    info.map_load_time = stamp
    info.resolution = m.resolution
    info.width, info.height = m.width, m.height
    info.origin.position.x, info.origin.position.y = m.origin[0], m.origin[1]
    info.origin.orientation.z = math.sin(m.origin[2] / 2.0)
    info.origin.orientation.w = math.cos(m.origin[2] / 2.0)
    msg.data = m.data.ravel().tolist()
    return msg


def main(argv=None):
    argv = rospy.myargv(argv if argv is not None else sys.argv)[1:]
    try:
        m = load_map_args(argv)          # fails before touching ROS on a bad file
    except MapError as err:
        sys.stderr.write("map_server: %s\n" % err)
        return 1
    rospy.init_node("map_server")
    overrides = {k: rospy.get_param("~" + k) for k in
                 ("negate", "occupied_thresh", "free_thresh", "origin", "mode") if rospy.has_param("~" + k)}
    if len(argv) == 2 and overrides:
        try:
            m = load_map_image(argv[0], argv[1], **overrides)
        except (MapError, TypeError) as err:
            rospy.logfatal("map_server: %s (parameters %s)", err, overrides)
            return 1
    frame_id = rospy.get_param("~frame_id", "map")
    msg = to_message(m, frame_id, rospy.Time.now())
    meta_pub = rospy.Publisher("map_metadata", MapMetaData, queue_size=1, latch=True)
    map_pub = rospy.Publisher("map", OccupancyGrid, queue_size=1, latch=True)
    meta_pub.publish(msg.info)
    map_pub.publish(msg)
    rospy.Service("static_map", GetMap, lambda _req: GetMapResponse(map=msg))
    rospy.loginfo("map_server: %s, %dx%d at %.3f m/cell, origin %s", m.image_path, m.width,
                  m.height, m.resolution, list(m.origin))
    rospy.spin()
    return 0
