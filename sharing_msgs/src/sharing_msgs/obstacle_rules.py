"""The one validation of a SharedObstacle, shared by coaty_bridge and sharing_handler_py.

Pure Python (no rospy, no paho), so both packages and their pure tests use it. Two levels:

- ``check_values``: every field fits what ``sharing_msgs/SharedObstacle`` can carry and what a
  receiver can use (ROS time range, uint32 / version ranges, float32 and float64 finiteness,
  index arrays on the grid, a rectangle inside the grid). Any message that passes serialises and
  can be published. A proposal (uuid "", version 0, deadline 0) passes this level.
- ``check_fleet``: ``check_values`` plus what a message travelling between robots must have:
  a UUID, a version >= 1, a deadline >= 1 and at least one cell index.

The bridge checks both levels on every obstacle that arrives over MQTT and every one it sends;
the handler checks both on every ``from_fleet`` message, so neither is looser than the other.
A failed check raises ``ObstacleFieldError`` naming the field, the kind of fault and the value;
each package maps it to its own drop counter.
"""
import math
import re

#: ROS time is uint32 seconds + uint32 nanoseconds. A stamp is kept one second below the end of
#: the range, so that rounding the nanoseconds up can never carry into an overflow.
MAX_STAMP = float(2 ** 32 - 1)
MAX_UINT32 = 2 ** 32 - 1
#: Versions travel as JSON numbers; a JS number holds integers exactly up to 2**53 - 1 (and the
#: message field is uint64, so this bound is the tighter one).
MAX_VERSION = 2 ** 53 - 1
#: Largest finite float32 (rectangle_shape and resolution are float32 in the message).
MAX_FLOAT32 = 3.4028234663852886e38
#: Longest source / frame_id.
MAX_TEXT = 256
#: A rectangle may reach this many cells beyond the grid's edge (bounding boxes of edge cells).
RECTANGLE_MARGIN_CELLS = 1.0

UUID_RE = re.compile(r"^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}$")
_FORBIDDEN_IN_NAME = re.compile(r"[\u0000+#/]")
#: A lone UTF-16 surrogate: JSON's "\ud800" escape makes one, Python keeps it in a str, and ROS
#: serialisation (UTF-8) then fails with a traceback far from the input (issue 27, item 8).
_SURROGATE = re.compile("[\ud800-\udfff]")

#: Kinds of fault (ObstacleFieldError.kind).
WRONG_TYPE = "wrong_type"
NON_FINITE = "non_finite"
OUT_OF_RANGE = "out_of_range"
TOO_MANY = "too_many"
EMPTY = "empty"
OUTSIDE_GRID = "outside_grid"


class ObstacleFieldError(ValueError):
    """One field of a SharedObstacle is unusable. ``field`` is the message field name,
    ``kind`` one of the kinds above, ``value`` the (possibly shortened) bad value."""

    def __init__(self, field, kind, value, why):
        self.field = field
        self.kind = kind
        self.value = value
        super().__init__("%s %s %s" % (field, _short(value), why))


def _short(value):
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def lone_surrogate(text):
    """Why ``text`` cannot be sent as UTF-8 (it holds a lone UTF-16 surrogate), or "" when it can."""
    bad = _SURROGATE.search(text)
    if not bad:
        return ""
    return "contains the lone UTF-16 surrogate U+%04X at index %d: not encodable as UTF-8" % (
        ord(bad.group()), bad.start())


def is_uuid(value):
    return isinstance(value, str) and bool(UUID_RE.match(value))


def _integer(field, value, low, high):
    if isinstance(value, bool) or not isinstance(value, int):
        raise ObstacleFieldError(field, WRONG_TYPE, value, "is not an integer")
    if not low <= value <= high:
        raise ObstacleFieldError(field, OUT_OF_RANGE, value, "outside %d..%d" % (low, high))


def _number(field, value, limit):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ObstacleFieldError(field, WRONG_TYPE, value, "is not a number")
    if not math.isfinite(value):
        raise ObstacleFieldError(field, NON_FINITE, value, "is not finite")
    if abs(value) > limit:
        # A float32 field turns it into infinity; a float64 one would carry it, but no map is
        # that large, so one bound serves both.
        raise ObstacleFieldError(field, NON_FINITE, value, "is not finite as float32 (|v| > %g)" % limit)


def _text(field, value, allow_empty):
    if not isinstance(value, str):
        raise ObstacleFieldError(field, WRONG_TYPE, value, "is not a string")
    if not value and not allow_empty:
        raise ObstacleFieldError(field, EMPTY, value, "is empty")
    if len(value) > MAX_TEXT:
        raise ObstacleFieldError(field, OUT_OF_RANGE, value, "is longer than %d characters" % MAX_TEXT)
    why = lone_surrogate(value)
    if why:
        raise ObstacleFieldError(field, OUT_OF_RANGE, value, why)


def check_values(uuid, source, version, stamp, frame_id, deadline, rectangle, resolution,
                 origin_x, origin_y, size_x, size_y, marked, cleared):
    """Raises ObstacleFieldError unless every field fits the message and the grid it names.
    ``uuid`` may be "" (a proposal); otherwise it must be a UUID."""
    if not isinstance(uuid, str) or (uuid and not UUID_RE.match(uuid)):
        raise ObstacleFieldError("uuid", OUT_OF_RANGE, uuid, "is not a UUID")
    _text("source", source, allow_empty=True)
    if _FORBIDDEN_IN_NAME.search(source):
        raise ObstacleFieldError("source", OUT_OF_RANGE, source, "contains NUL, '/', '+' or '#'")
    _text("frame_id", frame_id, allow_empty=True)
    if "\0" in frame_id:
        raise ObstacleFieldError("frame_id", OUT_OF_RANGE, frame_id, "contains NUL")
    _integer("version", version, 0, MAX_VERSION)
    _integer("deadline", deadline, 0, MAX_UINT32)
    _number("stamp", stamp, MAX_FLOAT32)
    if not 0.0 <= stamp < MAX_STAMP:
        raise ObstacleFieldError("stamp", OUT_OF_RANGE, stamp,
                                 "outside the ROS time range [0, %d) s" % int(MAX_STAMP))
    _number("resolution", resolution, MAX_FLOAT32)
    if not resolution > 0:
        raise ObstacleFieldError("resolution", OUT_OF_RANGE, resolution, "is not positive")
    _number("origin_x", origin_x, MAX_FLOAT32)
    _number("origin_y", origin_y, MAX_FLOAT32)
    _integer("size_x", size_x, 1, MAX_UINT32)
    _integer("size_y", size_y, 1, MAX_UINT32)
    cells = size_x * size_y
    if cells > MAX_UINT32 + 1:
        raise ObstacleFieldError("size_x", OUT_OF_RANGE, (size_x, size_y),
                                 "has more cells than a uint32 index can address")
    _check_rectangle(rectangle, resolution, origin_x, origin_y, size_x, size_y)
    for field, values in (("marked_indexes", marked), ("cleared_indexes", cleared)):
        if len(values) > cells:
            raise ObstacleFieldError(field, TOO_MANY, len(values), "indexes for a grid of %d cells" % cells)
        for value in values:
            if isinstance(value, bool) or not isinstance(value, int):
                raise ObstacleFieldError(field, WRONG_TYPE, value, "is not an integer index")
            if not 0 <= value < cells:
                raise ObstacleFieldError(field, OUT_OF_RANGE, value,
                                         "is outside the %d x %d grid" % (size_x, size_y))


def _check_rectangle(rectangle, resolution, origin_x, origin_y, size_x, size_y):
    try:
        rect = tuple(rectangle)
    except TypeError:
        raise ObstacleFieldError("rectangle_shape", WRONG_TYPE, rectangle, "is not a list")
    if len(rect) != 4:
        raise ObstacleFieldError("rectangle_shape", WRONG_TYPE, rect[:8], "does not have 4 values")
    for value in rect:
        _number("rectangle_shape", value, MAX_FLOAT32)
    min_x, min_y, max_x, max_y = rect
    if min_x > max_x or min_y > max_y:
        raise ObstacleFieldError("rectangle_shape", OUT_OF_RANGE, list(rect), "has min > max")
    # The monitored subsection lies on the map: a rectangle far beyond it (a whole-world
    # [-1e38, ..., 1e38]) would make every later proposal look redundant on every robot.
    margin = RECTANGLE_MARGIN_CELLS * resolution
    low_x, low_y = origin_x - margin, origin_y - margin
    high_x = origin_x + size_x * resolution + margin
    high_y = origin_y + size_y * resolution + margin
    if min_x < low_x or min_y < low_y or max_x > high_x or max_y > high_y:
        raise ObstacleFieldError("rectangle_shape", OUTSIDE_GRID, list(rect),
                                 "is not inside the grid [%g, %g, %g, %g]" % (low_x, low_y, high_x, high_y))


def check_fleet(uuid, source, version, stamp, frame_id, deadline, rectangle, resolution,
                origin_x, origin_y, size_x, size_y, marked, cleared):
    """``check_values`` plus what every message between robots needs: a UUID, a source,
    version >= 1, deadline >= 1 and at least one cell index (an update without cells carries
    nothing; an obstacle that only exists as an id is not worth holding)."""
    check_values(uuid, source, version, stamp, frame_id, deadline, rectangle, resolution,
                 origin_x, origin_y, size_x, size_y, marked, cleared)
    if not uuid:
        raise ObstacleFieldError("uuid", EMPTY, uuid, "is empty")
    if not source:
        raise ObstacleFieldError("source", EMPTY, source, "is empty")
    if version < 1:
        raise ObstacleFieldError("version", OUT_OF_RANGE, version, "is 0 (a proposal) on the fleet channel")
    if deadline < 1:
        raise ObstacleFieldError("deadline", OUT_OF_RANGE, deadline, "is 0: it would expire on arrival")
    if not marked and not cleared:
        raise ObstacleFieldError("marked_indexes", EMPTY, 0, "and cleared_indexes are both empty")
