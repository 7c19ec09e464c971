"""Fleet robots' footprints on the wire, and the table of robots a bridge has heard.
Imports neither paho nor rospy.

Each bridge advertises its robot's footprint, placed at the robot's pose, as one CoatyObject of
its own objectType (default ``org.fleetsharing.RobotFootprint``) on
``coaty/3/<ns>/ADV::<objectType>/<sourceId>``, at ``footprint_rate`` (2 Hz)::

    {"objectType": "org.fleetsharing.RobotFootprint", "coreType": "CoatyObject",
     "objectId": <uuid of this advert series>, "name": "RobotFootprint robot_0",
     "robot": "robot_0", "stamp": 1700000000.25, "frameId": "map",
     "footprint": [[x, y], [x, y], ...]}

``footprint`` is the polygon in ``frameId`` at ``stamp`` (move_base's global_costmap/footprint).
Receivers keep the latest advert per robot and forget a robot not heard for ``robot_timeout``;
the sharing layers never share cells within a known robot's footprint plus a margin.

Areas (``footprint_area_size`` A > 0, the default 10 m): sent to every peer, adverts grow with
the square of the fleet (100 robots at 2 Hz: 198 adverts per second into each robot), yet a robot
only needs the robots its own sensors can see. So the map frame is cut into squares of
A metres, and an advert's objectType names the square holding the footprint's centroid,
``<objectType>.area_<ix>_<iy>`` with ix = floor(x / A), iy = floor(y / A). Each bridge subscribes
to the 3 x 3 squares around its own robot's centroid, so it hears every robot within A metres
along both axes (and some up to 2A away). A is fleet-wide; 0 puts every advert under the plain
objectType, heard by everyone. Adverts under the plain objectType are always heard (a peer that
does not use areas, such as a Coaty JS agent).
"""
import json
import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Tuple

from coaty_bridge.errors import (InvalidNameError, MissingFieldError, NonFiniteNumberError,
                                 OutOfRangeError, WrongTypeError)
from coaty_bridge.topics import _NAME_RE, _UUID_RE
from sharing_msgs import obstacle_rules

DEFAULT_FOOTPRINT_OBJECT_TYPE = "org.fleetsharing.RobotFootprint"
#: Most vertices of a footprint (the sharing core's kMaxFootprintPoints).
MAX_POINTS = 1000
#: Largest extent of a footprint, m (the sharing core's kMaxFootprintExtent): a robot, not a building.
MAX_EXTENT = 50.0
#: Default of the receiver's own cap (``max_footprint_extent``), m: an AGV, forklift or tugger is a
#: few metres; a 35 m x 35 m "robot" (issue 27) is not.
DEFAULT_MAX_FOOTPRINT_EXTENT = 5.0
#: Largest |coordinate|, m: geometry_msgs/Point32 is float32, exact to a few cm up to here.
MAX_COORDINATE = 1.0e6
#: ROS time range (seconds), as for obstacles.
MAX_STAMP = float(2 ** 32 - 1)
MAX_TEXT = 256
#: footprint_area_size bounds, m (0 is allowed too: no areas).
MIN_AREA_SIZE = 1.0
MAX_AREA_SIZE = 10000.0
_AREA_MARK = ".area_"


def _short(value):
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _finite_number(what, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WrongTypeError("%s %s is not a number" % (what, _short(value)))
    if not math.isfinite(value):
        raise NonFiniteNumberError("%s %r is not finite" % (what, value))
    return float(value)


@dataclass(frozen=True)
class RobotFootprint:
    """One robot's footprint at its pose, validated: ``points`` is a tuple of (x, y) floats in
    ``frame_id``; ``stamp`` in seconds (ROS time of the sender)."""
    robot: str
    stamp: float
    frame_id: str
    points: Tuple[Tuple[float, float], ...]

    def __post_init__(self):
        if not isinstance(self.robot, str) or not _NAME_RE.match(self.robot) or len(self.robot) > MAX_TEXT:
            raise InvalidNameError("robot %s is not a Coaty name (1..%d characters, no NUL, '/', '+' or '#')"
                                   % (_short(self.robot), MAX_TEXT))
        stamp = _finite_number("stamp", self.stamp)
        if not 0.0 <= stamp < MAX_STAMP:
            raise OutOfRangeError("stamp %r outside ROS time [0, 2^32-1) s" % (stamp,))
        object.__setattr__(self, "stamp", stamp)
        if not isinstance(self.frame_id, str) or not 0 < len(self.frame_id) <= MAX_TEXT or "\u0000" in self.frame_id:
            raise OutOfRangeError("frameId %s is not a frame name (1..%d characters)" % (_short(self.frame_id), MAX_TEXT))
        for name, text in (("robot", self.robot), ("frameId", self.frame_id)):
            why = obstacle_rules.lone_surrogate(text)
            if why:  # else it fails later, in ROS serialisation of fleet_robots (issue 27, item 8)
                raise OutOfRangeError("%s %s %s" % (name, _short(text), why))
        points = self.points
        if not isinstance(points, (list, tuple)):
            raise WrongTypeError("footprint %s is not a list of [x, y]" % _short(points))
        if not 1 <= len(points) <= MAX_POINTS:
            raise OutOfRangeError("footprint has %d vertices, expected 1..%d" % (len(points), MAX_POINTS))
        clean = []
        for point in points:
            if not isinstance(point, (list, tuple)) or len(point) != 2:
                raise WrongTypeError("footprint vertex %s is not [x, y]" % _short(point))
            x, y = (_finite_number("footprint vertex", v) for v in point)
            if abs(x) > MAX_COORDINATE or abs(y) > MAX_COORDINATE:
                raise OutOfRangeError("footprint vertex (%r, %r) beyond %g m" % (x, y, MAX_COORDINATE))
            clean.append((x, y))
        xs, ys = [p[0] for p in clean], [p[1] for p in clean]
        if max(xs) - min(xs) > MAX_EXTENT or max(ys) - min(ys) > MAX_EXTENT:
            raise OutOfRangeError("footprint %.1f x %.1f m is wider than %.0f m: not a robot"
                                  % (max(xs) - min(xs), max(ys) - min(ys), MAX_EXTENT))
        object.__setattr__(self, "points", tuple(clean))


def footprint_to_object(footprint, object_id, object_type=DEFAULT_FOOTPRINT_OBJECT_TYPE):
    """RobotFootprint -> CoatyObject dict."""
    return {
        "objectType": object_type,
        "coreType": "CoatyObject",
        "objectId": object_id,
        "name": "RobotFootprint %s" % footprint.robot,
        "robot": footprint.robot,
        "stamp": footprint.stamp,
        "frameId": footprint.frame_id,
        # millimetres: the layers' cells are centimetres wide, and full float64 digits double the bytes
        "footprint": [[round(x, 3), round(y, 3)] for x, y in footprint.points],
    }


def footprint_from_object(obj, object_type=DEFAULT_FOOTPRINT_OBJECT_TYPE):
    """CoatyObject dict -> RobotFootprint; raises an InvalidPayloadError subclass (InvalidNameError
    for a bad robot name) naming the bad field and value."""
    if not isinstance(obj, dict):
        raise WrongTypeError("object %s is not a JSON object" % _short(obj))
    for key in ("objectType", "coreType", "objectId", "name", "robot", "stamp", "frameId", "footprint"):
        if key not in obj:
            raise MissingFieldError("field %r missing" % key)
    if obj["objectType"] != object_type:
        raise WrongTypeError("objectType %s is not %r" % (_short(obj["objectType"]), object_type))
    if obj["coreType"] != "CoatyObject":
        raise WrongTypeError("coreType %s is not 'CoatyObject'" % _short(obj["coreType"]))
    if not isinstance(obj["objectId"], str) or not _UUID_RE.match(obj["objectId"]):
        raise WrongTypeError("objectId %s is not a UUID" % _short(obj["objectId"]))
    if not isinstance(obj["name"], str):
        raise WrongTypeError("name %s is not a string" % _short(obj["name"]))
    if not isinstance(obj["robot"], str):
        raise WrongTypeError("robot %s is not a string" % _short(obj["robot"]))
    if not isinstance(obj["frameId"], str):
        raise WrongTypeError("frameId %s is not a string" % _short(obj["frameId"]))
    return RobotFootprint(robot=obj["robot"], stamp=obj["stamp"], frame_id=obj["frameId"],
                          points=obj["footprint"])


def decode_footprint_advertise(data, object_type=DEFAULT_FOOTPRINT_OBJECT_TYPE):
    """Advertise payload dict (ADV::<footprint objectType>) -> RobotFootprint."""
    if "privateData" in data and not isinstance(data["privateData"], dict):
        raise WrongTypeError("privateData %s is not an object" % _short(data["privateData"]))
    if "object" not in data:
        raise MissingFieldError("field 'object' missing")
    return footprint_from_object(data["object"], object_type)


def footprint_payload(footprint, object_id, object_type=DEFAULT_FOOTPRINT_OBJECT_TYPE):
    """The Advertise payload (UTF-8 JSON, no NaN) of one footprint."""
    return json.dumps({"object": footprint_to_object(footprint, object_id, object_type)},
                      separators=(",", ":"), allow_nan=False).encode("utf-8")


def area_of(point, area_size):
    """The (ix, iy) square of side ``area_size`` holding ``point`` (x, y)."""
    return (math.floor(point[0] / area_size), math.floor(point[1] / area_size))


def area_object_type(object_type, area):
    """The objectType adverts of robots standing in ``area`` go out under."""
    return "%s%s%d_%d" % (object_type, _AREA_MARK, area[0], area[1])


def areas_around(point, area_size):
    """The 3 x 3 squares around ``point``: every robot within area_size along both axes stands
    in one of them."""
    ix, iy = area_of(point, area_size)
    return {(ix + dx, iy + dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)}


def is_footprint_object_type(candidate, object_type):
    """True for ``object_type`` itself and for any ``<object_type>.area_<ix>_<iy>``."""
    if candidate == object_type:
        return True
    if not candidate.startswith(object_type + _AREA_MARK):
        return False
    parts = candidate[len(object_type) + len(_AREA_MARK):].split("_")
    try:
        return len(parts) == 2 and all(str(int(p)) == p for p in parts)
    except ValueError:
        return False


@dataclass(frozen=True)
class HeardRobot:
    """A robot's latest footprint and when this bridge heard it (its clock)."""
    footprint: RobotFootprint
    heard_at: float


def extent(points):
    """(width, height) of a footprint's bounding box, m."""
    xs, ys = [x for x, _ in points], [y for _, y in points]
    return (max(xs) - min(xs), max(ys) - min(ys))


def centroid(points):
    """Mean of a footprint's vertices: where it is, for telling how far it moved."""
    return (sum(x for x, _ in points) / len(points), sum(y for _, y in points) / len(points))


def moved(a, b):
    """Distance (m) between two centroids."""
    return math.hypot(b[0] - a[0], b[1] - a[1])


class FleetRobotTable:
    """The fleet robots a bridge has heard: the latest footprint per robot, forgotten ``timeout`` s
    after it was last heard (``clock`` is injected: the node passes ROS time). Its own robot is
    never kept. Thread-safe enough for one writer (MQTT thread) and one reader (a timer): every
    method replaces the dict, never mutates one a reader holds."""

    def __init__(self, own_robot, timeout, clock: Callable[[], float]):
        if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not 0 < timeout < 1e6:
            raise ValueError("parameter robot_timeout = %r: must be a positive number of seconds" % (timeout,))
        self.own_robot = own_robot
        self.timeout = float(timeout)
        self._clock = clock
        self._robots: Dict[str, HeardRobot] = {}

    def heard(self, footprint):
        """Records an advert; returns False (and keeps nothing) for the own robot's name and for an
        advert older (by its stamp) than the one held, which a reordering path (a broker bridge, a
        reconnect) delivered late. A stamp more than timeout older is a robot whose clock restarted
        (a new simulation): that one is taken."""
        if footprint.robot == self.own_robot:
            return False
        held = self._robots.get(footprint.robot)
        if held is not None and held.footprint.stamp - self.timeout <= footprint.stamp < held.footprint.stamp:
            return False
        robots = dict(self._robots)
        robots[footprint.robot] = HeardRobot(footprint, self._clock())
        self._robots = robots
        return True

    def expire(self):
        """Forgets robots not heard within timeout (or heard 'in the future': a clock that went
        back); returns their names, sorted."""
        now = self._clock()
        keep = {name: r for name, r in self._robots.items() if abs(now - r.heard_at) <= self.timeout}
        gone = sorted(set(self._robots) - set(keep))
        self._robots = keep
        return gone

    def robots(self) -> List[HeardRobot]:
        """The known robots, by name."""
        robots = self._robots
        return [robots[name] for name in sorted(robots)]
