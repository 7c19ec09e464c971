"""A bridge agent's configuration: the node's private parameters as one validated value, and where the
broker URL comes from. Imports neither paho nor rospy."""
import urllib.parse
from dataclasses import dataclass, field

from coaty_bridge import codec, footprint as footprints
from coaty_bridge import liveness as liveness_rules
from coaty_bridge.errors import CoatyError
from coaty_bridge.identity import identity_for
from coaty_bridge.security import is_loopback
from coaty_bridge.topics import check_name, check_uuid, new_uuid
from sharing_msgs.authority import EvidenceRule

_SCHEMES = {"mqtt": (False, 1883), "tcp": (False, 1883), "mqtts": (True, 8883),
            "ssl": (True, 8883), "tls": (True, 8883)}


@dataclass(frozen=True)
class BrokerAddress:
    host: str
    port: int
    tls: bool


def parse_broker_url(url):
    """'mqtt://host:port' (or mqtts://, tcp://, ssl://) -> BrokerAddress; ValueError otherwise."""
    if not isinstance(url, str):
        raise ValueError("broker_url %r is not a string" % (url,))
    try:
        parts = urllib.parse.urlsplit(url)
        port = parts.port
    except ValueError as err:
        raise ValueError("broker_url %r: %s" % (url, err))
    if parts.scheme not in _SCHEMES or not parts.hostname or parts.path not in ("", "/"):
        raise ValueError("broker_url %r is not mqtt://host[:port] or mqtts://host[:port]" % (url,))
    tls, default_port = _SCHEMES[parts.scheme]
    return BrokerAddress(parts.hostname, port or default_port, tls)


@dataclass(frozen=True)
class BridgeConfig:
    """Everything one bridge agent needs; field names are the node's private
    parameter names, and a bad value raises ValueError naming parameter and value."""
    robot_name: str
    broker_url: str = "mqtt://127.0.0.1:1883"
    namespace: str = "fleet"
    object_type: str = codec.DEFAULT_OBJECT_TYPE
    footprint_object_type: str = footprints.DEFAULT_FOOTPRINT_OBJECT_TYPE
    identity_id: str = ""
    tls_ca: str = ""
    tls_cert: str = ""
    tls_key: str = ""
    username: str = ""
    password: str = ""
    # where the password came from: read again before each connection attempt, so a secret rotated while the
    # fleet runs (fleet_credentials rotate) is used on the next reconnect (issue 43, item 9)
    password_file: str = ""
    max_payload_bytes: int = 1024 * 1024
    max_indexes: int = 1_000_000
    # the handler's caps on one obstacle (same meaning, same defaults): checked before expanding
    max_obstacle_extent: float = 10.0
    max_obstacle_cells: int = 0
    # Plausible evidence (issue 43; sharing_msgs README, "Plausible evidence"). sensor_reach: m, this robot's
    # sensor reach, advertised with its footprint (max of the layer's obstacle_range, raytrace_range and
    # trigger_radius). max_sensor_reach: m, the most any robot may claim; a robot's obstacle is at most
    # 2 x (it + 0.5 m) across, like the handler's (0: max_obstacle_extent alone). require_evidence: a peer's
    # obstacle message keeps only the cells within its reach of a pose it advertised near the stamp (the
    # fleet launch sets it with authenticate_sources). The slack: evidence_window s, max_robot_speed m/s,
    # localisation_tolerance m.
    sensor_reach: float = 4.0
    max_sensor_reach: float = 0.0
    require_evidence: bool = False
    evidence_window: float = 2.0
    max_robot_speed: float = 1.0
    localisation_tolerance: float = 0.25
    offline_queue_size: int = 1000
    compact_indexes: bool = True
    keepalive: int = 60
    reconnect_min_delay: float = 0.5
    reconnect_max_delay: float = 30.0
    discover_window: float = 30.0
    # Discover answers per requester (sourceId): a token bucket, this many per s with this burst;
    # one 52-byte Discover costs every bridge one Resolve per obstacle held (issue 27, attack 4)
    discover_answer_rate: float = 1.0
    discover_answer_burst: int = 3
    # who answers an obstacle Discover with another robot's obstacle: "creator" (the robot that
    # created it, while it is a live peer; every robot once it is gone) or "everyone" holding it. Each
    # robot always replays its own updates. "everyone" costs a joining robot one Resolve per obstacle
    # per robot in the fleet.
    discover_answers: str = "creator"
    # Per sender (MQTT sourceId; issue 27, item 3): obstacle Advertises beyond a token bucket of this
    # many per s with this burst are dropped before their payload is parsed, and what is left waits
    # in a queue per sender (at most source_queue_size), served round-robin, so one sender's flood
    # does not delay another's obstacles (fairness.py)
    source_message_rate: float = 100.0
    source_message_burst: int = 1000
    source_queue_size: int = 1000
    # s: end-to-end liveness (liveness.py): a tick this often, with an echo (only we receive it) unless
    # all we sent is back; ERROR when nothing sent at or after a tick is back within liveness_timeout
    # s (issue 27, attack 6); a heartbeat every peer receives each
    # peer_heartbeat_interval s (0: automatic, 3 s per peer known, at least heartbeat_interval;
    # issue 29), WARN when a peer's is missing for 3 of its intervals (at least liveness_timeout)
    heartbeat_interval: float = 1.0
    liveness_timeout: float = 3.0
    peer_heartbeat_interval: float = 0.0
    authenticate_sources: bool = False
    # true: plain mqtt:// to a broker that is not on this machine is allowed (logins and obstacles
    # then cross the network in clear text); false refuses it at start-up (issue 27, item 9)
    insecure: bool = False
    # metres; fleet-wide. Adverts go out per square of the map and each bridge hears the 3 x 3
    # squares around its robot (see footprint.py); 0 = one advert channel for the whole fleet. 5 m: a robot
    # hears every robot within 5 m, beyond what costmap_2d marks (obstacle_range 2.5 m) plus a robot's size and
    # a far advert's 1 m of drift; 10 m squares (the default before) made each robot hear 4 x the area for nothing.
    footprint_area_size: float = 5.0
    # metres; fleet-wide. An obstacle's monitoring updates (not its first share, not an update that only
    # clears) go out under the square of its rectangle's centre, and each bridge hears the 3 x 3 squares
    # around its robot; far robots get the first share, every clearing update and a renewal before their
    # copy's lease runs out (issue 29; README "Obstacle areas"). 0 = every update to every robot. 5 m, as
    # footprint_area_size: a robot hears the monitoring updates within 5 m, twice obstacle_range.
    obstacle_area_size: float = 5.0
    # metres; a footprint advert wider or longer than this is not a robot and is dropped
    max_footprint_extent: float = footprints.DEFAULT_MAX_FOOTPRINT_EXTENT
    # robot names whose footprint adverts are taken; empty = any robot (see README "Fleet robot
    # footprints": with authenticate_sources, any robot with broker credentials)
    known_robots: tuple = ()
    # operator names (fleet_console logins that may act): with authenticate_sources, an obstacle Advertise sent by
    # such an operator's own identity (only its login may publish under it, the broker's ACL) is taken without
    # plausible evidence: an operator has no sensors, its authority is its login
    operators: tuple = ()
    # s: while the broker cannot be reached, a WARN at the first failed attempt and then this often
    broker_warn_interval: float = 30.0
    # where broker_url came from (which parameter), for log lines; set by the node
    broker_url_source: str = "the default"
    address: BrokerAddress = field(init=False, repr=False)

    def __post_init__(self):
        def fail(name, why):
            raise ValueError("parameter %s = %r: %s" % (name, getattr(self, name), why))
        for name in ("robot_name", "namespace", "object_type", "footprint_object_type"):
            try:
                check_name(getattr(self, name), name)
            except CoatyError as err:
                fail(name, err)
        if self.object_type.startswith("coaty."):
            fail("object_type", "the coaty.* object types are reserved")
        if self.footprint_object_type.startswith("coaty."):
            fail("footprint_object_type", "the coaty.* object types are reserved")
        if self.footprint_object_type == self.object_type:
            fail("footprint_object_type", "must differ from object_type")
        if not isinstance(self.authenticate_sources, bool):
            fail("authenticate_sources", "must be true or false")
        if self.identity_id:
            try:
                object.__setattr__(self, "identity_id", check_uuid(self.identity_id, "identity_id"))
            except CoatyError as err:
                fail("identity_id", err)
            if self.authenticate_sources and self.identity_id != identity_for(self.namespace, self.robot_name):
                fail("identity_id", "with authenticate_sources the identity must be the one derived "
                                    "from the name, %s" % identity_for(self.namespace, self.robot_name))
        elif self.authenticate_sources:
            # the broker's ACL and every receiver bind this id to the robot's name
            object.__setattr__(self, "identity_id", identity_for(self.namespace, self.robot_name))
        else:
            object.__setattr__(self, "identity_id", new_uuid())
        if self.authenticate_sources and not self.username:
            # the ACL's %u is the sourceId: log in as the identity (a TLS broker with
            # use_identity_as_username takes it from the certificate's CN instead)
            object.__setattr__(self, "username", self.identity_id)
        try:
            object.__setattr__(self, "address", parse_broker_url(self.broker_url))
        except ValueError as err:
            fail("broker_url", err)
        if not isinstance(self.insecure, bool):
            fail("insecure", "must be true or false")
        if not self.use_tls and not is_loopback(self.address.host) and not self.insecure:
            fail("broker_url", "plain MQTT to %s, which is not this machine: the login and every obstacle would "
                               "cross the network in clear text; use mqtts:// (tls_ca, and tls_cert/tls_key or a "
                               "password), or set insecure: true to accept the risk" % self.address.host)
        for name in ("tls_ca", "tls_cert", "tls_key", "username", "password", "password_file"):
            if not isinstance(getattr(self, name), str):
                fail(name, "not a string")
        if bool(self.tls_cert) != bool(self.tls_key):
            fail("tls_cert", "tls_cert and tls_key go together")
        if self.password and not self.username:
            fail("password", "a password needs a username")
        for name, low in (("max_payload_bytes", 64), ("max_indexes", 1), ("offline_queue_size", 0),
                          ("keepalive", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                fail(name, "must be an integer >= %d" % low)
        if not isinstance(self.compact_indexes, bool):
            fail("compact_indexes", "must be true or false")
        try:
            object.__setattr__(self, "_limits", codec.CodecLimits(
                self.max_payload_bytes, self.max_indexes, self.max_obstacle_extent, self.max_obstacle_cells,
                self.max_sensor_reach))
        except ValueError as err:
            fail("max_obstacle_cells" if "cells" in str(err) else
                 "max_sensor_reach" if "reach" in str(err) else "max_obstacle_extent", err)
        if not isinstance(self.require_evidence, bool):
            fail("require_evidence", "must be true or false")
        for name, high in (("sensor_reach", 1000.0), ("evidence_window", 3600.0), ("max_robot_speed", 100.0),
                           ("localisation_tolerance", 100.0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= high:
                fail(name, "must be a number 0..%g" % high)
        try:
            object.__setattr__(self, "_evidence_rule", EvidenceRule(
                max_sensor_reach=self.max_sensor_reach or self.sensor_reach, window=self.evidence_window,
                max_speed=self.max_robot_speed, localisation_tolerance=self.localisation_tolerance))
        except ValueError as err:
            fail("max_sensor_reach", err)
        if isinstance(self.discover_answer_burst, bool) or not isinstance(self.discover_answer_burst, int) \
                or not 1 <= self.discover_answer_burst <= 1000:
            fail("discover_answer_burst", "must be an integer 1..1000")
        if self.discover_answers not in ("creator", "everyone"):
            fail("discover_answers", "must be \"creator\" or \"everyone\", not %r" % (self.discover_answers,))
        rate = self.source_message_rate
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate < 1e9:
            fail("source_message_rate", "must be a positive number of messages per second")
        for name in ("source_message_burst", "source_queue_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 10 ** 7:
                fail(name, "must be an integer 1..10000000")
        for name in ("reconnect_min_delay", "reconnect_max_delay", "discover_window", "broker_warn_interval",
                     "discover_answer_rate", "heartbeat_interval", "liveness_timeout"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1e6:
                fail(name, "must be a positive number of seconds")
        if self.liveness_timeout < 2 * self.heartbeat_interval:
            fail("liveness_timeout", "must be at least twice heartbeat_interval (%g s)" % self.heartbeat_interval)
        peer = self.peer_heartbeat_interval
        if isinstance(peer, bool) or not isinstance(peer, (int, float)) or not (
                peer == 0 or self.heartbeat_interval <= peer <= liveness_rules.MAX_ANNOUNCED_INTERVAL):
            fail("peer_heartbeat_interval", "must be 0 (automatic: %g s per peer) or %g..%g s (heartbeat_interval.."
                 "3600)" % (liveness_rules.AUTO_SECONDS_PER_PEER, self.heartbeat_interval,
                            liveness_rules.MAX_ANNOUNCED_INTERVAL))
        if self.reconnect_max_delay < self.reconnect_min_delay:
            fail("reconnect_max_delay", "smaller than reconnect_min_delay")
        for name in ("footprint_area_size", "obstacle_area_size"):
            area = getattr(self, name)
            if isinstance(area, bool) or not isinstance(area, (int, float)) or not (
                    area == 0 or footprints.MIN_AREA_SIZE <= area <= footprints.MAX_AREA_SIZE):
                fail(name, "must be 0 (one area) or %g..%g m; all robots of a fleet need the same"
                     % (footprints.MIN_AREA_SIZE, footprints.MAX_AREA_SIZE))
        extent = self.max_footprint_extent
        if isinstance(extent, bool) or not isinstance(extent, (int, float)) or not (
                0.1 <= extent <= footprints.MAX_EXTENT):
            fail("max_footprint_extent", "must be 0.1..%g m" % footprints.MAX_EXTENT)
        if isinstance(self.known_robots, str) or not isinstance(self.known_robots, (list, tuple)):
            fail("known_robots", "must be a list of robot names")
        for name in self.known_robots:
            try:
                check_name(name, "known robot")
            except CoatyError as err:
                fail("known_robots", err)
        object.__setattr__(self, "known_robots", tuple(self.known_robots))
        if isinstance(self.operators, str):
            object.__setattr__(self, "operators", tuple(self.operators.replace(",", " ").split()))
        if not isinstance(self.operators, (list, tuple)):
            fail("operators", "must be a list of operator names")
        for name in self.operators:
            try:
                check_name(name, "operator")
            except CoatyError as err:
                fail("operators", err)
        object.__setattr__(self, "operators", tuple(self.operators))

    @property
    def use_tls(self):
        return self.address.tls or bool(self.tls_ca)

    @property
    def limits(self):
        return self._limits

    @property
    def evidence_rule(self):
        """The slack of plausible evidence (sharing_msgs.authority.EvidenceRule); the reach cap is max_sensor_reach,
        or this robot's own sensor_reach when that is 0."""
        return self._evidence_rule


class BrokerUrlChoice:
    """Which broker URL the bridge uses and where it came from (a parameter's full name, or the
    default); ``warning`` says when a private ~broker_url overrides the parameter the launch named."""

    def __init__(self, url, source, warning=None):
        self.url, self.source, self.warning = url, source, warning


def choose_broker_url(params, wait, default=None):
    """The bridge node's broker URL (``params``: has(name), get(name[, default]), resolve(name), as
    rospy's parameter functions): the private ~broker_url if set; else the parameter that ~broker_url_param
    names (``wait(name)`` waits for it, as run_broker sets it); else ``default``.

    A private ~broker_url stays on the master after the launch that set it ends, and wins over the
    ~broker_url_param of every later launch of the node under the same name: that is said in the
    returned warning, with both names and values."""
    private = params.resolve("~broker_url")
    url_param = params.get("~broker_url_param", "") if params.has("~broker_url_param") else ""
    if not isinstance(url_param, str):
        raise ValueError("parameter broker_url_param = %r: must be a parameter name" % (url_param,))
    named = params.resolve(url_param) if url_param else ""
    if params.has("~broker_url"):
        url = params.get("~broker_url")
        source = "private parameter %s" % private
        if not url_param:
            return BrokerUrlChoice(url, source)
        if params.has(url_param):
            other = params.get(url_param)
            if other == url:
                return BrokerUrlChoice(url, source + " (the same as %s)" % named)
            state = "which is %r" % (other,)
        else:
            state = "not set yet"
        return BrokerUrlChoice(url, source, (
            "private parameter %s = %r overrides ~broker_url_param %s (%s); if it is a leftover of an "
            "earlier run on this master, remove it: rosparam delete %s" % (private, url, named, state, private)))
    if url_param:
        return BrokerUrlChoice(wait(url_param), "parameter %s (named by ~broker_url_param)" % named)
    return BrokerUrlChoice(BridgeConfig.broker_url if default is None else default,
                           "the default (neither ~broker_url nor ~broker_url_param is set)")
