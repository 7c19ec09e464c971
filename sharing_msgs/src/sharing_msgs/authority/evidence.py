"""Plausible evidence (issue 43, DESIGN.md §6c): a peer may mark, clear or renew only cells its sensors
could have seen. Pure Python, no ROS, no paho. The rule and the reasoning behind each slack are in the
sharing_msgs README, "Plausible evidence"; keep the two together.

Every bridge advertises its robot's footprint at its pose, with the reach of its sensors (``reach``,
m). A receiver keeps what each peer advertised (``PoseHistory``: a ``Sighting`` per advert, by stamp).
A cell of a message from peer P stamped t is plausible when some sighting s of P covers t
(s.stamp - window <= t <= s.stamp + max(window, s.valid_for)) and the cell's centre lies within

    min(s.reach, max_sensor_reach) + s.radius + resolution / sqrt(2) + localisation_tolerance
        + max_speed * |t - s.stamp|      (for a parked sighting, t within its validity: at most the window)

of the footprint's centroid. Only the advertising robot's own clock is compared with itself (the
advert's stamp and the message's), so no clock synchronisation between robots is assumed.
``judge`` keeps the plausible cells of a message and says why the others were refused.
"""
import bisect
import collections
import math
from dataclasses import dataclass
from typing import Tuple

#: Most sightings kept per robot (2 Hz while driving: about 34 min) and robots kept (least recent dropped).
MAX_SIGHTINGS_PER_ROBOT = 4096
MAX_ROBOTS = 1024
#: Longest validity of a parked robot's advert a receiver takes (the footprint's MAX_VALID_FOR), s.
MAX_VALID_FOR = 600.0


@dataclass(frozen=True)
class EvidenceRule:
    """The receiver's slack; the defaults and why are in the sharing_msgs README, "Plausible evidence"."""

    max_sensor_reach: float = 5.0         # m: an advertised reach beyond this counts as this
    window: float = 2.0                   # s: an advert is evidence for messages stamped this close to it
    max_speed: float = 1.0                # m/s: how far the robot may have moved since (or until) the advert
    localisation_tolerance: float = 0.25  # m: the robot's own error placing what it saw in the map

    def __post_init__(self):
        for name, low, high in (("max_sensor_reach", 0.0, 1000.0), ("window", 0.0, 3600.0),
                                ("max_speed", 0.0, 100.0), ("localisation_tolerance", 0.0, 100.0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
                raise ValueError("%s %r must be %g..%g" % (name, value, low, high))


@dataclass(frozen=True)
class Sighting:
    """One advertised pose of a robot: its footprint's centroid (x, y) and circumradius, in ``frame_id``
    at ``stamp`` (the robot's own clock), its sensor ``reach`` (m) and, for a parked robot, how long it
    said the pose holds (``valid_for``, s)."""

    stamp: float
    x: float
    y: float
    radius: float
    reach: float
    frame_id: str = "map"
    valid_for: float = 0.0

    @classmethod
    def from_footprint(cls, points, stamp, reach, frame_id="map", valid_for=0.0):
        xs, ys = [p[0] for p in points], [p[1] for p in points]
        cx, cy = sum(xs) / len(xs), sum(ys) / len(ys)
        radius = max(math.hypot(x - cx, y - cy) for x, y in points)
        return cls(float(stamp), cx, cy, radius, float(reach), frame_id.lstrip("/"), min(float(valid_for), MAX_VALID_FOR))


@dataclass(frozen=True)
class Judgement:
    """What ``PoseHistory.judge`` kept of a message: the plausible ``marked`` and ``cleared`` cells, how many
    it ``refused``, and (when it refused any) ``why``, one line naming a refused cell, the pose and the limit."""

    marked: Tuple[int, ...]
    cleared: Tuple[int, ...]
    refused: int
    why: str = ""


class PoseHistory:
    """The sightings of every peer, and the judgement of a message's cells against them."""

    def __init__(self, rule=None, max_per_robot=MAX_SIGHTINGS_PER_ROBOT, max_robots=MAX_ROBOTS):
        self.rule = rule or EvidenceRule()
        self.max_per_robot = max_per_robot
        self.max_robots = max_robots
        self._robots = collections.OrderedDict()   # robot -> ([stamps], [sightings]), sorted by stamp

    def __contains__(self, robot):
        return robot in self._robots

    def note(self, robot, sighting):
        """Records a sighting of ``robot`` (any order of arrival; an exact repeat is kept once)."""
        held = self._robots.get(robot)
        if held is None:
            held = self._robots[robot] = ([], [])
            while len(self._robots) > self.max_robots:
                self._robots.popitem(last=False)
        else:
            self._robots.move_to_end(robot)
        stamps, sightings = held
        at = bisect.bisect_right(stamps, sighting.stamp)
        if at and sightings[at - 1] == sighting:
            return
        stamps.insert(at, sighting.stamp)
        sightings.insert(at, sighting)
        if len(stamps) > self.max_per_robot:
            del stamps[0]
            del sightings[0]

    def covering(self, robot, stamp, frame_id="map"):
        """The sightings of ``robot`` in ``frame_id`` that are evidence for a message stamped ``stamp``."""
        held = self._robots.get(robot)
        if held is None:
            return []
        stamps, sightings = held
        window = self.rule.window
        frame_id = frame_id.lstrip("/")
        lo = bisect.bisect_left(stamps, stamp - window)
        hi = bisect.bisect_right(stamps, stamp + window)
        found = sightings[lo:hi]
        # a parked robot's earlier advert holds for its validity: look back while one could still cover
        i = lo - 1
        while i >= 0 and stamps[i] >= stamp - MAX_VALID_FOR:
            if stamps[i] + sightings[i].valid_for >= stamp:
                found.append(sightings[i])
                break
            i -= 1
        return [s for s in found if s.frame_id == frame_id]

    def allowance(self, sighting, stamp, resolution):
        """m: how far from the sighting's centroid a cell centre may lie for a message stamped ``stamp``."""
        rule = self.rule
        dt = abs(stamp - sighting.stamp)
        if sighting.valid_for > 0 and sighting.stamp <= stamp <= sighting.stamp + sighting.valid_for:
            dt = min(dt, rule.window)    # parked: it advertises again at once when it moves
        return (min(max(sighting.reach, 0.0), rule.max_sensor_reach) + sighting.radius
                + resolution / math.sqrt(2.0) + rule.localisation_tolerance + rule.max_speed * dt)

    def judge(self, robot, stamp, frame_id, marked, cleared, resolution, origin_x, origin_y, size_x,
              rectangle=None):
        """Keeps the cells of a message of ``robot`` stamped ``stamp`` that lie within the allowance of a
        sighting covering the stamp. ``rectangle`` (min_x, min_y, max_x, max_y), when given, lets a message
        whose whole rectangle lies within one allowance pass without looking at each cell."""
        sightings = self.covering(robot, stamp, frame_id)
        if not sightings:
            refused = len(marked) + len(cleared)
            return Judgement((), (), refused, "no pose of %s advertised within %g s of the message's stamp %.3f"
                             " (in frame %r)%s" % (robot, self.rule.window, stamp, frame_id,
                                                   "" if robot in self else "; it never advertised one here"))
        reaches = [(s, self.allowance(s, stamp, resolution)) for s in sightings]
        if rectangle is not None:
            for s, allowed in reaches:
                far_x = max(abs(rectangle[0] - s.x), abs(rectangle[2] - s.x)) + resolution
                far_y = max(abs(rectangle[1] - s.y), abs(rectangle[3] - s.y)) + resolution
                if math.hypot(far_x, far_y) <= allowed:
                    return Judgement(tuple(marked), tuple(cleared), 0)
        worst = [None]

        def plausible(cell):
            cx = origin_x + (cell % size_x + 0.5) * resolution
            cy = origin_y + (cell // size_x + 0.5) * resolution
            best = None
            for s, allowed in reaches:
                d = math.hypot(cx - s.x, cy - s.y)
                if d <= allowed:
                    return True
                if best is None or d - allowed < best[0]:
                    best = (d - allowed, d, allowed, s, cell, cx, cy)
            if worst[0] is None or best[0] > worst[0][0]:
                worst[0] = best
            return False
        kept_marked = tuple(c for c in marked if plausible(c))
        kept_cleared = tuple(c for c in cleared if plausible(c))
        refused = len(marked) + len(cleared) - len(kept_marked) - len(kept_cleared)
        why = ""
        if refused:
            _, d, allowed, s, cell, cx, cy = worst[0]
            why = ("cell %d at (%.2f, %.2f) is %.2f m from %s's pose (%.2f, %.2f) advertised at %.3f, beyond "
                   "its reach %g m + slack = %.2f m" % (cell, cx, cy, d, robot, s.x, s.y, s.stamp,
                                                      min(s.reach, self.rule.max_sensor_reach), allowed))
        return Judgement(kept_marked, kept_cleared, refused, why)
