"""The ROS-free core of the VDA 5050 bridge.

Out: the robot's current VDA 5050 order (nodes with positions, edges between them) and the fleet's
shared obstacles (axis-aligned rectangles in the map frame) give the ``errors`` of the robot's
``state``: one WARNING per (blocked order element, obstacle).
In: blocked areas declared by master control (3.0: zones of type BLOCKED in the enabled zone set of
a map; 2.x: the instant actions ``fleetBlockArea`` / ``fleetUnblockArea``, our documented
extension) become obstacles with source ``master_control``; withdrawn areas go away.

Every outgoing message is validated against the official schema of its version; every incoming
one is checked (size, JSON, schema, vehicle, plausibility) and a bad one raises ``BadInput`` with a
reason (a counter name) and one line of text. Nothing here keeps state that a bad input can touch.
"""
import datetime
import json
import math
import uuid as uuidlib
from collections import Counter, namedtuple

from sharing_msgs.authority import MASTER_CONTROL, AuthorityError, PeerPolicy
from vda5050_bridge import schemas

MASTER_SOURCE = MASTER_CONTROL   # the source of master control's areas (sharing_msgs.authority)
ERROR_TYPE = "fleetObstacleOnPath"
BLOCK_ACTION = "fleetBlockArea"
UNBLOCK_ACTION = "fleetUnblockArea"
_NS = uuidlib.UUID("5d1f0c52-8a55-4c59-9f3f-0b3a0c5f5050")

Obstacle = namedtuple("Obstacle", "uuid source rect")          # rect = (min_x, min_y, max_x, max_y)
Node = namedtuple("Node", "node_id sequence_id released pos")  # pos = (x, y) or None
Edge = namedtuple("Edge", "edge_id sequence_id released start end")
Order = namedtuple("Order", "order_id order_update_id nodes edges")
Blocked = namedtuple("Blocked", "kind element_id sequence_id obstacle")  # kind: "edgeId" | "nodeId"
Area = namedtuple("Area", "uuid key polygon rect")             # a master-control blocked area
Rect = namedtuple("Rect", "min_x min_y max_x max_y")


class BadInput(ValueError):
    """An incoming message we drop; ``reason`` names its counter."""

    def __init__(self, reason, text):
        ValueError.__init__(self, text)
        self.reason = reason


def major(version):
    return version.split(".")[0]


def topic_prefix(interface_name, version, manufacturer, serial_number):
    """``<interfaceName>/<majorVersion>/<manufacturer>/<serialNumber>`` (VDA 5050 §6.5), e.g.
    ``uagv/v2/acme/robot_0``."""
    for part in (interface_name, manufacturer, serial_number):
        if not part or any(c in part for c in "/+#"):
            raise ValueError("invalid MQTT topic part %r" % part)
    return "%s/v%s/%s/%s" % (interface_name, major(version), manufacturer, serial_number)


def iso_timestamp(seconds):
    return datetime.datetime.fromtimestamp(seconds, datetime.timezone.utc).strftime(
        "%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


# ------------------------------------------------------------------ geometry

def segment_hits_rect(p, q, rect, margin=0.0):
    """Whether segment p-q comes within ``margin`` (Chebyshev, i.e. the rectangle grown by
    ``margin`` on every side: a superset of the robot's swept path of half-width ``margin``) of
    ``rect``. Liang-Barsky clipping."""
    x0, y0, x1, y1 = rect[0] - margin, rect[1] - margin, rect[2] + margin, rect[3] + margin
    dx, dy = q[0] - p[0], q[1] - p[1]
    t0, t1 = 0.0, 1.0
    for den, num in ((-dx, p[0] - x0), (dx, x1 - p[0]), (-dy, p[1] - y0), (dy, y1 - p[1])):
        if den == 0:
            if num < 0:
                return False
            continue
        t = num / den
        if den < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return False
    return True


def point_in_polygon(x, y, polygon):
    inside = False
    n = len(polygon)
    for i in range(n):
        (ax, ay), (bx, by) = polygon[i], polygon[(i + 1) % n]
        if (ay > y) != (by > y) and x < (bx - ax) * (y - ay) / (by - ay) + ax:
            inside = not inside
    return inside


def cells_in_polygon(polygon, resolution, origin_x, origin_y, size_x, size_y):
    """Indexes (y * size_x + x) of the grid cells whose centre lies inside ``polygon``."""
    min_x = min(p[0] for p in polygon)
    max_x = max(p[0] for p in polygon)
    min_y = min(p[1] for p in polygon)
    max_y = max(p[1] for p in polygon)
    cx0 = max(0, int(math.floor((min_x - origin_x) / resolution)))
    cx1 = min(size_x - 1, int(math.floor((max_x - origin_x) / resolution)))
    cy0 = max(0, int(math.floor((min_y - origin_y) / resolution)))
    cy1 = min(size_y - 1, int(math.floor((max_y - origin_y) / resolution)))
    out = []
    for cy in range(cy0, cy1 + 1):
        wy = origin_y + (cy + 0.5) * resolution
        for cx in range(cx0, cx1 + 1):
            if point_in_polygon(origin_x + (cx + 0.5) * resolution, wy, polygon):
                out.append(cy * size_x + cx)
    return out


# ------------------------------------------------------------------ out: order x obstacles -> errors

def parse_order(doc):
    """An ``Order`` from a schema-valid order document (positions where the nodes have them)."""
    nodes = []
    for n in doc.get("nodes", []):
        pos = n.get("nodePosition")
        xy = (float(pos["x"]), float(pos["y"])) if pos and "x" in pos and "y" in pos else None
        if xy is not None and not all(math.isfinite(v) for v in xy):
            raise BadInput("absurd_order", "order %s: node %s has a non-finite position"
                           % (doc.get("orderId"), n.get("nodeId")))
        if not isinstance(n["nodeId"], str):
            raise BadInput("absurd_order", "order %s: a nodeId is not a string" % doc.get("orderId"))
        nodes.append(Node(n["nodeId"], int(n["sequenceId"]), bool(n["released"]), xy))
    edges = [Edge(e["edgeId"], int(e["sequenceId"]), bool(e["released"]), e["startNodeId"], e["endNodeId"])
             for e in doc.get("edges", [])]
    ids = {n.node_id for n in nodes if isinstance(n.node_id, str)}
    for e in edges:
        if not all(isinstance(v, str) for v in (e.edge_id, e.start, e.end)) or e.start not in ids or e.end not in ids:
            raise BadInput("absurd_order", "order %s: edge %r does not join two of its nodes"
                           % (doc.get("orderId"), e.edge_id))
    return Order(doc["orderId"], int(doc["orderUpdateId"]), tuple(nodes), tuple(edges))


def blocked_elements(order, obstacles, half_width):
    """(kind, id, sequenceId, obstacle) for every order node and edge an obstacle touches."""
    if order is None:
        return []
    pos = {n.node_id: n.pos for n in order.nodes}
    out = []
    for obstacle in sorted(obstacles, key=lambda o: o.uuid):
        for node in order.nodes:
            if node.pos is not None and segment_hits_rect(node.pos, node.pos, obstacle.rect, half_width):
                out.append(Blocked("nodeId", node.node_id, node.sequence_id, obstacle))
        for edge in order.edges:
            p, q = pos.get(edge.start), pos.get(edge.end)
            if p is not None and q is not None and segment_hits_rect(p, q, obstacle.rect, half_width):
                out.append(Blocked("edgeId", edge.edge_id, edge.sequence_id, obstacle))
    return out


def rect_text(rect):
    return ",".join("%.3f" % v for v in rect)


def error_entries(order, blocked):
    """The VDA 5050 ``errors`` entries for ``blocked`` (valid in 2.0.0, 2.1.0 and 3.0.0).

    errorType ``fleetObstacleOnPath`` (3.0's errorType is an extensible enumeration, 2.x's a free
    string), errorLevel WARNING (the robot can still drive and take a new order; master control
    should reroute). errorReferences: the blocked ``edgeId`` or ``nodeId`` (the keys the standard
    names), the ``orderId``, and, under keys of our own (the standard's list is "e.g."),
    ``obstacleId`` = the shared obstacle's uuid, ``obstacleSource`` and ``obstacleRectangle`` =
    "min_x,min_y,max_x,max_y" in metres, map frame (the polygon: a shared obstacle is a rectangle;
    errorReference values are strings in every version).
    """
    out = []
    for b in blocked:
        o = b.obstacle
        out.append({
            "errorType": ERROR_TYPE,
            "errorLevel": "WARNING",
            "errorReferences": [
                {"referenceKey": b.kind, "referenceValue": b.element_id},
                {"referenceKey": "orderId", "referenceValue": order.order_id},
                {"referenceKey": "obstacleId", "referenceValue": o.uuid},
                {"referenceKey": "obstacleSource", "referenceValue": o.source},
                {"referenceKey": "obstacleRectangle", "referenceValue": rect_text(o.rect)},
            ],
            "errorDescription": "%s %s (sequenceId %d) of order %s is blocked by fleet obstacle %s from %s, "
                                "rectangle [%s] m in the map frame" % (
                                    "edge" if b.kind == "edgeId" else "node", b.element_id, b.sequence_id,
                                    order.order_id, o.uuid, o.source, rect_text(o.rect)),
        })
    return out


class StateBuilder:
    """Builds schema-valid ``state`` messages of one version for one vehicle."""

    def __init__(self, version, manufacturer, serial_number):
        if version not in schemas.VERSIONS:
            raise ValueError("unsupported VDA 5050 version %r (one of %s)" % (version, ", ".join(schemas.VERSIONS)))
        self.version = version
        self.manufacturer = manufacturer
        self.serial_number = serial_number
        self.header_id = 0

    def header(self, now):
        self.header_id += 1
        return {"headerId": self.header_id, "timestamp": iso_timestamp(now), "version": self.version,
                "manufacturer": self.manufacturer, "serialNumber": self.serial_number}

    def connection(self, state, now):
        """A ``connection`` message; ``state`` ONLINE, OFFLINE or BROKEN (CONNECTIONBROKEN in 2.x,
        CONNECTION_BROKEN in 3.0)."""
        if state == "BROKEN":
            state = "CONNECTION_BROKEN" if self.version == "3.0.0" else "CONNECTIONBROKEN"
        doc = self.header(now)
        doc["connectionState"] = state
        problems = schemas.errors(self.version, "connection", doc)
        if problems:
            raise AssertionError("built an invalid %s connection: %s" % (self.version, "; ".join(problems[:3])))
        return doc

    def state(self, order, errors, now):
        doc = self.header(now)
        first = order.nodes[0] if order and order.nodes else None
        doc.update({
            "orderId": order.order_id if order else "",
            "orderUpdateId": order.order_update_id if order else 0,
            "lastNodeId": first.node_id if first else "",
            "lastNodeSequenceId": first.sequence_id if first else 0,
            "nodeStates": [{"nodeId": n.node_id, "sequenceId": n.sequence_id, "released": n.released}
                           for n in (order.nodes[1:] if order else ())],
            "edgeStates": [{"edgeId": e.edge_id, "sequenceId": e.sequence_id, "released": e.released}
                           for e in (order.edges if order else ())],
            "driving": False,
            "actionStates": [],
            "operatingMode": "AUTOMATIC",
            "errors": errors,
        })
        if self.version == "3.0.0":
            doc["instantActionStates"] = []
            doc["powerSupply"] = {"stateOfCharge": 100.0, "charging": False}
            doc["safetyState"] = {"activeEmergencyStop": "NONE", "fieldViolation": False}
        else:
            doc["batteryState"] = {"batteryCharge": 100.0, "charging": False}
            doc["safetyState"] = {"eStop": "NONE", "fieldViolation": False}
        problems = schemas.errors(self.version, "state", doc)
        if problems:  # our own bug: never send it
            raise AssertionError("built an invalid %s state: %s" % (self.version, "; ".join(problems[:3])))
        return doc


# ------------------------------------------------------------------ in: decoding and blocked areas

class Limits:
    def __init__(self, max_payload_bytes=1048576, max_zones=1000, max_vertices=1000,
                 max_extent=100.0, max_coordinate=1.0e5):
        self.max_payload_bytes = max_payload_bytes
        self.max_zones = max_zones
        self.max_vertices = max_vertices
        self.max_extent = max_extent
        self.max_coordinate = max_coordinate
        # sharing_msgs.authority: the same extent rule the handler and the Coaty bridge apply
        self.policy = PeerPolicy(max_extent=max_extent, max_lifetime=1)


def decode(payload, version, topic, manufacturer, serial_number, limits):
    """A schema-valid document of ``topic`` addressed to this vehicle, or BadInput."""
    if len(payload) > limits.max_payload_bytes:
        raise BadInput("oversized", "%s: %d bytes > %d" % (topic, len(payload), limits.max_payload_bytes))
    try:
        doc = json.loads(payload.decode("utf-8") if isinstance(payload, (bytes, bytearray)) else payload,
                         parse_constant=_refuse_constant)
    except (ValueError, UnicodeDecodeError, RecursionError) as err:
        raise BadInput("invalid_json", "%s: not JSON: %s" % (topic, str(err)[:120]))
    if not isinstance(doc, dict):
        raise BadInput("schema_violation", "%s: not a JSON object" % topic)
    if version == "2.0.0" and topic == "instantActions" and "actions" not in doc and "instantActions" in doc:
        # vda-5050-lib (npm, 1.4.0) sends 2.0.0 instant actions under the 1.1 name "instantActions";
        # the 2.0.0 text says "actions". Taken as the same field; nothing else is renamed.
        doc["actions"] = doc.pop("instantActions")
    try:
        problems = schemas.errors(version, topic, doc)
    except RecursionError:
        raise BadInput("schema_violation", "%s: nested too deeply" % topic)
    if problems:
        raise BadInput("schema_violation", "%s: %s" % (topic, "; ".join(problems[:3])))
    if major(str(doc["version"])) != major(version):
        raise BadInput("wrong_version", "%s: version %r, we speak %s" % (topic, doc["version"], version))
    if doc["manufacturer"] != manufacturer or doc["serialNumber"] != serial_number:
        raise BadInput("wrong_vehicle", "%s: for %s/%s, we are %s/%s" % (
            topic, doc["manufacturer"], doc["serialNumber"], manufacturer, serial_number))
    return doc


def _refuse_constant(name):
    raise ValueError("%s is not a JSON number" % name)


def _polygon(vertices, what, limits):
    if not isinstance(vertices, list) or len(vertices) < 3:
        raise BadInput("absurd_zone", "%s: needs at least 3 vertices" % what)
    if len(vertices) > limits.max_vertices:
        raise BadInput("absurd_zone", "%s: %d vertices > %d" % (what, len(vertices), limits.max_vertices))
    poly = []
    for v in vertices:
        if not isinstance(v, dict):
            raise BadInput("absurd_zone", "%s: a vertex is not an {x, y} object" % what)
        x, y = v.get("x"), v.get("y")
        if isinstance(x, bool) or isinstance(y, bool) or not isinstance(x, (int, float)) \
                or not isinstance(y, (int, float)):
            raise BadInput("absurd_zone", "%s: vertex %r has no numeric x and y" % (what, v))
        if not (math.isfinite(x) and math.isfinite(y)) or max(abs(x), abs(y)) > limits.max_coordinate:
            raise BadInput("absurd_zone", "%s: vertex (%r, %r) out of range" % (what, x, y))
        poly.append((float(x), float(y)))
    rect = Rect(min(p[0] for p in poly), min(p[1] for p in poly), max(p[0] for p in poly), max(p[1] for p in poly))
    try:
        # the fleet's rule of authority for an obstacle's extent, with master control's own cap
        limits.policy.check_extent(rect, what)
    except AuthorityError as err:
        raise BadInput("absurd_zone", err.detail) from None
    area = 0.5 * abs(sum(poly[i][0] * poly[(i + 1) % len(poly)][1] - poly[(i + 1) % len(poly)][0] * poly[i][1]
                         for i in range(len(poly))))
    if area <= 1e-9:
        raise BadInput("absurd_zone", "%s: zero area" % what)
    return tuple(poly), rect


def area_uuid(key):
    """The obstacle uuid of a master-control area: the same on every robot for a zone set sent to
    all (key = zoneSetId/zoneId), so each robot's handler holds one obstacle, not one per robot."""
    return str(uuidlib.uuid5(_NS, "vda5050:%s" % key))


class BlockedAreas:
    """Blocked areas master control declared. ``apply_*`` validate the whole message first and
    change nothing when it is bad (BadInput); ``areas()`` is the current set, keyed by uuid."""

    def __init__(self, limits=None):
        self.limits = limits or Limits()
        self.zone_sets = {}   # zoneSetId -> (mapId, [Area])     (3.0, received)
        self.enabled = {}     # mapId -> zoneSetId               (3.0, enableZoneSet)
        self.extension = {}   # areaId -> Area                   (2.x and 3.0: fleetBlockArea)

    def areas(self):
        out = {a.uuid: a for a in self.extension.values()}
        for set_id in self.enabled.values():
            for a in self.zone_sets.get(set_id, ("", []))[1]:
                out[a.uuid] = a
        return out

    def apply_zone_set(self, doc):
        zs = doc["zoneSet"]
        set_id, map_id = zs["zoneSetId"], zs["mapId"]
        if len(zs["zones"]) > self.limits.max_zones:
            raise BadInput("absurd_zone", "zoneSet %s: %d zones > %d" % (set_id, len(zs["zones"]),
                                                                         self.limits.max_zones))
        if set_id in self.zone_sets:
            raise BadInput("duplicate_zone_set", "zoneSet %s already received (a zone set never changes)" % set_id)
        areas = []
        for z in zs["zones"]:
            if z["zoneType"] != "BLOCKED":
                continue
            key = "%s/%s" % (set_id, z["zoneId"])
            poly, rect = _polygon(z["vertices"], "zoneSet %s zone %s" % (set_id, z["zoneId"]), self.limits)
            areas.append(Area(area_uuid(key), key, poly, rect))
        self.zone_sets[set_id] = (map_id, areas)

    def apply_instant_actions(self, doc):
        """enableZoneSet / deleteZoneSet (3.0) and fleetBlockArea / fleetUnblockArea (all
        versions). Returns the actionIds it handled; other actions are ignored."""
        staged_ext = dict(self.extension)
        staged_enabled = dict(self.enabled)
        staged_sets = dict(self.zone_sets)
        handled = []
        for action in doc["actions"]:
            kind = action["actionType"]
            params = {p.get("key"): p.get("value") for p in action.get("actionParameters", [])
                      if isinstance(p, dict)}
            what = "instantAction %s (%s)" % (action["actionId"], kind)
            if kind == BLOCK_ACTION:
                area_id = params.get("areaId")
                if not isinstance(area_id, str) or not area_id:
                    raise BadInput("absurd_zone", "%s: needs a string areaId" % what)
                poly, rect = _polygon(params.get("vertices"), what, self.limits)
                if area_id not in staged_ext and len(staged_ext) >= self.limits.max_zones:
                    raise BadInput("absurd_zone", "%s: more than %d areas" % (what, self.limits.max_zones))
                key = "area/" + area_id
                staged_ext[area_id] = Area(area_uuid(key), key, poly, rect)
            elif kind == UNBLOCK_ACTION:
                staged_ext.pop(params.get("areaId"), None)
            elif kind == "enableZoneSet":
                set_id = params.get("zoneSetId")
                if set_id not in staged_sets:
                    raise BadInput("unknown_zone_set", "%s: zone set %r not received" % (what, set_id))
                staged_enabled[staged_sets[set_id][0]] = set_id
            elif kind == "deleteZoneSet":
                set_id = params.get("zoneSetId")
                if set_id in staged_sets:
                    map_id = staged_sets.pop(set_id)[0]
                    if staged_enabled.get(map_id) == set_id:
                        del staged_enabled[map_id]
            else:
                continue
            handled.append(action["actionId"])
        self.extension, self.enabled, self.zone_sets = staged_ext, staged_enabled, staged_sets
        return handled


class BridgeCore:
    """Everything the node does, without ROS and MQTT: incoming payloads by topic suffix,
    the fleet's obstacles, the state to send. ``counters`` holds ``received.<topic>`` and
    ``dropped.<reason>``."""

    def __init__(self, version, manufacturer, serial_number, half_width=0.3, limits=None):
        self.version = version
        self.manufacturer = manufacturer
        self.serial_number = serial_number
        self.half_width = half_width
        self.limits = limits or Limits()
        self.builder = StateBuilder(version, manufacturer, serial_number)
        self.areas = BlockedAreas(self.limits)
        self.order = None
        self.obstacles = {}
        self.counters = Counter()

    def topics_in(self):
        return ["order", "instantActions"] + (["zoneSet"] if self.version == "3.0.0" else [])

    def on_message(self, topic, payload):
        """Handles one payload of ``topic`` (order, instantActions, zoneSet). Returns None when it
        was taken, or the one log line describing why it was dropped."""
        try:
            if topic not in self.topics_in():
                raise BadInput("unknown_topic", "unexpected topic %r" % str(topic)[:80])
            doc = decode(payload, self.version, topic, self.manufacturer, self.serial_number, self.limits)
            if topic == "order":
                self.order = parse_order(doc)
            elif topic == "instantActions":
                self.areas.apply_instant_actions(doc)
            else:
                self.areas.apply_zone_set(doc)
        except BadInput as err:
            self.counters["dropped." + err.reason] += 1
            return "dropped %s message (%s): %s" % (topic, err.reason, err)
        except Exception as err:  # noqa: BLE001 - a bug in one message must not stop the bridge
            self.counters["dropped.internal_error"] += 1
            return "dropped %s message (internal_error): %r" % (topic, err)
        self.counters["received." + topic] += 1
        return None

    def set_obstacles(self, obstacles):
        """The fleet's current obstacles (the handler's list); master control's own are left out
        (it knows them; reporting them back would echo)."""
        self.obstacles = {o.uuid: o for o in obstacles if o.source != MASTER_SOURCE}

    def state(self, now):
        blocked = blocked_elements(self.order, self.obstacles.values(), self.half_width)
        doc = self.builder.state(self.order, error_entries(self.order, blocked) if blocked else [], now)
        self.counters["sent.state"] += 1
        return doc
