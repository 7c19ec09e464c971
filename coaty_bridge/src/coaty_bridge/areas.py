"""Squares of the map frame that scope who hears what (issue 12 for footprints, issue 29 for
obstacle updates). Imports neither paho nor rospy.

The map frame is cut into squares of side ``area_size``; an event about something standing in
square (ix, iy) goes out under ``<objectType>.area_<ix>_<iy>`` and a bridge subscribes to the
3 x 3 squares around its own robot, so it hears whatever stands within ``area_size`` along both
axes (and some of what stands up to twice that away), and not the rest of the fleet. The
squares are fleet-wide: robots with different sizes do not hear each other's scoped events.
"""
import math

AREA_MARK = ".area_"


def area_of(point, area_size):
    """The (ix, iy) square of side ``area_size`` holding ``point`` (x, y)."""
    return (math.floor(point[0] / area_size), math.floor(point[1] / area_size))


def area_object_type(object_type, area):
    """The objectType of events about something in ``area``."""
    return "%s%s%d_%d" % (object_type, AREA_MARK, area[0], area[1])


def areas_around(point, area_size):
    """The 3 x 3 squares around ``point``: everything within area_size along both axes is in one."""
    ix, iy = area_of(point, area_size)
    return {(ix + dx, iy + dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)}


def parse_area(candidate, object_type):
    """(ix, iy) for ``<object_type>.area_<ix>_<iy>``; None for anything else (the plain
    object_type included)."""
    if not isinstance(candidate, str) or not candidate.startswith(object_type + AREA_MARK):
        return None
    parts = candidate[len(object_type) + len(AREA_MARK):].split("_")
    try:
        if len(parts) == 2 and all(str(int(p)) == p for p in parts):
            return (int(parts[0]), int(parts[1]))
    except ValueError:
        pass
    return None


def is_scoped_object_type(candidate, object_type):
    """True for ``object_type`` itself and for any of its area objectTypes."""
    return candidate == object_type or parse_area(candidate, object_type) is not None


def rectangle_centre(rectangle):
    """Centre (x, y) of [min_x, min_y, max_x, max_y]: where an obstacle is, for its area."""
    return ((rectangle[0] + rectangle[2]) / 2.0, (rectangle[1] + rectangle[3]) / 2.0)


def lies_in(point, area, area_size, tolerance=0.01):
    """Whether ``point`` lies in square ``area`` of side ``area_size``, give or take ``tolerance`` m (a sender's
    coordinates are rounded to millimetres on the wire, so a centroid on an edge may fall either side)."""
    ix, iy = area
    return (ix * area_size - tolerance <= point[0] < (ix + 1) * area_size + tolerance
            and iy * area_size - tolerance <= point[1] < (iy + 1) * area_size + tolerance)
