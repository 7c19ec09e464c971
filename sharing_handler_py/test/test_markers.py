"""The fleet's obstacle markers pass RViz 1.14's own checks (rviz/default_plugin/markers/marker_utils.cpp,
checkMarkerMsg and checkMarkerArrayMsg, written out below as the oracle) and show what they claim."""
import math

import rospy

from visualization_msgs.msg import Marker

from handler_fixtures import GRID, Recorder, U, cells_in, rect, update
from sharing_handler_py.markers import NS_CELLS, NS_LABELS, NS_RECTANGLES, label_text, obstacle_markers


def rviz_problems(marker):
    """What RViz 1.14 warns or errs about for one marker (ADD only; DELETE/DELETEALL are not checked)."""
    out = []
    if marker.action != Marker.ADD:
        return out
    q = marker.pose.orientation
    uses_pose = marker.type != Marker.POINTS and marker.type != Marker.TEXT_VIEW_FACING
    if uses_pose:
        if (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 0.0):
            out.append("uninitialized quaternion")
        elif abs(math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2) - 1.0) > 1e-3:
            out.append("unnormalized quaternion")
    s = marker.scale
    if marker.type in (Marker.CUBE_LIST, Marker.SPHERE_LIST, Marker.CUBE, Marker.SPHERE, Marker.CYLINDER) \
            and 0.0 in (s.x, s.y, s.z):
        out.append("scale contains 0.0")
    if marker.type in (Marker.LINE_STRIP, Marker.LINE_LIST):
        if s.x == 0.0:
            out.append("line width 0.0")
        elif s.y != 0.0 or s.z != 0.0:
            out.append("scale.y and scale.z of a line are ignored")
        if marker.type == Marker.LINE_STRIP and len(marker.points) <= 1:
            out.append("a LINE_STRIP needs two points")
    if marker.type == Marker.TEXT_VIEW_FACING:
        if s.z == 0.0:
            out.append("text height 0.0")
        elif s.x != 0.0 or s.y != 0.0:
            out.append("scale.x and scale.y of a text are ignored")
        if not marker.text.strip():
            out.append("empty text")
        if marker.points:
            out.append("points ignored")
    elif marker.text:
        out.append("text ignored for this type")
    if marker.type in (Marker.CUBE_LIST, Marker.SPHERE_LIST, Marker.LINE_STRIP, Marker.LINE_LIST, Marker.POINTS) \
            and not marker.points:
        out.append("points empty")
    if marker.colors and len(marker.colors) != len(marker.points):
        out.append("colors and points differ in number")
    if not marker.colors and marker.color.a == 0.0:
        out.append("fully transparent")
    if marker.mesh_resource or marker.mesh_use_embedded_materials:
        out.append("mesh fields ignored")
    if not marker.header.frame_id:
        out.append("no frame")
    return out


def rviz_array_problems(array):
    out, seen, added = [], set(), False
    for m in array.markers:
        if m.action == Marker.ADD:
            added = True
        elif m.action == Marker.DELETEALL:
            if added:
                out.append("DELETEALL after ADD: those markers never show")
            added = False
        key = (m.ns, m.id)
        if key in seen:
            out.append("found %s/%d multiple times" % key)
        seen.add(key)
    return out


def held_two():
    r = Recorder(duration=1200)
    r.handler.on_external(update(U("a"), marked=cells_in(rect(0, 0, 1, 1), 3), version=1, source="robot_1",
                                 rectangle=rect(0, 0, 1, 1), deadline=1200))
    r.handler.on_external(update(U("b"), marked=cells_in(rect(3, 3, 4, 4), 1), version=1, source="robot_2",
                                 rectangle=rect(3, 3, 4, 4), deadline=600))
    r.clock.now += 42.0
    return r


def test_the_markers_pass_rvizs_checks_and_show_cells_rectangles_and_labels():
    r = held_two()
    array = obstacle_markers(r.handler.obstacles(), r.clock(), "map", rospy.Time(5))
    assert rviz_array_problems(array) == []
    for m in array.markers:
        assert rviz_problems(m) == [], (m.ns, m.id, rviz_problems(m))
    assert array.markers[0].action == Marker.DELETEALL
    by_ns = {}
    for m in array.markers[1:]:
        by_ns.setdefault(m.ns, []).append(m)
    assert sorted(by_ns) == sorted([NS_CELLS, NS_LABELS, NS_RECTANGLES])
    cells = by_ns[NS_CELLS]
    assert [len(m.points) for m in cells] == [3, 1]
    # the first cell of obstacle a on the fixtures' grid, at its centre
    first = cells_in(rect(0, 0, 1, 1), 3)[0]
    x, y = cells[0].points[0].x, cells[0].points[0].y
    assert x == GRID.origin_x + (first % GRID.size_x + 0.5) * GRID.resolution
    assert y == GRID.origin_y + (first // GRID.size_x + 0.5) * GRID.resolution
    labels = [m.text for m in by_ns[NS_LABELS]]
    assert labels == ["robot_1 · 42 s old · 1158 s left · 3 cells", "robot_2 · 42 s old · 558 s left · 1 cells"]
    assert [(p.x, p.y) for p in by_ns[NS_RECTANGLES][1].points] == [(3, 3), (4, 3), (4, 4), (3, 4), (3, 3)]


def test_the_oracle_catches_what_rviz_warns_about():
    """The checks can fail: RViz's warnings on markers made the way the stand-in used to make them."""
    r = held_two()
    array = obstacle_markers(r.handler.obstacles(), r.clock(), "map", rospy.Time(5))
    cells = array.markers[1]
    cells.text = "a uuid"                      # the stand-in's CUBE_LIST carried its uuid as text
    assert "text ignored for this type" in rviz_problems(cells)
    array.markers[0].pose.orientation.w = 0.0  # an uninitialised DELETEALL is not checked by RViz...
    assert rviz_problems(array.markers[0]) == []
    cells.pose.orientation.w = 0.0             # ... an ADD is
    assert "uninitialized quaternion" in rviz_problems(cells)
    array.markers.append(array.markers[1])
    assert rviz_array_problems(array)


def test_an_obstacle_whose_cells_were_all_seen_free_draws_nothing_and_labels_count_whole_seconds():
    r = held_two()
    r.handler.on_external(update(U("a"), cleared=cells_in(rect(0, 0, 1, 1), 3), version=2, source="robot_1",
                                 rectangle=rect(0, 0, 1, 1)))
    array = obstacle_markers(r.handler.obstacles(), r.clock(), "map", rospy.Time(5))
    assert [m.text for m in array.markers if m.ns == NS_LABELS] == ["robot_2 · 42 s old · 558 s left · 1 cells"]
    held = r.handler.obstacles()[0]
    assert label_text(held, held.arrival - 5.0).startswith("robot_2 · 0 s old")
