"""Value types of the handler, validated on construction (no ROS in here).

Every type is a frozen dataclass whose ``__post_init__`` raises a SharingError subclass that
names the bad value, so an object that exists is well-formed. What depends on the receiving
handler (its grid, its robot name, what it already holds) is checked in ``logic``.
"""
import math
import re
from dataclasses import dataclass, replace
from typing import Tuple

from sharing_handler_py.errors import InvalidMessageError, InvalidParameterError
from sharing_msgs import obstacle_rules
from sharing_msgs.authority import MIN_VERSION_STEP, OPERATOR_VERSION_MARGIN

#: Relative tolerance for comparing resolutions and origins of two grids.
GEOMETRY_REL_TOL = 1e-6
#: Longest uuid accepted from outside (uuid4 text is 36 characters).
MAX_UUID_LENGTH = 64
_UUID_CHARS = re.compile(r"^[A-Za-z0-9_.:-]+$")
_MAX_INDEX = 2 ** 32  # indexes travel as uint32


def _close(a, b, floor):
    """True when a and b agree within GEOMETRY_REL_TOL relative, or within `floor` near zero."""
    return abs(a - b) <= max(GEOMETRY_REL_TOL * max(abs(a), abs(b)), floor)


@dataclass(frozen=True)
class Geometry:
    """The grid that cell indexes (y * size_x + x) refer to."""

    resolution: float  # metres per cell
    origin_x: float    # world x of the corner of cell (0, 0), metres
    origin_y: float
    size_x: int        # cells
    size_y: int

    def __post_init__(self):
        if not (isinstance(self.resolution, (int, float)) and math.isfinite(self.resolution)
                and self.resolution > 0):
            raise InvalidMessageError("bad_geometry", "resolution %r is not a positive finite number"
                                      % (self.resolution,))
        for name in ("origin_x", "origin_y"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise InvalidMessageError("bad_geometry", "%s %r is not finite" % (name, value))
        for name in ("size_x", "size_y"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InvalidMessageError("bad_geometry", "%s %r is not a positive integer"
                                          % (name, value))
        if self.size_x * self.size_y > _MAX_INDEX:
            raise InvalidMessageError("bad_geometry", "%d x %d cells do not fit uint32 indexes"
                                      % (self.size_x, self.size_y))

    @property
    def cell_count(self):
        return self.size_x * self.size_y

    def matches(self, other):
        """Same grid: sizes exact; resolution and origin within 1e-6 relative (for an origin
        near zero, within a millionth of a cell)."""
        floor = GEOMETRY_REL_TOL * self.resolution
        return (self.size_x == other.size_x and self.size_y == other.size_y
                and _close(self.resolution, other.resolution, 0.0)
                and _close(self.origin_x, other.origin_x, floor)
                and _close(self.origin_y, other.origin_y, floor))

    def cells_in(self, rectangle):
        """Indexes of the cells whose centre lies inside `rectangle` (closed), sorted."""
        def span(lo, hi, origin, size):
            first = max(0, math.ceil((lo - origin) / self.resolution - 0.5))
            last = min(size - 1, math.floor((hi - origin) / self.resolution - 0.5))
            return range(first, last + 1)
        xs = span(rectangle.min_x, rectangle.max_x, self.origin_x, self.size_x)
        return tuple(y * self.size_x + x
                     for y in span(rectangle.min_y, rectangle.max_y, self.origin_y, self.size_y)
                     for x in xs)

    def __str__(self):
        return "%gm/cell origin (%g, %g) %dx%d" % (self.resolution, self.origin_x, self.origin_y,
                                                    self.size_x, self.size_y)


@dataclass(frozen=True)
class Rectangle:
    """A monitored subsection [min_x, min_y, max_x, max_y] in metres."""

    min_x: float
    min_y: float
    max_x: float
    max_y: float

    def __post_init__(self):
        values = (self.min_x, self.min_y, self.max_x, self.max_y)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise InvalidMessageError("non_finite_rectangle", "rectangle %r" % (list(values),))
        if self.min_x > self.max_x or self.min_y > self.max_y:
            raise InvalidMessageError("malformed", "rectangle %r has min > max" % (list(values),))

    @classmethod
    def from_sequence(cls, values):
        """[min_x, min_y, max_x, max_y] -> Rectangle; any other length is malformed."""
        values = list(values)
        if len(values) != 4:
            raise InvalidMessageError("malformed", "rectangle_shape has %d values, expected 4: %r"
                                      % (len(values), values[:8]))
        return cls(*(float(v) for v in values))

    def as_list(self):
        return [self.min_x, self.min_y, self.max_x, self.max_y]

    def overlaps(self, other):
        """Positive-area intersection. Along an axis where either rectangle has zero extent,
        touching counts (a degenerate rectangle on another's edge overlaps it)."""
        def axis(a_lo, a_hi, b_lo, b_hi):
            lo, hi = max(a_lo, b_lo), min(a_hi, b_hi)
            return lo < hi or (lo == hi and (a_lo == a_hi or b_lo == b_hi))
        return (axis(self.min_x, self.max_x, other.min_x, other.max_x)
                and axis(self.min_y, self.max_y, other.min_y, other.max_y))

    def gap(self, other):
        """Distance between the two rectangles along the axis where they lie farthest apart
        (0 when they touch or overlap): how wide a passage between them can be."""
        return max(0.0, other.min_x - self.max_x, self.min_x - other.max_x,
                   other.min_y - self.max_y, self.min_y - other.max_y)

    def union(self, other):
        """The smallest rectangle holding both; a join (commutative, associative, idempotent),
        so a rectangle grown by unions is the same on every robot whatever the order."""
        if self.contains(other):
            return self
        return Rectangle(min(self.min_x, other.min_x), min(self.min_y, other.min_y),
                         max(self.max_x, other.max_x), max(self.max_y, other.max_y))

    def contains(self, other):
        return (self.min_x <= other.min_x and self.min_y <= other.min_y
                and self.max_x >= other.max_x and self.max_y >= other.max_y)

    def __str__(self):
        return "[%g, %g, %g, %g]" % (self.min_x, self.min_y, self.max_x, self.max_y)


@dataclass(frozen=True)
class Obstacle:
    """One message of the protocol as a plain value: a proposal (uuid ''), a first share
    (version 1) or an update. Mirrors sharing_msgs/SharedObstacle."""

    uuid: str
    marked: Tuple[int, ...]
    cleared: Tuple[int, ...]
    deadline: int          # seconds the obstacle lives after local arrival
    rectangle: Rectangle
    source: str            # robot that made this update
    geometry: Geometry
    version: int = 0
    frame_id: str = ""
    stamp: float = 0.0     # header stamp, seconds

    def __post_init__(self):
        if not isinstance(self.marked, tuple):
            object.__setattr__(self, "marked", tuple(self.marked))
        if not isinstance(self.cleared, tuple):
            object.__setattr__(self, "cleared", tuple(self.cleared))
        if not isinstance(self.uuid, str) or not isinstance(self.source, str):
            raise InvalidMessageError("malformed", "uuid %r / source %r are not strings"
                                      % (self.uuid, self.source))
        for name in ("deadline", "version"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise InvalidMessageError("malformed", "%s %r is not a non-negative integer"
                                          % (name, value))
        if not isinstance(self.rectangle, Rectangle) or not isinstance(self.geometry, Geometry):
            raise InvalidMessageError("malformed", "rectangle/geometry of wrong type: %r, %r"
                                      % (type(self.rectangle).__name__, type(self.geometry).__name__))

    def replace(self, **changes):
        return replace(self, **changes)

    @property
    def stamp_key(self):
        """The (version, source) pair that orders updates of one obstacle."""
        return (self.version, self.source)


def check_uuid(uuid):
    """Raises InvalidMessageError unless `uuid` is a plausible obstacle id."""
    if not uuid:
        raise InvalidMessageError("empty_uuid", "uuid is empty")
    if len(uuid) > MAX_UUID_LENGTH or not _UUID_CHARS.match(uuid):
        raise InvalidMessageError("malformed", "uuid %r is not an id (max %d chars of [A-Za-z0-9_.:-])"
                                  % (uuid[:80], MAX_UUID_LENGTH))


def check_indexes(obstacle, geometry, max_cells):
    """Raises unless the message's cell count is <= max_cells and every index is on `geometry`."""
    count = len(obstacle.marked) + len(obstacle.cleared)
    if count > max_cells:
        raise InvalidMessageError("too_many_cells", "%d cell indexes > max_cells_per_message %d"
                                  % (count, max_cells))
    limit = geometry.cell_count
    for name, cells in (("marked_indexes", obstacle.marked), ("cleared_indexes", obstacle.cleared)):
        if cells:
            low, high = min(cells), max(cells)
            if low < 0 or high >= limit:
                bad = high if high >= limit else low
                raise InvalidMessageError("index_out_of_range", "%s holds %d, grid has %d cells (%s)"
                                          % (name, bad, limit, geometry))


def _rule_fields(obstacle):
    g = obstacle.geometry
    return (obstacle.uuid, obstacle.source, obstacle.version, obstacle.stamp, obstacle.frame_id,
            obstacle.deadline, obstacle.rectangle.as_list(), g.resolution, g.origin_x, g.origin_y,
            g.size_x, g.size_y, obstacle.marked, obstacle.cleared)


def _drop_reason(err):
    """obstacle_rules.ObstacleFieldError -> one of logic.DROP_REASONS."""
    field, kind = err.field, err.kind
    if field == "uuid":
        return "empty_uuid" if kind == obstacle_rules.EMPTY else "malformed"
    if field == "version":
        return "bad_version"
    if field == "deadline":
        return "zero_deadline" if err.value == 0 else "malformed"
    if field == "stamp":
        return "bad_stamp"
    if field in ("resolution", "origin_x", "origin_y", "size_x", "size_y"):
        return "bad_geometry"
    if field == "rectangle_shape":
        if kind == obstacle_rules.NON_FINITE:
            return "non_finite_rectangle"
        return "rectangle_outside_grid" if kind == obstacle_rules.OUTSIDE_GRID else "malformed"
    if field in ("marked_indexes", "cleared_indexes"):
        return {obstacle_rules.TOO_MANY: "too_many_cells", obstacle_rules.OUT_OF_RANGE: "index_out_of_range",
                obstacle_rules.EMPTY: "empty_update"}.get(kind, "malformed")
    return "malformed"


def check_message_values(obstacle):
    """Raises InvalidMessageError unless every field of `obstacle` fits sharing_msgs/SharedObstacle
    and its own grid (the rules the bridge applies too; a proposal's empty uuid passes)."""
    try:
        obstacle_rules.check_values(*_rule_fields(obstacle))
    except obstacle_rules.ObstacleFieldError as err:
        raise InvalidMessageError(_drop_reason(err), str(err)) from None


def check_fleet_message(obstacle):
    """Raises InvalidMessageError unless `obstacle` is a valid message between robots: exactly
    the check the bridge applies to what it receives over MQTT and what it sends."""
    try:
        obstacle_rules.check_fleet(*_rule_fields(obstacle))
    except obstacle_rules.ObstacleFieldError as err:
        raise InvalidMessageError(_drop_reason(err), str(err)) from None


@dataclass(frozen=True)
class HandlerParams:
    """The node's parameters, checked at start-up. Field names are the private parameter names."""

    robot_name: str
    obstacle_duration: float = 1200.0  # s, deadline given to authorised obstacles (the lease; README, "Lifecycle")
    expiry_rate: float = 1.0           # Hz, expiry check, diagnostics and snapshot
    snapshot_file: str = ""            # YAML snapshot path; "" = off
    max_cells_per_message: int = 100000
    map_topic: str = "/map"
    max_obstacle_extent: float = 10.0  # m, longest side of a manually added obstacle
    merge_distance: float = 0.5        # m, obstacles and proposals this close are one obstacle
    # issue 27, bounded authority of a peer (authority.py)
    max_obstacle_cells: int = 0        # cells one obstacle may hold; 0 = a max_obstacle_extent square
    max_version_step: int = 1000000    # a version more than this beyond the highest seen is dropped
    max_clock_skew: float = 5.0        # s; stamps older than obstacle_duration + this or ahead by more
                                       # than this are dropped; -1 = stamps not checked
    # issue 27, per-source quotas (quotas.py)
    max_obstacles_per_source: int = 1000   # live obstacles one peer may hold here; new ones beyond are dropped
    source_update_rate: float = 100.0      # messages per s per source (token bucket) ...
    source_update_burst: int = 2000        # ... with this burst; the excess is dropped
    list_cost_share: float = 0.05          # at most this share of time goes to rebuilding the latched list
    # issue 43: what one robot can see; a robot's obstacle is at most 2 x (this + 0.5 m) across (0: only
    # max_obstacle_extent bounds it)
    max_sensor_reach: float = 4.0
    # issue 43: fleet messages waiting per source before the handler takes them (fair delivery)
    source_queue_size: int = 200

    def __post_init__(self):
        def bad(name, why):
            raise InvalidParameterError("~%s = %r: %s" % (name, getattr(self, name), why))
        if not isinstance(self.robot_name, str) or not self.robot_name.strip():
            bad("robot_name", "must be a non-empty string (set it when the node runs outside a "
                              "robot namespace)")
        if "/" in self.robot_name:
            bad("robot_name", "must not contain '/'")
        for name in ("obstacle_duration", "expiry_rate"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                bad(name, "must be a finite number")
        if not 1.0 <= self.obstacle_duration <= 2.0 ** 32 - 1:
            bad("obstacle_duration", "must be in [1, 4294967295] seconds")
        if not 0.0 < self.expiry_rate <= 1000.0:
            bad("expiry_rate", "must be in (0, 1000] Hz")
        if not isinstance(self.snapshot_file, str):
            bad("snapshot_file", "must be a path string ('' = off)")
        value = self.max_cells_per_message
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            bad("max_cells_per_message", "must be a positive integer")
        if not isinstance(self.map_topic, str) or not self.map_topic:
            bad("map_topic", "must be a non-empty topic name")
        value = self.max_obstacle_extent
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1e6:
            bad("max_obstacle_extent", "must be a positive number of metres below 1e6")
        value = self.merge_distance
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1e6:
            bad("merge_distance", "must be a number of metres in [0, 1e6)")
        for name, low in (("max_obstacle_cells", 0), ("max_version_step", MIN_VERSION_STEP)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                bad(name, "must be an integer >= %d" % low + (" (an operator's action on the fleet console goes "
                    "up to %d versions beyond the highest heard)" % OPERATOR_VERSION_MARGIN
                    if name == "max_version_step" else ""))
        value = self.max_clock_skew
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                value == -1 or 0 <= value <= 3600):
            bad("max_clock_skew", "must be 0..3600 seconds, or -1 (stamps not checked)")
        for name, low in (("max_obstacles_per_source", 1), ("source_update_burst", 1), ("source_queue_size", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                bad(name, "must be an integer >= %d" % low)
        value = self.source_update_rate
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1e9:
            bad("source_update_rate", "must be a positive number of messages per second")
        value = self.max_sensor_reach
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1000:
            bad("max_sensor_reach", "must be 0..1000 metres (0: robots' obstacles bounded by max_obstacle_extent alone)")
        value = self.list_cost_share
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 1:
            bad("list_cost_share", "must be in (0, 1]")

    @property
    def clock_skew(self):
        """max_clock_skew as the handler takes it: None when stamps are not checked."""
        return None if self.max_clock_skew == -1 else float(self.max_clock_skew)
