"""Coaty JSON <-> validated obstacle values. Imports neither paho nor rospy.

Wire form of one obstacle update (a CoatyObject of the configured objectType;
one object per obstacle: objectId is the obstacle uuid, every update of the
obstacle re-advertises it with a higher version)::

    {"objectType": "org.fleetsharing.SharedObstacle", "coreType": "CoatyObject",
     "objectId": <uuid>, "name": "<first 8 of uuid>",
     "uuid": <uuid>, "source": "robot_0", "version": 3, "stamp": 1700000000.25,
     "frameId": "map", "deadline": 60, "rectangle": [min_x, min_y, max_x, max_y],
     "resolution": 0.05, "origin": [x, y], "size": [size_x, size_y],
     "markedIndexes": [...] | "<compact>", "clearedIndexes": [...] | "<compact>",
     "evidence": [stamp, x, y, radius, reach]}

An index field is either a JSON array of ints or a string in the compact
encoding of ``compact.py``; both mean the same set. ``evidence`` (optional) is where the
sender stood when it saw the cells: its footprint's centroid (x, y) and circumradius in
``frameId``, taken at ``stamp`` on its own clock, and how far its sensors reach from there
(m): what receivers judge its cells by (sharing_msgs.authority.evidence; evidence.py).
"""
import json
import math
from dataclasses import dataclass, field
from typing import Optional, Tuple

from coaty_bridge import compact
from coaty_bridge.areas import parse_area
from coaty_bridge.errors import (CoatyError, InvalidJsonError, InvalidPayloadError, MissingFieldError,
                                 NonFiniteNumberError, OutOfRangeError, PayloadTooLargeError,
                                 TooManyIndexesError, WrongTypeError)
from coaty_bridge.topics import check_uuid, _UUID_RE
from coaty_bridge.errors import (CellsOutsideRectangleError, InvalidNameError, ObstacleCellsError, ObstacleExtentError,
                                 RectangleCellsError)
from sharing_msgs import obstacle_rules
from sharing_msgs.authority import AuthorityError, PeerPolicy, check_cells_inside, rectangle_capacity

IDENTITY_OBJECT_TYPE = "coaty.Identity"
IDENTITY_CORE_TYPE = "Identity"
DEFAULT_OBJECT_TYPE = "org.fleetsharing.SharedObstacle"
MAX_SAFE_INTEGER = obstacle_rules.MAX_VERSION  # largest integer a JS number holds exactly
MAX_UINT32 = obstacle_rules.MAX_UINT32
MAX_TEXT = obstacle_rules.MAX_TEXT


@dataclass(frozen=True)
class _Geometry:
    resolution: float


@dataclass(frozen=True)
class _Rectangle:
    min_x: float
    min_y: float
    max_x: float
    max_y: float

    def __str__(self):
        return "[%g, %g, %g, %g]" % (self.min_x, self.min_y, self.max_x, self.max_y)


@dataclass(frozen=True)
class CodecLimits:
    """Bounds applied to everything that arrives."""
    max_payload_bytes: int = 1024 * 1024
    max_indexes: int = 1_000_000
    # The handler's caps (sharing_msgs.authority.PeerPolicy, the same rules): checked
    # here before the index sets are expanded (issue 27, attack 4).
    max_obstacle_extent: float = 10.0   # m, longest side of the rectangle
    max_obstacle_cells: int = 0         # 0 = the cells of a square of the extent cap (+1 cell a side)
    # m; > 0: a robot's obstacle is at most what one robot can see across (issue 43, PeerPolicy)
    max_sensor_reach: float = 0.0

    def __post_init__(self):
        for name in ("max_payload_bytes", "max_indexes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError("%s must be a positive integer, got %r" % (name, value))
        # PeerPolicy validates both caps and raises ValueError naming a bad one
        object.__setattr__(self, "policy", PeerPolicy(max_extent=self.max_obstacle_extent, max_lifetime=1,
                                                      max_obstacle_cells=self.max_obstacle_cells,
                                                      max_sensor_reach=self.max_sensor_reach))

    def obstacle_cell_cap(self, resolution):
        """Cells one obstacle may hold on a grid of this resolution (the handler's rule)."""
        if not (isinstance(resolution, (int, float)) and math.isfinite(resolution) and resolution > 0):
            return self.max_indexes  # an unusable resolution is refused by the field checks
        return self.policy.cell_cap(_Geometry(resolution))


def _is_uuid(value):
    return isinstance(value, str) and bool(_UUID_RE.match(value))


@dataclass(frozen=True)
class ObstacleUpdate:
    """One SharedObstacle as a validated value (field names as in the message;
    ``stamp`` in seconds; index sets sorted and without duplicates)."""
    uuid: str
    source: str
    version: int
    stamp: float
    frame_id: str
    deadline: int
    rectangle: Tuple[float, float, float, float]
    resolution: float
    origin_x: float
    origin_y: float
    size_x: int
    size_y: int
    marked: Tuple[int, ...] = ()
    cleared: Tuple[int, ...] = ()
    # (stamp, x, y, radius, reach): where the sender stood when it saw the cells (check_evidence); None: not said
    evidence: Optional[Tuple[float, float, float, float, float]] = None

    def __post_init__(self):
        if self.evidence is not None:
            object.__setattr__(self, "evidence", check_evidence(self.evidence))
        # The one validation shared with the handler (sharing_msgs.obstacle_rules): whatever
        # passes here also passes the handler's from_fleet check and serialises as a ROS message.
        try:
            obstacle_rules.check_fleet(
                self.uuid, self.source, self.version, self.stamp, self.frame_id, self.deadline,
                self.rectangle, self.resolution, self.origin_x, self.origin_y, self.size_x,
                self.size_y, self.marked, self.cleared)
        except obstacle_rules.ObstacleFieldError as err:
            raise _bridge_error(err) from None
        object.__setattr__(self, "uuid", self.uuid.lower())
        object.__setattr__(self, "rectangle", tuple(float(v) for v in self.rectangle))
        for name in ("marked", "cleared"):
            object.__setattr__(self, name, tuple(sorted(set(getattr(self, name)))))


#: Largest circumradius of a footprint in evidence, m: that of the footprint module's MAX_EXTENT square (a
#: receiver caps it further by its max_footprint_extent, as it does a footprint advert's)
MAX_EVIDENCE_RADIUS = 50.0 * math.sqrt(0.5)
#: Largest sensor reach evidence may state, m (the footprint module's MAX_REACH)
MAX_EVIDENCE_REACH = 1000.0


def check_evidence(value):
    """An obstacle's ``evidence`` [stamp, x, y, radius, reach] as a tuple of floats; raises WrongTypeError,
    NonFiniteNumberError or OutOfRangeError naming the bad value."""
    if not isinstance(value, (list, tuple)) or len(value) != 5:
        raise WrongTypeError("evidence %s is not [stamp, x, y, radius, reach]" % _short(value))
    for name, v in zip(("stamp", "x", "y", "radius", "reach"), value):
        _check_float("evidence " + name, v)
    stamp, x, y, radius, reach = (float(v) for v in value)
    for name, v, low, high in (("stamp", stamp, 0.0, float(MAX_UINT32)), ("x", x, -1.0e6, 1.0e6),
                               ("y", y, -1.0e6, 1.0e6), ("radius", radius, 0.0, MAX_EVIDENCE_RADIUS),
                               ("reach", reach, 0.0, MAX_EVIDENCE_REACH)):
        if not low <= v <= high:
            raise OutOfRangeError("evidence %s %r outside [%g, %g]" % (name, v, low, high))
    return (stamp, x, y, radius, reach)


def evidence_to_list(evidence):
    """The wire form of an update's evidence: millimetres, the stamp as it is."""
    stamp, x, y, radius, reach = evidence
    return [stamp, round(x, 3), round(y, 3), round(radius, 3), reach]


_ERROR_BY_KIND = {
    obstacle_rules.WRONG_TYPE: WrongTypeError,
    obstacle_rules.NON_FINITE: NonFiniteNumberError,
    obstacle_rules.OUT_OF_RANGE: OutOfRangeError,
    obstacle_rules.EMPTY: OutOfRangeError,
    obstacle_rules.OUTSIDE_GRID: OutOfRangeError,
    obstacle_rules.TOO_MANY: TooManyIndexesError,
}


def _bridge_error(err):
    """ObstacleFieldError -> the bridge's error class (its drop counter)."""
    if err.field == "source" and err.kind != obstacle_rules.WRONG_TYPE:
        return InvalidNameError("source: %s" % err)
    return _ERROR_BY_KIND.get(err.kind, InvalidPayloadError)(str(err))


def _check_float(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise WrongTypeError("%s %r is not a number" % (name, value))
    if not math.isfinite(value):
        raise NonFiniteNumberError("%s %r is not finite" % (name, value))


# ---------------------------------------------------------------- JSON parsing

def _reject_constant(name):
    raise NonFiniteNumberError("JSON constant %s is not allowed" % name)


def parse_payload(payload, limits):
    """bytes -> dict. Raises PayloadTooLargeError, InvalidJsonError, NonFiniteNumberError,
    WrongTypeError (top level not an object)."""
    if isinstance(payload, str):
        payload = payload.encode("utf-8", "surrogatepass")
    if len(payload) > limits.max_payload_bytes:
        raise PayloadTooLargeError("payload of %d bytes exceeds max_payload_bytes %d"
                                   % (len(payload), limits.max_payload_bytes))
    try:
        text = bytes(payload).decode("utf-8")
        data = json.loads(text, parse_constant=_reject_constant)
    except NonFiniteNumberError:
        raise
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise InvalidJsonError("payload is not UTF-8 JSON (%s): %r" % (str(err)[:80], bytes(payload[:60])))
    if not isinstance(data, dict):
        raise WrongTypeError("payload is a JSON %s, not an object" % type(data).__name__)
    return data


def dump(data):
    """dict -> compact UTF-8 JSON bytes, refusing NaN (Coaty JS would drop the event)."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False).encode("utf-8")


# ----------------------------------------------------------- field extraction

def _get(obj, key):
    if key not in obj:
        raise MissingFieldError("field %r missing" % key)
    return obj[key]


def _num(obj, key):
    value = _get(obj, key)
    _check_float(key, value)
    return float(value)


def _int(obj, key, low, high):
    value = _get(obj, key)
    # JS has one number type: accept 3.0 for 3, reject 3.5.
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        value = int(value)
    if isinstance(value, float) and not math.isfinite(value):
        raise NonFiniteNumberError("%s %r is not finite" % (key, value))
    if isinstance(value, bool) or not isinstance(value, int):
        raise WrongTypeError("%s %r is not an integer" % (key, _short(value)))
    if not low <= value <= high:
        raise OutOfRangeError("%s %r outside %d..%d" % (key, value, low, high))
    return value


def _str(obj, key):
    value = _get(obj, key)
    if not isinstance(value, str):
        raise WrongTypeError("%s %r is not a string" % (key, _short(value)))
    return value


def _num_list(obj, key, length):
    value = _get(obj, key)
    if not isinstance(value, list) or len(value) != length:
        raise WrongTypeError("%s %r is not a list of %d numbers" % (key, _short(value), length))
    for item in value:
        _check_float(key, item)
    return [float(v) for v in value]


def _indexes(obj, key, cells, max_count, cell_cap=None, rectangle_cap=None):
    value = _get(obj, key)
    limit = min(cells, max_count)
    for cap, error, why in ((rectangle_cap, RectangleCellsError, "more cells than its rectangle holds (%d)"),
                            (cell_cap, ObstacleCellsError, "more cells than max_obstacle_cells %d allows for one obstacle")):
        if cap is None or cap >= limit:
            continue
        # the tighter bound: decode_indexes stops at it (never expands more)
        try:
            if isinstance(value, str):
                return compact.decode_indexes(value, cells, cap)
            if isinstance(value, list) and len(value) > cap:
                raise TooManyIndexesError("%s has %d indexes" % (key, len(value)))
        except TooManyIndexesError as err:
            raise error(("%s: " + why + " (%s)") % (key, cap, err)) from None
        limit = cap
    if isinstance(value, str):
        return compact.decode_indexes(value, cells, limit)
    if not isinstance(value, list):
        raise WrongTypeError("%s %r is neither a list nor a compact string" % (key, _short(value)))
    if len(value) > limit:
        raise TooManyIndexesError("%s has %d indexes, more than %d" % (key, len(value), limit))
    for item in value:
        if isinstance(item, float) and item.is_integer():
            continue
        if isinstance(item, bool) or not isinstance(item, int):
            raise WrongTypeError("%s index %r is not an integer" % (key, _short(item)))
    return tuple(int(v) for v in value)


def _short(value):
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ----------------------------------------------------------------- obstacles

def obstacle_to_object(update, object_type=DEFAULT_OBJECT_TYPE, compact_indexes=True):
    """ObstacleUpdate -> CoatyObject dict."""
    def indexes(values):
        return compact.encode_indexes(values) if compact_indexes else list(values)
    obj = {
        "objectType": object_type,
        "coreType": "CoatyObject",
        "objectId": update.uuid,
        "name": update.uuid[:8],   # Coaty requires a name; objectType says what it is, objectId is the uuid
        "uuid": update.uuid,
        "source": update.source,
        "version": update.version,
        "stamp": update.stamp,
        "frameId": update.frame_id,
        "deadline": update.deadline,
        "rectangle": list(update.rectangle),
        "resolution": update.resolution,
        "origin": [update.origin_x, update.origin_y],
        "size": [update.size_x, update.size_y],
        "markedIndexes": indexes(update.marked),
        "clearedIndexes": indexes(update.cleared),
    }
    if update.evidence is not None:
        obj["evidence"] = evidence_to_list(update.evidence)
    return obj


def obstacle_from_object(obj, object_type=DEFAULT_OBJECT_TYPE, limits=CodecLimits()):
    """CoatyObject dict -> ObstacleUpdate; raises an InvalidPayloadError subclass
    (or InvalidNameError for a bad source) naming the bad field and value."""
    if not isinstance(obj, dict):
        raise WrongTypeError("object %s is not a JSON object" % _short(obj))
    if _str(obj, "objectType") != object_type:
        raise WrongTypeError("objectType %r is not %r" % (_short(obj["objectType"]), object_type))
    if _str(obj, "coreType") != "CoatyObject":
        raise WrongTypeError("coreType %r is not 'CoatyObject'" % _short(obj["coreType"]))
    object_id = _str(obj, "objectId")
    _str(obj, "name")
    uuid = _str(obj, "uuid")
    if not _is_uuid(object_id) or uuid.lower() != object_id.lower():
        raise OutOfRangeError("objectId %s must be the obstacle uuid %s" % (_short(object_id), _short(uuid)))
    size = _get(obj, "size")
    if not isinstance(size, list) or len(size) != 2:
        raise WrongTypeError("size %s is not [size_x, size_y]" % _short(size))
    size_x = _int({"size_x": size[0]}, "size_x", 1, MAX_UINT32)
    size_y = _int({"size_y": size[1]}, "size_y", 1, MAX_UINT32)
    cells = size_x * size_y
    origin = _num_list(obj, "origin", 2)
    rectangle = tuple(_num_list(obj, "rectangle", 4))
    resolution = _num(obj, "resolution")
    # Bounded authority before expansion (issue 27, attack 4): a few bytes of compact indexes can
    # declare 10^6 cells; the handler would drop the obstacle, so do not build it at all.
    try:
        limits.policy.check_extent(_Rectangle(*rectangle), "rectangle of obstacle %s" % uuid)
    except AuthorityError as err:
        raise ObstacleExtentError(str(err)) from None
    cell_cap = limits.obstacle_cell_cap(resolution)
    # A one-cell rectangle declaring 40,000 cells (issue 43, item 1): refused before the cells are built.
    rectangle_cap = None
    if all(isinstance(v, (int, float)) and math.isfinite(v) for v in rectangle + tuple(origin)) \
            and rectangle[0] <= rectangle[2] and rectangle[1] <= rectangle[3] \
            and isinstance(resolution, (int, float)) and math.isfinite(resolution) and resolution > 0:
        rectangle_cap = rectangle_capacity(_Rectangle(*rectangle), resolution, origin[0], origin[1])
    marked = _indexes(obj, "markedIndexes", cells, limits.max_indexes, cell_cap, rectangle_cap)
    cleared = _indexes(obj, "clearedIndexes", cells, limits.max_indexes, cell_cap, rectangle_cap)
    update = ObstacleUpdate(
        uuid=uuid,
        source=_str(obj, "source"),
        version=_int(obj, "version", 1, MAX_SAFE_INTEGER),
        stamp=_num(obj, "stamp"),
        frame_id=_str(obj, "frameId"),
        deadline=_int(obj, "deadline", 0, MAX_UINT32),
        rectangle=rectangle,
        resolution=resolution,
        origin_x=origin[0],
        origin_y=origin[1],
        size_x=size_x,
        size_y=size_y,
        marked=marked,
        cleared=cleared,
        evidence=check_evidence(obj["evidence"]) if obj.get("evidence") is not None else None,
    )
    check_inside(update)
    return update


def check_inside(update):
    """Raises RectangleCellsError / CellsOutsideRectangleError unless every cell of ``update`` lies inside its
    rectangle (sharing_msgs.authority.check_cells_inside, the handler's rule)."""
    try:
        check_cells_inside(_Rectangle(*update.rectangle), update.marked, update.cleared, update.resolution,
                           update.origin_x, update.origin_y, update.size_x, "obstacle %s v%d from %s"
                           % (update.uuid, update.version, update.source))
    except AuthorityError as err:
        raise (RectangleCellsError if err.reason == "more_cells_than_rectangle" else CellsOutsideRectangleError)(
            str(err)) from None


# -------------------------------------------------------------------- events

def identity_object(identity_id, name):
    """The Identity CoatyObject of one bridge (agent)."""
    return {"objectType": IDENTITY_OBJECT_TYPE, "coreType": IDENTITY_CORE_TYPE,
            "objectId": check_uuid(identity_id, "identity id"), "name": name}


def advertise_payload(obj):
    return dump({"object": obj})


def deadvertise_payload(object_ids):
    return dump({"objectIds": list(object_ids)})


#: objectIds one Deadvertise may name
MAX_DEADVERTISE_IDS = 1000


def decode_deadvertise(data):
    """Deadvertise payload dict -> the objectIds (lower-case UUIDs) it names; raises
    InvalidPayloadError when malformed."""
    if not isinstance(data, dict) or "objectIds" not in data:
        raise MissingFieldError("Deadvertise without objectIds")
    ids = data["objectIds"]
    if not isinstance(ids, list) or not 1 <= len(ids) <= MAX_DEADVERTISE_IDS:
        raise WrongTypeError("Deadvertise objectIds %s is not a list of 1..%d UUIDs" % (_short(ids), MAX_DEADVERTISE_IDS))
    for object_id in ids:
        if not _is_uuid(object_id):
            raise WrongTypeError("Deadvertise objectId %s is not a UUID" % _short(object_id))
    return tuple(i.lower() for i in ids)


def discover_object_types_payload(object_types):
    return dump({"objectTypes": list(object_types)})


def resolve_payload(obj, related=()):
    """A Resolve of ``obj``; ``related`` objects go in ``relatedObjects`` (Coaty's field for more objects)."""
    if related:
        return dump({"object": obj, "relatedObjects": list(related)})
    return dump({"object": obj})


#: objectTypes one Discover may name (a robot asks for the 3 x 3 obstacle areas it enters, at most 9)
_MAX_DISCOVER_AREAS = 64


@dataclass(frozen=True)
class DiscoverRequest:
    """What a Discover asks of us: our Identity, our obstacles (all, or those in some areas: the
    ``<object_type>.area_<ix>_<iy>`` objectTypes it names), or neither."""
    identity: bool
    obstacles: bool
    areas: frozenset = frozenset()


def decode_discover(data, identity_id, object_type):
    """Discover payload dict -> DiscoverRequest; raises InvalidPayloadError when malformed."""
    keys = [k for k in ("objectId", "externalId", "objectTypes", "coreTypes") if k in data]
    if not keys:
        raise MissingFieldError("Discover without objectId, externalId, objectTypes or coreTypes")
    identity = obstacles = False
    if "objectId" in data:
        if not _is_uuid(data["objectId"]):
            raise WrongTypeError("Discover objectId %s is not a UUID" % _short(data["objectId"]))
        identity = data["objectId"].lower() == identity_id
    if "externalId" in data and not isinstance(data["externalId"], str):
        raise WrongTypeError("Discover externalId %s is not a string" % _short(data["externalId"]))
    for key in ("objectTypes", "coreTypes"):
        if key in data:
            value = data[key]
            if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
                raise WrongTypeError("Discover %s %s is not a non-empty list of strings" % (key, _short(value)))
    if "objectTypes" in data and "coreTypes" in data:
        raise InvalidPayloadError("Discover with both objectTypes and coreTypes")
    object_types = data.get("objectTypes", [])
    core_types = data.get("coreTypes", [])
    if "objectId" not in data and "externalId" not in data:
        identity = IDENTITY_OBJECT_TYPE in object_types or IDENTITY_CORE_TYPE in core_types
        obstacles = object_type in object_types
        named = frozenset(a for a in (parse_area(t, object_type) for t in object_types) if a is not None)
        if len(named) > _MAX_DISCOVER_AREAS:
            raise OutOfRangeError("Discover names %d obstacle areas (at most %d)" % (len(named), _MAX_DISCOVER_AREAS))
        return DiscoverRequest(identity=identity, obstacles=obstacles, areas=frozenset() if obstacles else named)
    return DiscoverRequest(identity=identity, obstacles=obstacles)


@dataclass(frozen=True)
class ObstacleBatch:
    """The obstacles found in an event that carries several (a Resolve, a renewals event), and the errors of
    the objects that were bad."""
    obstacles: Tuple[ObstacleUpdate, ...]
    errors: Tuple[CoatyError, ...] = field(default=())


def collect_obstacle(obj, object_type, limits, found, errors):
    """Decodes one obstacle object of several into ``found``, or its error into ``errors``: a bad one
    loses none of the good ones."""
    try:
        found.append(obstacle_from_object(obj, object_type, limits))
    except (CoatyError, ValueError) as err:
        errors.append(err if isinstance(err, CoatyError) else InvalidPayloadError(str(err)))


def decode_resolve(data, object_type, limits=CodecLimits()):
    """Resolve payload dict -> ObstacleBatch. Objects of other types are ignored;
    each bad obstacle object is reported in ``errors`` without losing the good ones."""
    objects = []
    if "object" in data:
        objects.append(data["object"])
    if "relatedObjects" in data:
        related = data["relatedObjects"]
        if not isinstance(related, list):
            raise WrongTypeError("Resolve relatedObjects %s is not a list" % _short(related))
        objects.extend(related)
    if not objects:
        raise MissingFieldError("Resolve without object or relatedObjects")
    if "privateData" in data and not isinstance(data["privateData"], dict):
        raise WrongTypeError("privateData %s is not an object" % _short(data["privateData"]))
    found, errors = [], []
    for obj in objects:
        if not isinstance(obj, dict):
            errors.append(WrongTypeError("Resolve object %s is not a JSON object" % _short(obj)))
            continue
        if obj.get("objectType") != object_type:
            continue
        collect_obstacle(obj, object_type, limits, found, errors)
    return ObstacleBatch(tuple(found), tuple(errors))


def decode_advertise(data, object_type, limits=CodecLimits()):
    """Advertise payload dict (ADV::<object_type>) -> ObstacleUpdate."""
    if "privateData" in data and not isinstance(data["privateData"], dict):
        raise WrongTypeError("privateData %s is not an object" % _short(data["privateData"]))
    return obstacle_from_object(_get(data, "object"), object_type, limits)
