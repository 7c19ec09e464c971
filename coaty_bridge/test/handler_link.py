"""The bridge's ObstacleUpdate and the handler's Obstacle, converted both ways, for tests that wire a real
SharingHandler to a real bridge client in one process (the nodes do it through ROS messages)."""
import os
import sys

from coaty_bridge.codec import ObstacleUpdate

HANDLER_SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                           "sharing_handler_py", "src")
if HANDLER_SRC not in sys.path:
    sys.path.append(HANDLER_SRC)
from sharing_handler_py.validation import Geometry, Obstacle, Rectangle  # noqa: E402


def to_update(o):
    """handler Obstacle -> bridge ObstacleUpdate"""
    g = o.geometry
    return ObstacleUpdate(uuid=o.uuid, source=o.source, version=o.version, stamp=o.stamp, frame_id=o.frame_id,
                          deadline=o.deadline, rectangle=tuple(o.rectangle.as_list()), resolution=g.resolution,
                          origin_x=g.origin_x, origin_y=g.origin_y, size_x=g.size_x, size_y=g.size_y,
                          marked=o.marked, cleared=o.cleared)


def to_obstacle(u):
    """bridge ObstacleUpdate -> handler Obstacle"""
    return Obstacle(uuid=u.uuid, marked=u.marked, cleared=u.cleared, deadline=u.deadline,
                    rectangle=Rectangle(*u.rectangle), source=u.source,
                    geometry=Geometry(u.resolution, u.origin_x, u.origin_y, u.size_x, u.size_y),
                    version=u.version, frame_id=u.frame_id, stamp=u.stamp)
