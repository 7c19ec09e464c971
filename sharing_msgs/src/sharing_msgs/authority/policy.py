"""Bounded authority of a peer (issue 27, issue 43, DESIGN.md §6a/§6c): the receiver's own caps on what
any message may make of an obstacle, and the window its stamp must lie in. Pure Python, no ROS.

A peer can send any value the message format carries (a whole-map rectangle, version 2^53-1,
deadline 2^32-1 s, a stamp from last week, 40,000 cells in a one-cell rectangle). None of them is
wrong as a format, so the format check (obstacle_rules) lets them through; what bounds them is this
policy, which every handler applies to everything from outside (fleet messages through the bridge,
Discover answers, ROS topics) and to every merge, and the bridges apply before a payload is expanded:

- extent: the longest side of an obstacle's rectangle. A robot's obstacle is at most what one robot
  could see: the diameter of its sensor reach (``single_robot_extent``, with ``max_sensor_reach``),
  and never more than ``max_extent``; master control's areas (source MASTER_CONTROL, which only the
  VDA 5050 bridge of the robot itself delivers) are bounded by ``max_extent`` alone;
- cells: the cells one obstacle may hold; and every cell of a message lies inside its rectangle
  (``check_cells_inside``): more cells than the rectangle holds, or one outside it, is a lie about
  the rectangle, and the caps above would mean nothing;
- lifetime: a deadline beyond the receiver's own obstacle_duration is cut to it;
- versions: at most ``max_version_step`` beyond the highest version seen for the obstacle (0 for
  one not held), so a single message cannot use up the version space. The same cap for every
  source, operators too: an operator's removal or confirmation (fleet_console) goes
  ``OPERATOR_VERSION_MARGIN`` beyond the highest version its page heard, and no receiver may set a
  step below ``MIN_VERSION_STEP`` (twice that), so a robot that holds up to a margin's worth fewer
  versions than the page heard still takes the operator's action;
- stamps (when ``max_clock_skew`` is set): not older than the lifetime cap plus the skew, not
  more than the skew in the future, so a captured message replayed later is refused.
"""
import math
from dataclasses import dataclass
from typing import Optional

from sharing_msgs.authority.errors import AuthorityError

#: The source name of master control's areas (the VDA 5050 bridge delivers them to its own robot's
#: handler). No robot may use it; its areas never merge with robots' obstacles.
MASTER_CONTROL = "master_control"

#: m added to the sensor reach on each side for the extent one robot can see: the sensor sits on the
#: robot's body, not at its centre (a footprint's circumradius, 0.46 m for the fleet's AGVs), and the
#: rectangle is drawn around whole cells. See the sharing_msgs README, "Plausible evidence".
EXTENT_SLACK = 0.5

#: Versions an operator's removal or confirmation (fleet_console, which reads it from the console server)
#: goes beyond the highest version its page heard for the obstacle: robots keep sending updates of it, and
#: one in flight at the same moment with the same version would win the tie (the greater source wins).
OPERATOR_VERSION_MARGIN = 100
#: The least ``max_version_step`` a receiver takes: an operator's action is at most OPERATOR_VERSION_MARGIN
#: beyond what the page heard, so a receiver that holds up to another margin fewer versions still takes it.
MIN_VERSION_STEP = 2 * OPERATOR_VERSION_MARGIN


def single_robot_extent(reach):
    """m: the longest side of a rectangle one robot with sensor reach ``reach`` can fill from one pose."""
    return 2.0 * (reach + EXTENT_SLACK)


@dataclass(frozen=True)
class PeerPolicy:
    """The caps; see the module docstring. ``max_obstacle_cells`` 0 means: the cells of a square
    of the extent cap on the grid in use (plus one cell of margin per side). ``max_sensor_reach``
    0 leaves robots' obstacles at ``max_extent`` (as before issue 43)."""

    max_extent: float               # m
    max_lifetime: int               # s, the receiver's obstacle_duration
    max_obstacle_cells: int = 0
    max_version_step: int = 1000000
    max_clock_skew: Optional[float] = None  # s; None = stamps are not compared with our clock
    max_sensor_reach: float = 0.0   # m; > 0: a robot's obstacle is at most single_robot_extent(it)

    def __post_init__(self):
        if not (isinstance(self.max_extent, (int, float)) and 0 < self.max_extent < 1e6):
            raise ValueError("max_obstacle_extent %r must be a positive number of metres" % (self.max_extent,))
        for name, low in (("max_obstacle_cells", 0), ("max_version_step", MIN_VERSION_STEP), ("max_lifetime", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError("%s %r must be an integer >= %d" % (name, value, low))
        skew = self.max_clock_skew
        if skew is not None and (isinstance(skew, bool) or not isinstance(skew, (int, float))
                                 or not 0 <= skew <= 3600):
            raise ValueError("max_clock_skew %r must be None or 0..3600 s" % (skew,))
        reach = self.max_sensor_reach
        if isinstance(reach, bool) or not isinstance(reach, (int, float)) or not 0 <= reach <= 1000:
            raise ValueError("max_sensor_reach %r must be 0..1000 m" % (reach,))

    # ------------------------------------------------------------------ caps

    def extent_cap(self, source=None):
        """m: the longest side an obstacle of ``source`` may have (a robot's unless it is MASTER_CONTROL)."""
        if source == MASTER_CONTROL or not self.max_sensor_reach:
            return self.max_extent
        return min(self.max_extent, single_robot_extent(self.max_sensor_reach))

    def cell_cap(self, geometry, source=None):
        if self.max_obstacle_cells:
            return self.max_obstacle_cells
        side = int(math.ceil(self.extent_cap(source) / geometry.resolution)) + 2
        return side * side

    def fits(self, rectangle, cell_count, geometry, source=None):
        """True when an obstacle of ``source`` with this rectangle and this many cells is within the caps."""
        return (max(rectangle.max_x - rectangle.min_x, rectangle.max_y - rectangle.min_y) <= self.extent_cap(source)
                and cell_count <= self.cell_cap(geometry, source))

    def check_extent(self, rectangle, what="rectangle", source=None):
        width, height = rectangle.max_x - rectangle.min_x, rectangle.max_y - rectangle.min_y
        cap = self.extent_cap(source)
        if max(width, height) > cap:
            why = ("max_obstacle_extent" if cap == self.max_extent else
                   "what one robot can see (2 x (max_sensor_reach %g + %g) m)" % (self.max_sensor_reach, EXTENT_SLACK))
            raise AuthorityError("oversized_rectangle", "%s %s is %g m x %g m, larger than %s %g m"
                                 % (what, rectangle, width, height, why, cap))

    def check_cells(self, count, geometry, what="obstacle", source=None):
        cap = self.cell_cap(geometry, source)
        if count > cap:
            raise AuthorityError("too_many_obstacle_cells", "%s would hold %d cells, more than "
                                 "max_obstacle_cells %d" % (what, count, cap))

    def check_version(self, version, highest_seen):
        """``highest_seen``: the obstacle's greatest version held here, 0 when it is new."""
        if version > highest_seen + self.max_version_step:
            raise AuthorityError("implausible_version", "version %d is more than max_version_step "
                                 "%d beyond the highest seen for it (%d)"
                                 % (version, self.max_version_step, highest_seen))

    def cap_deadline(self, deadline):
        """A deadline (s left) cut to the receiver's lifetime cap: no peer extends a lease beyond it."""
        return min(deadline, self.max_lifetime)

    # ---------------------------------------------------------------- stamps

    @property
    def max_message_age(self):
        """s; None when stamps are not checked. A message's own lifetime runs from its stamp, at
        most max_lifetime, so one stamped earlier than that (plus the skew) is dead everywhere."""
        return None if self.max_clock_skew is None else self.max_lifetime + self.max_clock_skew

    @property
    def tombstone_time(self):
        """s an expired uuid is remembered: with stamps checked, long enough that a message which
        still passes the stamp check cannot arrive after its tombstone is gone (lifetime + skew
        for its age, + skew for a stamp ahead of our clock)."""
        if self.max_clock_skew is None:
            return self.max_lifetime
        return self.max_lifetime + 2 * self.max_clock_skew

    def check_stamp(self, stamp, now):
        if self.max_clock_skew is None:
            return
        if stamp < now - self.max_message_age:
            raise AuthorityError("stale_stamp", "stamp %.3f is %.1f s old, more than %g s "
                                 "(obstacle_duration + max_clock_skew): a replay or a dead message"
                                 % (stamp, now - stamp, self.max_message_age))
        if stamp > now + self.max_clock_skew:
            raise AuthorityError("future_stamp", "stamp %.3f is %.1f s ahead of our clock, more "
                                 "than max_clock_skew %g s" % (stamp, stamp - now, self.max_clock_skew))


# -------------------------------------------------------------------- cells and their rectangle

#: How far (in cells) a cell's centre may lie outside the rectangle: a rectangle travels as float32 (a
#: micrometre off at 100 m), and every producer draws it around whole cells (the layer, merges, manual
#: adds, master control's areas), so centres lie half a cell inside. A hundredth of a cell leaves no room
#: for a neighbouring cell, whose centre lies half a cell outside.
INSIDE_TOLERANCE_CELLS = 0.01


def rectangle_capacity(rectangle, resolution, origin_x, origin_y):
    """How many cells of the grid (``resolution``, ``origin_x``, ``origin_y``) have their centre inside
    ``rectangle`` (within the tolerance)."""
    tolerance = INSIDE_TOLERANCE_CELLS * resolution

    def span(low, high, origin):
        first = math.ceil((low - tolerance - origin) / resolution - 0.5)
        last = math.floor((high + tolerance - origin) / resolution - 0.5)
        return max(0, last - first + 1)
    return (span(rectangle.min_x, rectangle.max_x, origin_x) * span(rectangle.min_y, rectangle.max_y, origin_y))


def check_cells_inside(rectangle, marked, cleared, resolution, origin_x, origin_y, size_x, what="message"):
    """Raises AuthorityError unless every cell of ``marked`` and ``cleared`` has its centre inside
    ``rectangle`` (within INSIDE_TOLERANCE_CELLS) and there are no more cells than the rectangle holds. A
    one-cell rectangle with 40,000 cells (issue 43, item 1) is a lie about the rectangle, and every cap
    on it would mean nothing."""
    count = len(set(marked).union(cleared))
    capacity = rectangle_capacity(rectangle, resolution, origin_x, origin_y)
    if count > capacity:
        raise AuthorityError("more_cells_than_rectangle", "%s has %d cells, its rectangle %s holds at most %d"
                             % (what, count, rectangle, capacity))
    tolerance = INSIDE_TOLERANCE_CELLS * resolution
    low_x, high_x = rectangle.min_x - tolerance, rectangle.max_x + tolerance
    low_y, high_y = rectangle.min_y - tolerance, rectangle.max_y + tolerance
    for name, cells in (("marked", marked), ("cleared", cleared)):
        for cell in cells:
            cx = origin_x + (cell % size_x + 0.5) * resolution
            cy = origin_y + (cell // size_x + 0.5) * resolution
            if not (low_x <= cx <= high_x and low_y <= cy <= high_y):
                raise AuthorityError("cells_outside_rectangle", "%s: %s cell %d (centre %.3f, %.3f) lies outside its "
                                     "rectangle %s" % (what, name, cell, cx, cy, rectangle))
