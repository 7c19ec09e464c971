"""The fleet's obstacles as a visualization_msgs/MarkerArray for RViz 1.14 (issue 28).

One DELETEALL first (obstacles that left, by evidence or lease, vanish with the next array), then per
obstacle: its present cells (CUBE_LIST), its monitored rectangle (LINE_STRIP) and a label (TEXT_VIEW_FACING:
source, age, time left, cells). Every marker passes RViz's own checks (marker_utils.cpp: normalised
quaternion, non-zero scale where it is used, no ignored fields, a visible colour, unique ns/id):
tests/test_markers.py holds those rules as its oracle. The stand-in navigation host's earlier markers
set a text on a CUBE_LIST, which RViz warns about ("Text is ignored for specified marker type")."""
import colorsys
import zlib

from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray

NS_CELLS = "fleet_obstacles/cells"
NS_RECTANGLES = "fleet_obstacles/rectangles"
NS_LABELS = "fleet_obstacles/labels"
CELL_HEIGHT = 0.2      # m, the cubes' height above the floor
LABEL_HEIGHT = 0.3     # m, text height
LINE_WIDTH = 0.03      # m


def source_colour(source):
    """A stable, saturated colour per robot (the same on every robot's RViz)."""
    hue = (zlib.crc32(source.encode("utf-8", "replace")) % 360) / 360.0
    return colorsys.hsv_to_rgb(hue, 0.85, 0.9)


def label_text(held, now):
    """'robot_0 · 42 s old · 1158 s left · 46 cells' (ages in whole seconds)."""
    return "%s · %d s old · %d s left · %d cells" % (
        held.source, max(0, int(now - held.arrival)), max(0, int(held.remaining)), len(held.cells))


def _base(marker_type, ns, marker_id, frame_id, stamp):
    m = Marker()
    m.header.frame_id = frame_id
    m.header.stamp = stamp
    m.ns, m.id, m.type, m.action = ns, marker_id, marker_type, Marker.ADD
    m.pose.orientation.w = 1.0
    return m


def obstacle_markers(held_obstacles, now, frame_id, stamp):
    """MarkerArray of the held obstacles (HeldObstacle list) at clock time `now`, in frame_id."""
    array = MarkerArray()
    clear = Marker()
    clear.header.frame_id = frame_id
    clear.header.stamp = stamp
    clear.action = Marker.DELETEALL
    clear.pose.orientation.w = 1.0
    array.markers.append(clear)
    for k, held in enumerate(held_obstacles):
        if not held.cells:
            continue
        r, g, b = source_colour(held.source)
        geometry = held.geometry
        cells = _base(Marker.CUBE_LIST, NS_CELLS, k, frame_id, stamp)
        cells.scale.x = cells.scale.y = geometry.resolution
        cells.scale.z = CELL_HEIGHT
        cells.color.r, cells.color.g, cells.color.b, cells.color.a = r, g, b, 0.85
        for index in held.cells:
            ix, iy = index % geometry.size_x, index // geometry.size_x
            cells.points.append(Point(geometry.origin_x + (ix + 0.5) * geometry.resolution,
                                      geometry.origin_y + (iy + 0.5) * geometry.resolution, CELL_HEIGHT / 2))
        box = _base(Marker.LINE_STRIP, NS_RECTANGLES, k, frame_id, stamp)
        box.scale.x = LINE_WIDTH
        box.color.r, box.color.g, box.color.b, box.color.a = r, g, b, 0.6
        rect = held.rectangle
        for x, y in ((rect.min_x, rect.min_y), (rect.max_x, rect.min_y), (rect.max_x, rect.max_y),
                     (rect.min_x, rect.max_y), (rect.min_x, rect.min_y)):
            box.points.append(Point(x, y, 0.02))
        label = _base(Marker.TEXT_VIEW_FACING, NS_LABELS, k, frame_id, stamp)
        label.pose.position.x = (rect.min_x + rect.max_x) / 2
        label.pose.position.y = rect.max_y + LABEL_HEIGHT
        label.pose.position.z = CELL_HEIGHT + 0.1
        label.scale.z = LABEL_HEIGHT
        label.color.r = label.color.g = label.color.b = 0.1
        label.color.a = 1.0
        label.text = label_text(held, now)
        array.markers += [cells, box, label]
    return array
