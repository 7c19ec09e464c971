"""Fleet robots' footprints on the wire, and the table of robots a bridge has heard.
Imports neither paho nor rospy.

Each bridge advertises its robot's footprint, placed at the robot's pose, as one CoatyObject of
its own objectType (default ``org.fleetsharing.RobotFootprint``) on
``coaty/3/<ns>/ADV::<objectType>/<sourceId>``, at ``footprint_rate`` (2 Hz)::

    {"objectType": "org.fleetsharing.RobotFootprint", "coreType": "CoatyObject",
     "objectId": <uuid of this advert series>, "name": "robot_0",
     "robot": "robot_0", "stamp": 1700000000.25, "frameId": "map",
     "footprint": [[x, y], [x, y], ...], "reach": 4.0, "velocity": [vx, vy], "validFor": 5.0}

``footprint`` is the polygon in ``frameId`` at ``stamp`` (move_base's global_costmap/footprint).
``reach`` (m, optional, issue 43) is how far the robot's sensors see from there: the evidence its
obstacle messages are judged by (sharing_msgs.authority.evidence); an advert without it claims nothing.
``velocity`` (m/s in ``frameId``, optional, with ``validFor``): a driving robot's dead-reckoned advert.
Receivers move the footprint on at that velocity from when they heard it, for at most validFor /
PARKED_VALIDITY s (the sender's advert interval), and the sender advertises again as soon as its true
footprint leaves the one so moved by ``footprint_min_move`` (AdvertSchedule): a straight drive costs an
advert every ``footprint_driving_interval`` s instead of one every 0.1 m.
Receivers keep the latest advert per robot and forget a robot not heard for ``robot_timeout``;
the sharing layers never share cells within a known robot's footprint plus a margin.

Areas (``footprint_area_size`` A > 0, the default 5 m): sent to every peer, adverts grow with
the square of the fleet (100 robots at 2 Hz: 198 adverts per second into each robot), yet a robot
only needs the robots its own sensors can see. So the map frame is cut into squares of
A metres, and an advert's objectType names the square holding the footprint's centroid,
``<objectType>.area_<ix>_<iy>`` with ix = floor(x / A), iy = floor(y / A). Each bridge subscribes
to the 3 x 3 squares around its own robot's centroid, so it hears every robot within A metres
along both axes (and some up to 2A away). A is fleet-wide; 0 puts every advert under the plain
objectType, heard by everyone. Adverts under the plain objectType are always heard (a peer that
does not use areas, such as a Coaty JS agent).
"""
import collections
import json
import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Tuple

from coaty_bridge.areas import area_of
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
#: Longest ``validFor`` a receiver takes, s: a parked robot's advert keeps it known at most this long.
MAX_VALID_FOR = 600.0
#: A parked robot's advert is valid for this many of its advert intervals (one lost advert is no gap).
PARKED_VALIDITY = 2.5
#: s between a far driving robot's adverts when it moves less than far_move (AdvertSchedule)
FAR_INTERVAL = 10.0
#: Longest sensor reach an advert may state, m (a receiver caps it further: max_sensor_reach).
MAX_REACH = 1000.0
#: Fastest velocity an advert may state, m/s: a warehouse robot, with room to spare.
MAX_SPEED = 20.0
#: s of own footprints a driving robot's velocity is estimated over (move_base's footprint topic at 5 Hz:
#: three samples, so one late footprint does not swing it)
VELOCITY_SPAN = 0.4
#: s between a driving robot's dead-reckoned adverts when nothing else sends one (footprint_driving_interval)
DEFAULT_DRIVING_INTERVAL = 2.0
#: footprint_area_size bounds, m (0 is allowed too: no areas).
MIN_AREA_SIZE = 1.0
MAX_AREA_SIZE = 10000.0


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
    # s the receivers keep it without a newer advert; 0: their own robot_timeout. A parked robot
    # advertises rarely and says so (issue 29).
    valid_for: float = 0.0
    # m the robot's sensors reach from its pose (issue 43: the evidence its obstacle messages are judged by)
    reach: float = 0.0
    # m/s (vx, vy) in frame_id: a dead-reckoned advert; receivers move it on (HeardRobot.points_at)
    velocity: Tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        velocity = self.velocity
        if not isinstance(velocity, (list, tuple)) or len(velocity) != 2:
            raise WrongTypeError("velocity %s is not [vx, vy]" % _short(velocity))
        vx, vy = (_finite_number("velocity", v) for v in velocity)
        if math.hypot(vx, vy) > MAX_SPEED:
            raise OutOfRangeError("velocity (%r, %r) faster than %g m/s" % (vx, vy, MAX_SPEED))
        object.__setattr__(self, "velocity", (vx, vy))
        reach = _finite_number("reach", self.reach)
        if not 0.0 <= reach <= MAX_REACH:
            raise OutOfRangeError("reach %r outside [0, %g] m" % (reach, MAX_REACH))
        object.__setattr__(self, "reach", reach)
        valid_for = _finite_number("validFor", self.valid_for)
        if not 0.0 <= valid_for <= MAX_VALID_FOR:
            raise OutOfRangeError("validFor %r outside [0, %g] s" % (valid_for, MAX_VALID_FOR))
        object.__setattr__(self, "valid_for", valid_for)
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

    @property
    def moving(self):
        """Whether this is a dead-reckoned advert: a velocity, and a validity to move it on for."""
        return self.valid_for > 0 and self.velocity != (0.0, 0.0)


def footprint_to_object(footprint, object_id, object_type=DEFAULT_FOOTPRINT_OBJECT_TYPE):
    """RobotFootprint -> CoatyObject dict."""
    obj = {
        "objectType": object_type,
        "coreType": "CoatyObject",
        "objectId": object_id,
        "name": footprint.robot,   # Coaty requires a name; objectType says what it is
        "robot": footprint.robot,
        "stamp": footprint.stamp,
        "frameId": footprint.frame_id,
        # millimetres: the layers' cells are centimetres wide, and full float64 digits double the bytes
        "footprint": [[round(x, 3), round(y, 3)] for x, y in footprint.points],
    }
    if footprint.valid_for > 0:
        obj["validFor"] = footprint.valid_for
    if footprint.reach > 0:
        obj["reach"] = footprint.reach
    if footprint.moving:
        obj["velocity"] = [round(v, 3) for v in footprint.velocity]   # mm/s
    return obj


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
                          points=obj["footprint"], valid_for=obj.get("validFor", 0.0), reach=obj.get("reach", 0.0),
                          velocity=obj.get("velocity", (0.0, 0.0)))


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


@dataclass(frozen=True)
class HeardRobot:
    """A robot's latest footprint and when this bridge heard it (its clock)."""
    footprint: RobotFootprint
    heard_at: float

    def vouched_at(self, now, timeout):
        """The stamp a layer counts its ``robot_timeout`` from (RobotFootprint.msg): when it was heard,
        or, for a parked robot's advert (``validFor``), as late as ``now`` while the advert holds, and
        never later than ``timeout`` before it runs out. A parked robot advertises only every
        footprint_parked_interval (30 s), far beyond a layer's 3 s robot_timeout: stamped with when it
        was heard, the layer would forget it between adverts, and share it as an obstacle."""
        if self.footprint.valid_for <= 0.0:
            return self.heard_at
        return max(self.heard_at, min(now, self.heard_at + self.footprint.valid_for - timeout))

    def points_at(self, now):
        """The footprint where this bridge believes the robot is at ``now`` (its clock): a dead-reckoned advert
        moved on at its velocity since it was heard, for at most the sender's advert interval (validFor /
        PARKED_VALIDITY; a lost advert then leaves the robot where that brought it, not driving on for ever)."""
        footprint = self.footprint
        return dead_reckoned(footprint.points, footprint.velocity, footprint.valid_for, now - self.heard_at)


def shifted(points, dx, dy):
    return tuple((x + dx, y + dy) for x, y in points)


def dead_reckoned(points, velocity, valid_for, elapsed):
    """``points`` of an advert with ``velocity`` and ``valid_for``, ``elapsed`` s after it went out: moved on at the
    velocity for at most valid_for / PARKED_VALIDITY s (the sender's advert interval), never back. The one rule of
    both sides: receivers (HeardRobot.points_at) and the sender judging what they believe (AdvertSchedule.believed)."""
    if valid_for <= 0 or velocity == (0.0, 0.0):
        return points
    dt = min(max(elapsed, 0.0), valid_for / PARKED_VALIDITY)
    return shifted(points, velocity[0] * dt, velocity[1] * dt)


def extent(points):
    """(width, height) of a footprint's bounding box, m."""
    xs, ys = [x for x, _ in points], [y for _, y in points]
    return (max(xs) - min(xs), max(ys) - min(ys))


def centroid(points):
    """Mean of a footprint's vertices: where it is, for telling how far it moved."""
    return (sum(x for x, _ in points) / len(points), sum(y for _, y in points) / len(points))


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
        keep = {name: r for name, r in self._robots.items()
                if abs(now - r.heard_at) <= max(self.timeout, r.footprint.valid_for)}
        gone = sorted(set(self._robots) - set(keep))
        self._robots = keep
        return gone

    def forget(self, robot):
        """Forgets ``robot`` now (it withdrew its footprint); False when it was not known."""
        if robot not in self._robots:
            return False
        self._robots = {name: r for name, r in self._robots.items() if name != robot}
        return True

    def robots(self) -> List[HeardRobot]:
        """The known robots, by name."""
        robots = self._robots
        return [robots[name] for name in sorted(robots)]


def near_any(own_points, peers, distance):
    """Whether a peer footprint (``peers``: point lists) has its centroid within ``distance`` m of this robot's
    (AdvertSchedule's near/far). ``distance`` <= 0: always near (every advert precise)."""
    if distance <= 0:
        return True
    x, y = centroid(own_points)
    return any(math.hypot(px - x, py - y) <= distance for px, py in (centroid(p) for p in peers))


def largest_move(a, b):
    """How far (m) the farthest-moving vertex went from footprint ``a`` to ``b`` (inf when their
    vertex counts differ): a turn on the spot moves the corners, not the centroid."""
    if a is None or len(a) != len(b):
        return math.inf
    return max(math.hypot(q[0] - p[0], q[1] - p[1]) for p, q in zip(a, b))


class AdvertSchedule:
    """When this robot advertises its footprint (issue 29: adverts were 40 % of the fleet's bytes).

    - at once when a vertex moved ``min_move`` from where the peers believe it (the last advert, moved on
      at its velocity when it stated one): a peer's view lags by at most that;
    - while moving (such an advert within ``parked_after`` s), at ``rate`` as a heartbeat, or with dead
      reckoning (``driving_interval`` > 0) every ``driving_interval`` s: each such advert states the
      robot's velocity (``advert_velocity``, estimated over VELOCITY_SPAN s of footprints) and is valid
      for PARKED_VALIDITY times that interval; receivers move it on (HeardRobot.points_at), so a straight
      drive sends a heartbeat, and a turn, a stop or a change of speed sends at once. An advert also goes
      at once when the robot enters another square of ``area_size`` (its adverts' topic changes);
    - parked, every ``parked_interval`` s, each advert valid for PARKED_VALIDITY times that, so the
      peers keep the robot between them (``validFor`` on the wire; older receivers use their own
      robot_timeout, and forget a parked robot between adverts).
    - far (the caller passes ``near=False``: no known peer within its near distance), driving: at once only
      when a vertex moved ``far_move`` (with dead reckoning: is ``far_move`` off what the peers believe, the
      advert stating the velocity), and otherwise every FAR_INTERVAL s, each advert valid for PARKED_VALIDITY
      times that. No peer's sensors reach the robot, so no peer needs its pose within ``min_move``; the first
      footprint that is near again sends at once when it is ``min_move`` off what the peers believe.
    ``parked_interval`` 0 (or ``min_move`` 0: motion is not watched) keeps the rate at all times;
    ``far_move`` 0 makes every robot near; ``driving_interval`` 0 sends every ``min_move`` (no velocity).
    Pure: the caller passes the time and sends what it is told (the validFor returned, and
    ``advert_velocity``); ``sent`` records it."""

    def __init__(self, rate, min_move, parked_interval, parked_after=2.0, far_move=0.0, driving_interval=0.0,
                 area_size=0.0):
        self.rate, self.min_move = float(rate), float(min_move)
        self.parked_interval, self.parked_after = float(parked_interval), float(parked_after)
        self.far_move = float(far_move)
        self.driving_interval, self.area_size = float(driving_interval), float(area_size)
        self._last_points = None
        self._last_time = None
        self._last_valid_for = 0.0
        self._last_kind = None
        self._last_velocity = (0.0, 0.0)
        self._last_motion = -math.inf
        self._motion_ref = None   # the footprint where motion was last seen (adverts or not: far ones are rare)
        self._samples = collections.deque()   # (time, centroid) of the recent own footprints
        self._velocity = (0.0, 0.0)
        self.decision = ("precise", (0.0, 0.0))   # (kind, velocity) of the advert just decided

    def _far(self, near):
        return not near and self.far_move > 0 and self.min_move > 0

    def _dead_reckoning(self):
        return self.driving_interval > 0 and self.min_move > 0

    def _watch_motion(self, points, now):
        if self.min_move > 0 and self._motion_ref is not None \
                and largest_move(self._motion_ref, points) >= self.min_move:
            self._last_motion, self._motion_ref = now, tuple(points)

    def _estimate(self, points, now):
        """The velocity over the last VELOCITY_SPAN s of footprints; (0, 0) when too few, or slower than one
        min_move per driving_interval (the peers' view then drifts less than the min_move that resends)."""
        here, samples = centroid(points), self._samples
        if samples and now < samples[-1][0]:
            samples.clear()                     # a clock that went back (a new simulation)
        if not samples or now > samples[-1][0]:
            samples.append((now, here))
        while len(samples) > 2 and now - samples[1][0] >= VELOCITY_SPAN:
            samples.popleft()
        then, there = samples[0]
        if now - then < 0.5 * VELOCITY_SPAN:
            return (0.0, 0.0)
        vx, vy = ((here[0] - there[0]) / (now - then), (here[1] - there[1]) / (now - then))
        if not self.min_move / self.driving_interval <= math.hypot(vx, vy) <= MAX_SPEED:
            return (0.0, 0.0)
        return (vx, vy)

    def believed(self, now):
        """The footprint the peers believe this robot has at ``now``: the last advert, moved on at its velocity
        for at most its validFor / PARKED_VALIDITY s (as HeardRobot.points_at does); None before any advert."""
        if self._last_points is None:
            return None
        return dead_reckoned(self._last_points, self._last_velocity, self._last_valid_for, now - self._last_time)

    def _area_changed(self, points):
        return self.area_size > 0 and self._last_points is not None and \
            area_of(centroid(points), self.area_size) != area_of(centroid(self._last_points), self.area_size)

    def _decide(self, kind, valid_for, velocity=(0.0, 0.0)):
        self.decision = (kind, velocity)
        return valid_for

    @property
    def advert_velocity(self):
        """The velocity the advert just decided states ((0, 0) unless dead-reckoned)."""
        return self.decision[1]

    def _far_advert(self):
        """The advert of a robot that drives far from every known robot: every far_move off (dead-reckoned: off what
        the peers believe), or every FAR_INTERVAL s."""
        return self._decide("far", PARKED_VALIDITY * FAR_INTERVAL,
                            self._velocity if self._dead_reckoning() else (0.0, 0.0))

    def _moving_advert(self):
        """The advert of a robot that moves near others: dead-reckoned, or precise."""
        if self._dead_reckoning():
            return self._decide("driving", PARKED_VALIDITY * self.driving_interval, self._velocity)
        return self._decide("precise", 0.0)

    def on_footprint(self, points, now, near=True):
        """A new own footprint: the validFor of an advert to send now (a motion advert), or None."""
        self._watch_motion(points, now)
        if self._dead_reckoning():
            self._velocity = self._estimate(points, now)
        if self.min_move <= 0 or self._last_points is None:
            return None
        moved = largest_move(self.believed(now), points)
        if self._far(near):
            return self._far_advert() if moved >= self.far_move else None
        if moved >= self.min_move or (self._dead_reckoning() and self._area_changed(points)):
            self._last_motion = now
            return self._moving_advert()
        return None

    def on_tick(self, points, now, near=True, at=None):
        """The ``rate`` tick: the validFor of an advert to send now, or None to skip this tick. ``at``: when
        ``points`` were taken (the last footprint's stamp; default ``now``), what the peers' belief is compared at."""
        self._watch_motion(points, now)
        far = self._far(near)
        if self._last_time is None or largest_move(self.believed(now if at is None else at), points) >= max(
                self.far_move if far else self.min_move, 1e-9):
            if self._last_points is not None and self.min_move > 0:
                self._last_motion = now
            if self._last_time is None:
                return self._decide("precise", 0.0)    # the first: nothing known of its motion yet
            if far:
                return self._far_advert()
            return self._moving_advert()
        since = now - self._last_time
        parked = self.parked_interval > 0 and self.min_move > 0 and now - self._last_motion >= self.parked_after
        if not parked and not far:
            # the heartbeat, skipped when a motion advert went out since the previous tick
            interval = self.driving_interval if self._dead_reckoning() else 1.0 / self.rate
            return self._moving_advert() if not 0.0 <= since < interval - 0.25 / self.rate else None
        if parked:
            if self._last_kind != "parked" or not 0.0 <= since < self.parked_interval:
                return self._decide("parked", PARKED_VALIDITY * self.parked_interval)
            return None
        if self._last_kind != "far" or not 0.0 <= since < FAR_INTERVAL:
            return self._far_advert()
        return None

    @property
    def last_valid_for(self):
        """validFor of the last advert sent (0 before any, or when it was a precise one)."""
        return self._last_valid_for

    def sent(self, points, now, valid_for, decision=None):
        """An advert went out at ``now`` with ``valid_for``: the one decided last, or ``decision`` (kind,
        velocity) read with it where another thread may decide in between."""
        kind, velocity = decision or self.decision
        self._last_points, self._last_time, self._last_valid_for = tuple(points), now, valid_for
        self._last_kind, self._last_velocity = kind, velocity if valid_for > 0 else (0.0, 0.0)
        if self._motion_ref is None:
            self._motion_ref = tuple(points)
