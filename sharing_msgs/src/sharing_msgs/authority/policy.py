"""Bounded authority of a peer (issue 27, DESIGN.md §6a): the receiver's own caps on what any
message may make of an obstacle, and the window its stamp must lie in. Pure Python, no ROS.

A peer can send any value the message format carries (a whole-map rectangle, version 2^53-1,
deadline 2^32-1 s, a stamp from last week). None of them is wrong as a format, so the bridge's
format check lets them through; what bounds them is this policy, which every handler applies
to everything from outside (fleet messages through the bridge, Discover answers, ROS topics)
and to every merge:

- extent: the longest side of an obstacle's rectangle (the same cap add_obstacle has);
- cells: the cells one obstacle may hold;
- lifetime: a deadline beyond the receiver's own obstacle_duration is cut to it;
- versions: at most ``max_version_step`` beyond the highest version seen for the obstacle (0 for
  one not held), so a single message cannot use up the version space;
- stamps (when ``max_clock_skew`` is set): not older than the lifetime cap plus the skew, not
  more than the skew in the future, so a captured message replayed later is refused.
"""
import math
from dataclasses import dataclass
from typing import Optional

from sharing_msgs.authority.errors import AuthorityError


@dataclass(frozen=True)
class PeerPolicy:
    """The caps; see the module docstring. ``max_obstacle_cells`` 0 means: the cells of a square
    of ``max_extent`` on the grid in use (plus one cell of margin per side)."""

    max_extent: float               # m
    max_lifetime: int               # s, the receiver's obstacle_duration
    max_obstacle_cells: int = 0
    max_version_step: int = 1000000
    max_clock_skew: Optional[float] = None  # s; None = stamps are not compared with our clock

    def __post_init__(self):
        if not (isinstance(self.max_extent, (int, float)) and 0 < self.max_extent < 1e6):
            raise ValueError("max_obstacle_extent %r must be a positive number of metres" % (self.max_extent,))
        for name, low in (("max_obstacle_cells", 0), ("max_version_step", 1), ("max_lifetime", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError("%s %r must be an integer >= %d" % (name, value, low))
        skew = self.max_clock_skew
        if skew is not None and (isinstance(skew, bool) or not isinstance(skew, (int, float))
                                 or not 0 <= skew <= 3600):
            raise ValueError("max_clock_skew %r must be None or 0..3600 s" % (skew,))

    # ------------------------------------------------------------------ caps

    def cell_cap(self, geometry):
        if self.max_obstacle_cells:
            return self.max_obstacle_cells
        side = int(math.ceil(self.max_extent / geometry.resolution)) + 2
        return side * side

    def fits(self, rectangle, cell_count, geometry):
        """True when an obstacle with this rectangle and this many cells is within the caps."""
        return (max(rectangle.max_x - rectangle.min_x, rectangle.max_y - rectangle.min_y) <= self.max_extent
                and cell_count <= self.cell_cap(geometry))

    def check_extent(self, rectangle, what="rectangle"):
        width, height = rectangle.max_x - rectangle.min_x, rectangle.max_y - rectangle.min_y
        if max(width, height) > self.max_extent:
            raise AuthorityError("oversized_rectangle", "%s %s is %g m x %g m, larger than "
                                      "max_obstacle_extent %g m" % (what, rectangle, width, height,
                                                                    self.max_extent))

    def check_cells(self, count, geometry, what="obstacle"):
        cap = self.cell_cap(geometry)
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
