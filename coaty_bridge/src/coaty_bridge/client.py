"""The MQTT side of a bridge: one Coaty agent on Debian's python3-paho-mqtt
(1.x callback API; on paho 2.x the VERSION1 API is requested explicitly).

The agent advertises its Identity on every (re)connect, leaves a last-will
Deadvertise, answers Identity Discovers, publishes obstacle updates as
Advertise events of one custom objectType, answers obstacle Discovers from the
robot's current list with one Resolve per obstacle, and on every connect asks
its peers for their obstacles (late joiner). Bad input is dropped, logged once
and counted; the MQTT thread never sees an exception.
"""
import collections
import dataclasses
import logging
import math
import select
import socket
import secrets
import ssl
import threading
import time
import urllib.parse
from dataclasses import dataclass, field

import paho.mqtt.client as mqtt

from coaty_bridge import areas, codec, footprint as footprints, lifetimes, renewals
from coaty_bridge.errors import (CoatyError, FootprintTooLargeError, ForgedSourceError, OutOfRangeError,
                                 UnknownRobotError, WrongTypeError)
from coaty_bridge import liveness as liveness_rules
from coaty_bridge.liveness import (CHANNEL as HEARTBEAT_CHANNEL, ECHO_CHANNEL, OBJECT_TYPE as HEARTBEAT_OBJECT_TYPE,
                                   Liveness)
from coaty_bridge.fairness import FairQueue
from coaty_bridge.identity import identity_for
from coaty_bridge.security import is_loopback
from coaty_bridge.topics import Topic, check_name, check_uuid, new_uuid, parse_topic, subscription
from sharing_handler_py.quotas import DropReport, TokenBuckets

LOG = logging.getLogger(__name__)

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
    max_payload_bytes: int = 1024 * 1024
    max_indexes: int = 1_000_000
    # the handler's caps on one obstacle (same meaning, same defaults): checked before expanding
    max_obstacle_extent: float = 10.0
    max_obstacle_cells: int = 0
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
    # s: end-to-end liveness (liveness.py): an echo (only we receive it) this often, ERROR when it is
    # not echoed for liveness_timeout s (issue 27, attack 6); a heartbeat every peer receives each
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
    # squares around its robot (see footprint.py); 0 = one advert channel for the whole fleet.
    footprint_area_size: float = 10.0
    # metres; fleet-wide. An obstacle's monitoring updates (not its first share, not an update that only
    # clears) go out under the square of its rectangle's centre, and each bridge hears the 3 x 3 squares
    # around its robot; far robots get the first share, every clearing update and a renewal before their
    # copy's lease runs out (issue 29; README "Obstacle areas"). 0 = every update to every robot.
    obstacle_area_size: float = 10.0
    # metres; a footprint advert wider or longer than this is not a robot and is dropped
    max_footprint_extent: float = footprints.DEFAULT_MAX_FOOTPRINT_EXTENT
    # robot names whose footprint adverts are taken; empty = any robot (see README "Fleet robot
    # footprints": with authenticate_sources, any robot with broker credentials)
    known_robots: tuple = ()
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
        for name in ("tls_ca", "tls_cert", "tls_key", "username", "password"):
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
                self.max_payload_bytes, self.max_indexes, self.max_obstacle_extent, self.max_obstacle_cells))
        except ValueError as err:
            fail("max_obstacle_cells" if "cells" in str(err) else "max_obstacle_extent", err)
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

    @property
    def use_tls(self):
        return self.address.tls or bool(self.tls_ca)

    @property
    def limits(self):
        return self._limits


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


def mqtt_client_id(identity_id, nonce=None):
    """The MQTT client id: "Coaty", 8 hex digits of the Identity id (to tell agents apart in the
    broker's log) and a random per-start nonce of 10 hex digits (40 bits), 23 characters, the
    longest every MQTT 3.1.1 broker must accept. The Identity id is public (and, with
    authenticate_sources, computable from the robot's name), so an id made of it alone let any
    peer connect under it and make the broker drop the robot (issue 27, attack 5: 19 s cut off).
    The bridge connects with a clean session (nothing persists under the id), so a fresh id per
    start costs nothing; it stays the same across reconnects of one start. With per-robot logins
    the broker also binds the id to the login (``use_username_as_clientid true``, README)."""
    if nonce is None:
        nonce = secrets.token_hex(5)
    return "Coaty" + identity_id.replace("-", "")[:8] + nonce


def _make_paho_client(client_id):
    if hasattr(mqtt, "CallbackAPIVersion"):  # paho-mqtt >= 2.0
        return mqtt.Client(mqtt.CallbackAPIVersion.VERSION1, client_id=client_id, clean_session=True)
    return mqtt.Client(client_id=client_id, clean_session=True)


#: Requesters whose Discover token buckets are remembered (the quietest are forgotten beyond).
_MAX_DISCOVER_REQUESTERS = 4096
#: Agents (sourceIds) whose robot names are remembered; one withdrawn by a Deadvertise is forgotten.
_MAX_KNOWN_AGENTS = 4096
# obstacles whose fleet-wide expiry is kept before expired entries are swept (a flood cannot grow it for long)
_MAX_FLEET_EXPIRIES = 400000


def _renewal_margin(deadline):
    """s before the far copies of an obstacle with ``deadline`` s left expire that its renewal is due."""
    return max(2.0, 0.1 * deadline)


#: Obstacles per Resolve answering a Discover at most, as renewals.MAX_ENTRIES, so that no single message
#: holds a receiver for long; and bytes per Resolve at most (or max_payload_bytes if lower), so that a
#: receiver with a lower max_payload_bytes than ours still takes the batches (an obstacle larger than
#: this goes alone, as every answer went before).
RESOLVE_BATCH = 64
RESOLVE_BATCH_BYTES = 16384
#: Own updates kept per obstacle for Discover answers (the oldest go first beyond this).
OWN_LOG_PER_OBSTACLE = 200
#: s after start() without a connection (and no failed attempt yet) before the first WARN.
FIRST_UNREACHABLE_WARN_AFTER = 5.0


class CoatyBridgeClient:
    """One Coaty agent per robot. ``on_obstacle(update, topic)`` is called from the
    MQTT thread for every valid external obstacle event; ``clock`` is injectable."""

    def __init__(self, config, on_obstacle, clock=time.monotonic, qos=0, on_footprint=None, heartbeats=True,
                 on_footprint_withdrawn=None):
        self.config = config
        self.identity_id = config.identity_id
        self._on_obstacle = on_obstacle
        # on_footprint(RobotFootprint, topic): a peer robot's footprint advert (fleet robots are never shared)
        self._on_footprint = on_footprint
        # on_footprint_withdrawn(robot, topic): a peer took its footprint back (a Deadvertise of its advert
        # series or of its agent: stopped, or its navigation went quiet), so it is forgotten at once
        self._on_footprint_withdrawn = on_footprint_withdrawn
        self._footprint_senders = {}   # sourceId -> (robot, advert objectId) of footprints heard
        self.footprint_object_id = new_uuid()
        self._clock = clock
        self._qos = qos
        self._lock = threading.Lock()
        self._counters = collections.Counter()
        self._queue = collections.deque()
        self._current = ()
        self._current_as_of = 0.0   # clock time at which the deadlines in _current were valid
        # uuid -> [(update, sent_at)]: this robot's own updates of live obstacles, replayed to a
        # Discover so a robot back from a partition or restart gets every cell's exact stamp
        # (a full-state entry alone cannot carry a clear; see README "Partitions and restarts")
        self._own_log = collections.OrderedDict()
        self._pending_discovers = {}
        # a token bucket per Discover requester (sourceId): a flood from one empties only its own
        self._discover_buckets = TokenBuckets(config.discover_answer_rate, config.discover_answer_burst,
                                              max_keys=_MAX_DISCOVER_REQUESTERS)
        # what paho reads goes into a queue per sourceId, served round-robin by one worker (fairness.py);
        # obstacle Advertises beyond a sender's token bucket are dropped before they queue
        self._inbox = FairQueue(config.source_queue_size)
        self._source_buckets = TokenBuckets(config.source_message_rate, config.source_message_burst)
        self._source_drops = DropReport(config.robot_name, log=LOG)
        self._source_drops_lock = threading.Lock()
        self._inbox_thread = None
        self._admit_cache = {}   # topic text -> (sender key, rate-limited kind), see admit
        # sourceId -> robot name, from heartbeats and Identity adverts: for log lines a person can act on, and to
        # tell which robot asks in a Discover
        self._robot_of = {}
        self._connected = False
        # the broker acknowledged the subscriptions made on connecting (their SUBACK's message id): before that,
        # what peers publish may not reach this client yet
        self._subscribed = False
        self._connect_subscribe_mid = None
        self._ever_connected = False
        self._stopping = False
        self._killed = False
        # unreachable broker: when the current outage began (None: connected or not started), failed
        # connection attempts in it, when it was last reported (None: not yet)
        self._down_since = None
        self._failed_attempts = 0
        self._last_unreachable_warn = None
        self._watch_stop = threading.Event()
        self._watch_thread = None
        # heartbeats=False: the owner calls heartbeat() itself (tests, with an injected clock)
        self._auto_heartbeats = heartbeats
        self.liveness = Liveness(config.robot_name, clock, config.liveness_timeout, config.known_robots,
                                 config.heartbeat_interval, config.peer_heartbeat_interval)
        ns = config.namespace
        self._heartbeat_topic = str(Topic(ns, "CHN", self.identity_id, filter=HEARTBEAT_CHANNEL))
        # the echo goes to a topic only we subscribe to (exactly, no wildcard), in a namespace of its own
        # so that no subscription of the fleet's namespace (coaty/+/<ns>/+/+ included) catches it
        self._echo_namespace = liveness_rules.echo_namespace(ns)
        self._echo_topic = str(Topic(self._echo_namespace, "CHN", self.identity_id, filter=ECHO_CHANNEL))
        self._identity = codec.identity_object(self.identity_id, config.robot_name)
        self._obstacle_topic = str(Topic(ns, "ADV", self.identity_id, object_type=config.object_type))
        self._footprint_topic = str(Topic(ns, "ADV", self.identity_id, object_type=config.footprint_object_type))
        self._dad_topic = str(Topic(ns, "DAD", self.identity_id))
        self._renewals_topic = str(Topic(ns, "CHN", self.identity_id, filter=renewals.CHANNEL))
        self._subscriptions = [
            (subscription(ns, "ADV::" + config.object_type), qos),
            (subscription(ns, "ADV::" + config.footprint_object_type), qos),
            (subscription(ns, "DSC", two_way=True), qos),
            (subscription(ns, "RSV", two_way=True), qos),
            (subscription(ns, "CHN:" + HEARTBEAT_CHANNEL), qos),
            (subscription(ns, "CHN:" + renewals.CHANNEL), qos),
            (subscription(ns, "DAD"), qos),
            # agents' Identity adverts (one per connection): which robot a Discover comes from
            (subscription(ns, "ADV:" + codec.IDENTITY_CORE_TYPE), qos),
            (self._echo_topic, qos),
        ]
        # Footprint and obstacle areas heard now (the 3 x 3 around the own robot, each at its own size);
        # none until the robot's position is known.
        self._own_area = None
        # Until then it hears every one-level event of the namespace (every area's updates too), so that
        # a robot without a known position (no footprint yet, a host without one) misses no update.
        self._area_subscriptions = {subscription(ns, "+")} if config.obstacle_area_size > 0 else set()
        self._obstacle_areas = set()
        # Obstacle areas (issue 29): uuid -> clock time at which the copies of robots that hear only
        # fleet-wide messages expire (the newest fleet-wide message's deadline), and this robot's pending
        # renewals, uuid -> (due, update, sent_at): its last area-scoped update, sent fleet-wide before
        # those copies would expire while the robots near the obstacle hold it longer.
        self._fleet_expiry = {}
        self._renewals = {}
        self.client_id = mqtt_client_id(self.identity_id)
        self._mqtt = _make_paho_client(self.client_id)
        self._mqtt.will_set(self._dad_topic, codec.deadvertise_payload([self.identity_id]), qos=0)
        if config.use_tls:
            self._mqtt.tls_set(ca_certs=config.tls_ca or None, certfile=config.tls_cert or None,
                               keyfile=config.tls_key or None, cert_reqs=ssl.CERT_REQUIRED)
        if config.username:
            self._mqtt.username_pw_set(config.username, config.password or None)
        self._mqtt.reconnect_delay_set(min_delay=config.reconnect_min_delay,
                                       max_delay=config.reconnect_max_delay)
        self._mqtt.on_connect = self._on_connect
        self._mqtt.on_disconnect = self._on_disconnect
        self._mqtt.on_connect_fail = self._on_connect_fail
        self._mqtt.on_message = self._on_mqtt_message
        self._mqtt.on_subscribe = self._on_subscribe

    # ------------------------------------------------------------ lifecycle

    def start(self):
        """Connects in the background; reconnects with backoff until stop()."""
        address = self.config.address
        with self._lock:
            self._down_since = self._clock()
        self._mqtt.connect_async(address.host, address.port, keepalive=self.config.keepalive)
        self._inbox_thread = threading.Thread(target=self._serve_inbox, name="coaty_bridge inbox", daemon=True)
        self._inbox_thread.start()
        self._mqtt.loop_start()
        # check_broker on a wall-clock second: the MQTT thread sleeps in its backoff, and ROS time may stand
        self._watch_thread = threading.Thread(target=self._watch_broker, name="coaty_bridge broker watch",
                                              daemon=True)
        self._watch_thread.start()
        if self._auto_heartbeats:
            threading.Thread(target=self._heartbeats, name="coaty_bridge heartbeat", daemon=True).start()

    def _heartbeats(self):
        while not self._watch_stop.wait(self.config.heartbeat_interval):
            try:
                self.heartbeat()
            except Exception as err:  # noqa: BLE001 - keep beating
                LOG.error("%s: heartbeat failed: %s: %s", self.config.robot_name, type(err).__name__, err)

    def heartbeat(self, leaving=False):
        """Publishes one heartbeat, see liveness.py: the echo (a Channel event on a topic only we
        subscribe to) or, when due, the peer heartbeat every bridge observes (it is echoed too).
        ``leaving``: a last peer heartbeat of a clean stop, so that peers do not miss this robot."""
        if not self._connected:
            return None
        seq, peer = self.liveness.next_heartbeat(peer=True if leaving else None)
        if peer is None:
            self._send(self._echo_topic, liveness_rules.echo_payload(self.identity_id, seq), queue=False)
            self._count("echoes_sent")
            return None
        payload = liveness_rules.heartbeat_payload(self.identity_id, self.config.robot_name, seq, peer, leaving)
        if leaving:
            return self._mqtt.publish(self._heartbeat_topic, payload, qos=1)
        self._send(self._heartbeat_topic, payload, queue=False)
        self._count("peer_heartbeats_sent")
        return None

    def _on_echo(self, topic, payload):
        if topic.source_id != self.identity_id:
            self._count("ignored")   # somebody else's echo: we subscribe to our own only
            return
        data = codec.parse_payload(payload, self.config.limits)
        obj = data.get("object") if isinstance(data, dict) else None
        if not isinstance(obj, dict) or obj.get("objectType") != liveness_rules.ECHO_OBJECT_TYPE:
            raise WrongTypeError("echo without a %s object" % liveness_rules.ECHO_OBJECT_TYPE)
        seq = obj.get("seq")
        if isinstance(seq, bool) or not isinstance(seq, int):
            raise WrongTypeError("echo seq %r: wrong type" % (seq,))
        self.liveness.own_echo(seq)

    def _on_heartbeat(self, topic, payload):
        data = codec.parse_payload(payload, self.config.limits)
        obj = data.get("object") if isinstance(data, dict) else None
        if not isinstance(obj, dict) or obj.get("objectType") != HEARTBEAT_OBJECT_TYPE:
            raise WrongTypeError("heartbeat without a %s object" % HEARTBEAT_OBJECT_TYPE)
        robot, seq = obj.get("robot"), obj.get("seq")
        if not isinstance(robot, str) or isinstance(seq, bool) or not isinstance(seq, int):
            raise WrongTypeError("heartbeat fields robot %r, seq %r: wrong types" % (str(robot)[:40], seq))
        legacy = "interval" not in obj and "hears" in obj   # a sender of the first design (issue 27)
        if legacy:
            names, interval, heard = obj.get("hears"), liveness_rules.LEGACY_INTERVAL, None
        else:
            names, interval, heard = obj.get("misses", []), obj.get("interval"), obj.get("heard")
            if isinstance(interval, bool) or not isinstance(interval, (int, float)) \
                    or isinstance(heard, bool) or not isinstance(heard, int):
                raise WrongTypeError("heartbeat of %r: interval %r, heard %r: wrong types"
                                     % (str(robot)[:40], str(interval)[:20], str(heard)[:20]))
            if not liveness_rules.MIN_ANNOUNCED_INTERVAL <= interval <= liveness_rules.MAX_ANNOUNCED_INTERVAL \
                    or not 0 <= heard <= 10 ** 6:
                raise OutOfRangeError("heartbeat of %r: interval %r s not in %g..%g or heard %r not in 0..1000000"
                                      % (str(robot)[:40], interval, liveness_rules.MIN_ANNOUNCED_INTERVAL,
                                         liveness_rules.MAX_ANNOUNCED_INTERVAL, heard))
        if not isinstance(names, list) or not all(isinstance(h, str) for h in names):
            raise WrongTypeError("heartbeat of %r: %s must be a list of robot names"
                                 % (str(robot)[:40], "hears" if legacy else "misses"))
        if len(names) > liveness_rules.MAX_LIST:
            raise OutOfRangeError("heartbeat of %r: %s lists %d robots, more than %d"
                                  % (str(robot)[:40], "hears" if legacy else "misses", len(names),
                                     liveness_rules.MAX_LIST))
        check_name(robot, "heartbeat robot")
        self._note_robot_of(topic.source_id, robot)
        if topic.source_id == self.identity_id:
            self.liveness.own_echo(seq)   # our own peer heartbeat is an echo too
            return
        if self.config.authenticate_sources and topic.source_id != identity_for(self.config.namespace, robot):
            raise ForgedSourceError("heartbeat of %r was sent by %s" % (robot, topic.source_id))
        if self.config.known_robots and robot not in self.config.known_robots:
            raise UnknownRobotError("heartbeat of robot %r (sourceId %s): not in known_robots"
                                    % (robot, topic.source_id))
        if obj.get("leaving") is True:
            # a clean stop says so in a last heartbeat: not missed. (The Deadvertise does not tell:
            # the broker sends the same one as the last will of a robot it lost.)
            self.liveness.forget(robot)
            return
        if legacy:
            self.liveness.peer(robot, interval, hears=names)
            self._count("heartbeats_received_legacy")
        else:
            self.liveness.peer(robot, interval, misses=names, heard=heard)
        self._count("heartbeats_received")

    def _watch_broker(self):
        while not self._watch_stop.wait(1.0):
            try:
                with self._source_drops_lock:
                    self._source_drops.flush(self._clock())
                self.check_broker()
                if self._connected:
                    self.renew_due()
            except Exception as err:  # noqa: BLE001 - a log problem must not end the watch
                LOG.error("%s: broker watch: %s: %s", self.config.robot_name, type(err).__name__, err)

    def check_broker(self):
        """WARNs while the broker cannot be reached: at the first failed attempt (or
        FIRST_UNREACHABLE_WARN_AFTER s after start without a connection) and then every
        ``broker_warn_interval`` s of the client's clock. Returns True when it warned."""
        now = self._clock()
        with self._lock:
            if self._connected or self._down_since is None or self._stopping:
                return False
            down_for = now - self._down_since
            if self._last_unreachable_warn is None:
                due = self._failed_attempts > 0 or down_for >= min(FIRST_UNREACHABLE_WARN_AFTER,
                                                                    self.config.broker_warn_interval)
            else:
                due = now - self._last_unreachable_warn >= self.config.broker_warn_interval
            if not due:
                return False
            self._last_unreachable_warn = now
            self._counters["broker_unreachable_warnings"] += 1
            attempts, queued = self._failed_attempts, len(self._queue)
        LOG.warning("%s: broker %s unreachable for %.0f s (%d connection attempts failed; broker_url from %s); "
                    "not in the fleet: nothing is shared or received, %d obstacle updates queued; retrying "
                    "every %g s at most", self.config.robot_name, self.config.broker_url, down_for, attempts,
                    self.config.broker_url_source, queued, self.config.reconnect_max_delay)
        return True

    def stop(self, timeout=2.0):
        """Deadvertises the Identity explicitly (a clean disconnect discards the will),
        then disconnects and stops the MQTT thread."""
        if self._killed:
            return
        self._stopping = True
        self._watch_stop.set()
        if self._connected:
            try:
                self.heartbeat(leaving=True)   # peers' liveness: gone on purpose, not partitioned
                info = self._mqtt.publish(self._dad_topic, codec.deadvertise_payload([self.identity_id]), qos=1)
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError) as err:
                LOG.warning("%s: could not deadvertise before disconnecting: %s", self.config.robot_name, err)
        self._mqtt.disconnect()
        self._mqtt.loop_stop()
        self._inbox.close()

    def kill(self):
        """Drops the connection without a Deadvertise, as a crash would (tests only):
        the broker then publishes the last will."""
        self._stopping = self._killed = True
        self._watch_stop.set()
        sock = self._mqtt.socket()
        self._mqtt.loop_stop()
        self._inbox.close()
        if sock is not None:
            sock.close()

    def clock(self):
        """The client's clock (monotonic seconds unless injected)."""
        return self._clock()

    @property
    def connected(self):
        return self._connected

    @property
    def subscribed(self):
        """Connected, and the broker has acknowledged the subscriptions made on connecting: from here on what peers
        publish to them reaches this client (before it, the broker may not have them yet)."""
        return self._connected and self._subscribed

    def counters(self):
        """A snapshot of all counters (dropped.<reason>, published, received, ...)."""
        with self._lock:
            snapshot = dict(self._counters)
            snapshot["queue_length"] = len(self._queue)
            snapshot["inbox_length"] = len(self._inbox)
        with self._source_drops_lock:
            # dropped_source_rate_limited.<robot@sourceId> / dropped_source_queue_full.<...>
            snapshot.update(self._source_drops.counters())
        return snapshot

    def _count(self, key, n=1):
        with self._lock:
            self._counters[key] += n

    # ------------------------------------------------------------- outgoing

    def publish_obstacle(self, update):
        """Publishes one internal ObstacleUpdate to the fleet (Advertise), fleet-wide or to the area
        around the obstacle (``_area_for``). Returns False if it was dropped (too large); queues it
        while offline."""
        area = self._area_for(update)
        object_type = self.config.object_type if area is None else areas.area_object_type(self.config.object_type,
                                                                                            area)
        payload = self._obstacle_payload(update, object_type)
        if len(payload) > self.config.max_payload_bytes:
            self._count("dropped_outgoing.oversized")
            LOG.warning("%s: obstacle %s v%d not published: %d bytes exceed max_payload_bytes %d",
                        self.config.robot_name, update.uuid, update.version, len(payload),
                        self.config.max_payload_bytes)
            return False
        self._count("published")
        self._count("bytes_published", len(payload))
        self._log_own(update)
        if area is None:
            self._count("published_fleet_wide")
            self._sent_fleet_wide(update)
            self._send(self._obstacle_topic, payload, update=update)
        else:
            self._count("published_to_area")
            self._schedule_renewal(update)
            self._send(str(Topic(self.config.namespace, "ADV", self.identity_id, object_type=object_type)),
                       payload, update=update)
        return True

    def _obstacle_area(self, update):
        """The obstacle area (at obstacle_area_size > 0) holding the centre of the update's rectangle."""
        return areas.area_of(areas.rectangle_centre(update.rectangle), self.config.obstacle_area_size)

    def _area_for(self, update):
        """The area an update goes to, or None for fleet-wide: a first share (every robot must plan around
        it), an update that marks nothing (it may end the obstacle: far robots must stop avoiding it), and
        any update while far robots hold no live copy this bridge knows of, go to every robot."""
        if self.config.obstacle_area_size <= 0 or update.version <= 1 or not update.marked:
            return None
        with self._lock:
            far = self._fleet_expiry.get(update.uuid)
        if far is None or far <= self._clock():
            return None
        return self._obstacle_area(update)

    def _schedule_renewal(self, update):
        """An area-scoped update: when the robots near the obstacle will hold it longer than the far ones,
        renew the far copies, fleet-wide, shortly before they expire (``renew_due``)."""
        now = self._clock()
        with self._lock:
            far = self._fleet_expiry.get(update.uuid, -math.inf)
            if now + update.deadline > far:
                self._renewals[update.uuid] = (max(now, far - _renewal_margin(update.deadline)), update, now)

    def _sent_fleet_wide(self, update, now=None):
        """Every robot got ``update`` (sent or heard on the fleet-wide objectType): their copies live
        until its deadline; a renewal it covers is dropped."""
        now = self._clock() if now is None else now
        expiry = now + update.deadline
        with self._lock:
            if expiry > self._fleet_expiry.get(update.uuid, -math.inf):
                self._fleet_expiry[update.uuid] = expiry
            renewal = self._renewals.get(update.uuid)
            if renewal is not None and renewal[2] + renewal[1].deadline <= expiry + 1.0:
                del self._renewals[update.uuid]
            if len(self._fleet_expiry) > _MAX_FLEET_EXPIRIES:
                for uuid in [u for u, t in self._fleet_expiry.items() if t <= now]:
                    del self._fleet_expiry[uuid]

    def renew_due(self):
        """Sends, fleet-wide, the renewals that are due (the broker watch calls it every second), and
        with them those due within their margin, in as few renewals events as their source, frame and
        grid allow (``renewals``); returns how many obstacles were renewed. A renewal is this robot's
        last area-scoped update of the obstacle, aged. Offline, they wait (and are aged when sent)."""
        now = self._clock()
        with self._lock:
            if not self._connected:
                return 0
            due = {u: r for u, r in self._renewals.items() if r[0] <= now}
            if due:
                # renewing a little early costs nothing, a second event costs its bytes again
                due.update({u: r for u, r in self._renewals.items()
                            if r[0] - _renewal_margin(r[1].deadline) <= now})
            for uuid in due:
                del self._renewals[uuid]
        fresh_updates = []
        for uuid, (_due, update, sent_at) in due.items():
            fresh = lifetimes.aged(update, now - sent_at)
            with self._lock:
                covered = self._fleet_expiry.get(uuid, -math.inf) >= sent_at + update.deadline - 1.0
            if fresh is not None and not covered:
                fresh_updates.append(fresh)
        sent = 0
        for chunk, obj in renewals.renewals_objects(fresh_updates, new_uuid):
            payload = renewals.renewals_payload(obj)
            with self._lock:
                published = self._connected and self._mqtt.publish(
                    self._renewals_topic, payload, qos=self._qos).rc == mqtt.MQTT_ERR_SUCCESS
                if not published:
                    # not lost: due again at the next watch tick, aged from now
                    for update in chunk:
                        self._renewals.setdefault(update.uuid, (now, update, now))
            if not published:
                continue
            for update in chunk:
                self._sent_fleet_wide(update, now)
            self._count("renewals_sent", len(chunk))
            self._count("renewal_events_sent")
            self._count("bytes_published", len(payload))
            sent += len(chunk)
        return sent

    def publish_footprint(self, footprint):
        """Advertises this robot's footprint (a RobotFootprint), under the objectType of the area
        it stands in. Not queued while offline: an old pose is worth nothing. Returns False when
        it was not sent."""
        where = footprints.centroid(footprint.points)
        self.note_own_position(where)
        object_type, topic = self.config.footprint_object_type, self._footprint_topic
        if self.config.footprint_area_size > 0:
            object_type = areas.area_object_type(object_type, areas.area_of(where, self.config.footprint_area_size))
            topic = str(Topic(self.config.namespace, "ADV", self.identity_id, object_type=object_type))
        payload = footprints.footprint_payload(footprint, self.footprint_object_id, object_type)
        if len(payload) > self.config.max_payload_bytes:
            self._count("dropped_outgoing.oversized")
            return False
        if not self._connected:
            self._count("footprints_not_sent_offline")
            return False
        self._count("footprints_published")
        self._count("footprint_bytes_published", len(payload))
        self._send(topic, payload, queue=False)
        return True

    def note_own_position(self, point):
        """This robot stands at ``point`` (x, y in the map frame): hear the footprint adverts and the
        obstacle updates of the 3 x 3 areas around it (each at its own size). Called with every own
        footprint, advertised or not. Obstacle areas new to it are asked for the updates made there
        while it was away (a Discover of those areas' objectTypes; each robot replays its own)."""
        fp_size, ob_size = self.config.footprint_area_size, self.config.obstacle_area_size
        key = (areas.area_of(point, fp_size) if fp_size > 0 else None,
               areas.area_of(point, ob_size) if ob_size > 0 else None)
        if key == (None, None) or key == self._own_area:
            return
        ns = self.config.namespace
        wanted = set()
        if fp_size > 0:
            wanted |= {subscription(ns, "ADV::" + areas.area_object_type(self.config.footprint_object_type, a))
                       for a in areas.areas_around(point, fp_size)}
        obstacle_areas = areas.areas_around(point, ob_size) if ob_size > 0 else set()
        wanted |= {subscription(ns, "ADV::" + areas.area_object_type(self.config.object_type, a))
                   for a in obstacle_areas}
        with self._lock:
            first = self._own_area is None
            if key[0] != (self._own_area or (None, None))[0]:
                self._counters["footprint_area_changes"] += 1
            self._own_area = key
            old, self._area_subscriptions = self._area_subscriptions, wanted
            new_obstacle_areas = sorted(obstacle_areas - self._obstacle_areas)
            self._obstacle_areas = obstacle_areas
            connected = self._connected
            if connected:
                # new ones first: a robot on the way in is heard from the first advert the broker has for it
                added, gone = sorted(wanted - old), sorted(old - wanted)
                if added:
                    self._mqtt.subscribe([(t, self._qos) for t in added])
                if gone:
                    self._mqtt.unsubscribe(gone)
        if connected and new_obstacle_areas and not first:
            # the first position follows the connect's own Discover, which already asked for everything
            self._discover_obstacles([areas.area_object_type(self.config.object_type, a) for a in new_obstacle_areas])
            self._count("obstacle_area_discovers")

    def _log_own(self, update):
        with self._lock:
            entries = self._own_log.setdefault(update.uuid, [])
            entries.append((update, self._clock()))
            if len(entries) > OWN_LOG_PER_OBSTACLE:
                del entries[0]
                self._counters["own_log_truncated"] += 1

    def _replayable_own_updates(self):
        """This robot's own updates still alive, aged to now; expired ones are forgotten."""
        now = self._clock()
        replay = []
        with self._lock:
            for uuid in list(self._own_log):
                alive = [(u, t) for u, t in self._own_log[uuid] if lifetimes.aged(u, now - t) is not None]
                if alive:
                    self._own_log[uuid] = alive
                    replay += [lifetimes.aged(u, now - t) for u, t in alive]
                else:
                    del self._own_log[uuid]
        return replay

    def _obstacle_payload(self, update, object_type=None):
        return codec.advertise_payload(
            codec.obstacle_to_object(update, object_type or self.config.object_type, self.config.compact_indexes))

    def set_current_obstacles(self, updates, as_of=None):
        """The robot's current full obstacles, used to answer obstacle Discovers; their
        deadlines were valid at clock time `as_of` (default: now) and are aged from there."""
        current = tuple(updates)
        as_of = self._clock() if as_of is None else as_of
        with self._lock:
            self._current = current
            self._current_as_of = as_of

    def _send(self, topic, payload, queue=True, update=None, queued_at=None):
        """Publishes now, or (``queue``) keeps it while offline. An obstacle ``update`` is kept
        with the time it was queued, so its deadline is aged when it finally goes out."""
        with self._lock:
            if self._connected:
                info = self._mqtt.publish(topic, payload, qos=self._qos)
                if info.rc == mqtt.MQTT_ERR_SUCCESS:
                    return
            if not queue:
                return
            if self.config.offline_queue_size == 0 or len(self._queue) >= self.config.offline_queue_size:
                self._counters["queue_drops"] += 1
                if self._queue:
                    self._queue.popleft()  # the newest update is worth more than the oldest
                else:
                    return
            self._queue.append((topic, payload, update, self._clock() if queued_at is None else queued_at))

    def _flush_queue(self):
        with self._lock:
            pending, self._queue = list(self._queue), collections.deque()
        now = self._clock()
        for topic, payload, update, queued_at in pending:
            if update is not None:
                fresh = lifetimes.aged(update, now - queued_at)
                if fresh is None:
                    # it expired on every robot while we were offline: sending it would revive it
                    self._count("queue_expired")
                    continue
                if fresh is not update:
                    # under the objectType it was queued with (an area's, or the plain one)
                    payload = self._obstacle_payload(fresh, parse_topic(topic).object_type)
                # its deadline is now valid as of now (should the send fail and re-queue it)
                self._send(topic, payload, update=fresh, queued_at=now)
            else:
                self._send(topic, payload)

    def _discover_obstacles(self, object_types=None):
        correlation_id = new_uuid()
        now = self._clock()
        with self._lock:
            window = self.config.discover_window
            self._pending_discovers = {c: t for c, t in self._pending_discovers.items() if now - t < window}
            self._pending_discovers[correlation_id] = now
        topic = Topic(self.config.namespace, "DSC", self.identity_id, correlation_id=correlation_id)
        self._send(str(topic), codec.discover_object_types_payload(object_types or [self.config.object_type]),
                   queue=False)
        self._count("discovers_sent")

    # ------------------------------------------------------- paho callbacks

    def _on_connect_fail(self, client, userdata):
        """paho: a connection attempt failed (nothing listens, no route, TLS handshake, ...)."""
        with self._lock:
            self._counters["connect_failures"] += 1
            self._failed_attempts += 1
        self.check_broker()

    def _on_connect(self, client, userdata, flags, rc, properties=None):
        if rc != 0:
            with self._lock:
                self._counters["connect_failures"] += 1
                self._failed_attempts += 1
                first = self._last_unreachable_warn is None
                if first:
                    self._last_unreachable_warn = self._clock()  # this line is the outage's first warning
            LOG.warning("%s: broker %s refused the connection: %s (broker_url from %s)", self.config.robot_name,
                        self.config.broker_url, mqtt.connack_string(rc), self.config.broker_url_source)
            return
        sock = client.socket()
        if sock is not None and hasattr(sock, "setsockopt"):
            try:  # small events: without this, Nagle + delayed ACK add tens of ms per event
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
        with self._lock:
            topics = self._subscriptions + [(t, self._qos) for t in sorted(self._area_subscriptions)]
            _, self._connect_subscribe_mid = client.subscribe(topics)
            self._subscribed = False
            self._connected = True
            if self._ever_connected:
                self._counters["reconnects"] += 1
            self._ever_connected = True
            down_since, warned = self._down_since, self._last_unreachable_warn is not None
            self._down_since = self._last_unreachable_warn = None
            self._failed_attempts = 0
        if warned:
            LOG.info("%s: connected to %s as Coaty agent %s, after %.0f s unreachable", self.config.robot_name,
                     self.config.broker_url, self.identity_id, self._clock() - down_since)
        else:
            LOG.info("%s: connected to %s as Coaty agent %s", self.config.robot_name,
                     self.config.broker_url, self.identity_id)
        payload = codec.advertise_payload(self._identity)
        ns = self.config.namespace
        self._send(str(Topic(ns, "ADV", self.identity_id, core_type="Identity")), payload, queue=False)
        self._send(str(Topic(ns, "ADV", self.identity_id, object_type=codec.IDENTITY_OBJECT_TYPE)),
                   payload, queue=False)
        self.liveness.reset()
        self._flush_queue()
        self._discover_obstacles()

    def _on_subscribe(self, client, userdata, mid, granted_qos, properties=None):
        """paho: a SUBACK. The one for the subscriptions made on connecting makes the client subscribed."""
        with self._lock:
            if mid == self._connect_subscribe_mid:
                self._subscribed = True

    def _on_disconnect(self, client, userdata, rc, properties=None):
        with self._lock:
            self._connected = False
            self._subscribed = False
            if not self._stopping and self._down_since is None:
                # this line is the outage's first warning; check_broker repeats it while it lasts
                self._down_since = self._last_unreachable_warn = self._clock()
                self._failed_attempts = 0
        if not self._stopping:
            self._count("disconnects")
            LOG.warning("%s: lost the broker %s (rc %s); reconnecting with backoff",
                        self.config.robot_name, self.config.broker_url, rc)

    def _on_mqtt_message(self, client, userdata, message):
        """paho's on_message (its network thread): only sorts the raw message into its sender's queue
        (fair delivery); obstacle Advertises beyond the sender's token bucket are dropped here, before
        their payload is parsed. The worker (_serve_inbox) does the rest. Never raises."""
        try:
            topic_text, payload = message.topic, message.payload
            key = self.admit(topic_text)
            if key is not None and not self._inbox.put(key, (topic_text, payload)):
                self._source_drop(key, "source_queue_full", topic_text,
                                  "its queue holds source_queue_size %d messages not yet handed over"
                                  % self.config.source_queue_size)
        except Exception as err:  # a bug must not kill the MQTT thread
            self._count("dropped.internal_error")
            LOG.error("%s: internal error on %r: %s: %s", self.config.robot_name,
                      str(getattr(message, "topic", "?"))[:120], type(err).__name__, err)

    def admit(self, topic_text):
        """The queue key (sender sourceId) of a message read from MQTT, or None when the sender's
        token bucket drops it (obstacle Advertises only: the costly ones; our own Resolves, heartbeats
        and footprints are not limited here). A topic that does not parse is queued under "" and
        counted by handle()."""
        known = self._admit_cache.get(topic_text)
        if known is None:
            try:
                topic = parse_topic(topic_text)
            except CoatyError:
                return ""
            key = topic.source_id or ""
            limited = topic.event == "ADV" and topic.object_type is not None and key != self.identity_id \
                and areas.is_scoped_object_type(topic.object_type, self.config.object_type)
            if len(self._admit_cache) >= 4096:
                self._admit_cache.clear()
            known = self._admit_cache[topic_text] = (key, limited)   # a flood repeats one topic
        key, limited = known
        if limited and not self._source_buckets.allow(key, self._clock()):
            self._source_drop(key, "source_rate_limited", topic_text,
                              "over source_message_rate %g/s (burst %d)"
                              % (self.config.source_message_rate, self.config.source_message_burst))
            return None
        return key

    def _source_drop(self, key, reason, topic_text, hint):
        self._count("dropped." + reason)
        robot = self._robot_of.get(key)
        label = "%s@%s" % (robot, key[:8]) if robot else key   # robot (sourceId) when its heartbeat told us
        with self._source_drops_lock:
            self._source_drops.drop(label, reason, self._clock(), "%s, last on %s" % (hint, str(topic_text)[:120]))

    def _serve_inbox(self):
        while not self.serve_one(timeout=1.0):
            pass

    def serve_one(self, timeout=None):
        """Hands the next message of the inbox (round-robin over senders) to handle(). Returns True
        once the inbox is closed and empty (the worker ends)."""
        item = self._inbox.get(timeout=timeout)
        if item is None:
            return self._stopping or self._killed
        _key, (topic_text, payload) = item
        try:
            self.handle(topic_text, payload)
        except Exception as err:  # a bug must not end delivery
            self._count("dropped.internal_error")
            LOG.error("%s: internal error on %r: %s: %s", self.config.robot_name, str(topic_text)[:120],
                      type(err).__name__, err)
        # Let paho's thread read on: holding the GIL until Python's switch interval (5 ms) forced it
        # out, this busy worker let paho read about one message per 5 ms, and yielding only per
        # message about one per message handled, so another sender's message sat unread in the
        # socket behind a flood (bench_flood: p99 1.2 s, then 0.8 s). While the socket has unread
        # data, paho gets a moment to read (and drop the excess) before the next message is handled.
        time.sleep(0.0005 if self._unread() else 0)
        return False

    def _unread(self):
        sock = self._mqtt.socket()
        if sock is None:
            return False
        try:
            return bool(select.select([sock], [], [], 0)[0])
        except (OSError, ValueError):
            return False

    def on_message(self, client, userdata, message):
        """Handles one message at once (the synchronous boundary, for tests). Never raises."""
        try:
            self.handle(message.topic, message.payload)
        except Exception as err:  # a bug must not kill the MQTT thread
            self._count("dropped.internal_error")
            LOG.error("%s: internal error on %r: %s: %s", self.config.robot_name,
                      str(getattr(message, "topic", "?"))[:120], type(err).__name__, err)

    def handle(self, topic_text, payload):
        """Handles one MQTT message; bad input is counted, logged and dropped."""
        try:
            topic = parse_topic(topic_text)
            if topic.event == "CHN" and topic.filter == HEARTBEAT_CHANNEL \
                    and topic.namespace == self.config.namespace:
                self._on_heartbeat(topic, payload)   # our own included: the echo is the point
                return
            if topic.event == "CHN" and topic.filter == ECHO_CHANNEL and topic.namespace == self._echo_namespace:
                self._on_echo(topic, payload)
                return
            if topic.source_id == self.identity_id:
                self._count("echoes_suppressed")
                return
            if topic.namespace != self.config.namespace:
                self._count("ignored")
                return
            if topic.event == "RSV" and not self._is_pending(topic.correlation_id):
                self._count("ignored")  # a Resolve to somebody else's Discover
                return
            data = codec.parse_payload(payload, self.config.limits)
            if topic.event == "ADV" and topic.object_type == self.config.object_type:
                update = codec.decode_advertise(data, self.config.object_type, self.config.limits)
                self._sent_fleet_wide(update)
                self._deliver(update, topic)
            elif topic.event == "ADV" and areas.parse_area(topic.object_type, self.config.object_type) is not None:
                self._count("received_from_area")
                self._deliver(codec.decode_advertise(data, topic.object_type, self.config.limits), topic)
            elif topic.event == "ADV" and topic.object_type is not None and areas.is_scoped_object_type(
                    topic.object_type, self.config.footprint_object_type):
                footprint = footprints.decode_footprint_advertise(data, topic.object_type)
                if self._deliver_footprint(footprint, topic):
                    with self._lock:
                        if len(self._footprint_senders) < 4096 or topic.source_id in self._footprint_senders:
                            self._footprint_senders[topic.source_id] = (footprint.robot,
                                                                        data["object"]["objectId"].lower())
            elif topic.event == "CHN" and topic.filter == renewals.CHANNEL:
                batch = renewals.decode_renewals(data, self.config.object_type, self.config.limits)
                self._count("renewals_received", len(batch.obstacles))
                for update in batch.obstacles:
                    self._sent_fleet_wide(update)
                self._deliver_batch(batch, topic, topic_text, payload)
            elif topic.event == "ADV" and topic.core_type == codec.IDENTITY_CORE_TYPE:
                self._on_identity(topic, data)
            elif topic.event == "DAD":
                self._on_deadvertise(topic, codec.decode_deadvertise(data))
            elif topic.event == "DSC":
                self._answer_discover(topic, codec.decode_discover(data, self.identity_id,
                                                                   self.config.object_type))
            elif topic.event == "RSV":
                self._deliver_batch(codec.decode_resolve(data, self.config.object_type, self.config.limits),
                                    topic, topic_text, payload)
            else:
                self._count("ignored")
        except CoatyError as err:
            self._drop(err, topic_text, payload)

    def _is_pending(self, correlation_id):
        with self._lock:
            started = self._pending_discovers.get(correlation_id)
        return started is not None and self._clock() - started < self.config.discover_window

    def _drop(self, err, topic_text, payload):
        self._count("dropped." + err.reason)
        excerpt = bytes(payload[:80]) if isinstance(payload, (bytes, bytearray)) else str(payload)[:80]
        LOG.warning("%s: dropped %s on %r: %s; payload %r", self.config.robot_name, err.reason,
                    str(topic_text)[:120], err, excerpt)

    def _deliver_batch(self, batch, topic, topic_text, payload):
        """A codec.ObstacleBatch: its bad objects dropped (each counted and logged), its good ones delivered."""
        for err in batch.errors:
            self._drop(err, topic_text, payload)
        for update in batch.obstacles:
            self._deliver(update, topic)

    def _deliver(self, update, topic):
        if self.config.authenticate_sources:
            expected = identity_for(self.config.namespace, update.source)
            if topic.source_id != expected:
                # Only the robot itself may speak for it: an update or clear of another robot's
                # obstacle is fine, but under the sender's own name (and the broker's ACL makes
                # sure the sender's sourceId is its own).
                self._drop(ForgedSourceError(
                    "obstacle %s v%d claims source %r (identity %s) but was sent by %s"
                    % (update.uuid, update.version, update.source, expected, topic.source_id)),
                    str(topic), b"")
                return
        self._count("received")
        try:
            self._on_obstacle(update, topic)
        except Exception as err:
            self._count("dropped.delivery_error")
            LOG.error("%s: could not deliver obstacle %s v%d from %s: %s: %s", self.config.robot_name,
                      update.uuid, update.version, update.source, type(err).__name__, err)

    def _deliver_footprint(self, footprint, topic):
        if self.config.authenticate_sources and topic.source_id != identity_for(self.config.namespace,
                                                                                footprint.robot):
            self._drop(ForgedSourceError("footprint of %r was sent by %s, not by that robot's identity"
                                         % (footprint.robot, topic.source_id)), str(topic), b"")
            return
        # Bounded authority (issue 27, item 10): a peer's footprint is cells no layer shares, so a
        # made-up or building-sized one would blind every robot's sharing around it.
        if self.config.known_robots and footprint.robot not in self.config.known_robots:
            self._drop(UnknownRobotError("footprint of robot %r (sourceId %s): not in known_robots"
                                         % (footprint.robot, topic.source_id)), str(topic), b"")
            return
        width, height = footprints.extent(footprint.points)
        if max(width, height) > self.config.max_footprint_extent:
            self._drop(FootprintTooLargeError(
                "footprint of robot %r (sourceId %s) is %.2f m x %.2f m, larger than max_footprint_extent %g m"
                % (footprint.robot, topic.source_id, width, height, self.config.max_footprint_extent)),
                str(topic), b"")
            return
        if footprint.robot == self.config.robot_name:
            # another agent under our name (or a replay of ours): this robot is not a fleet robot to itself
            self._count("footprints_own_name")
            return
        self._count("footprints_received")
        if self._on_footprint is None:
            return True
        try:
            self._on_footprint(footprint, topic)
        except Exception as err:
            self._count("dropped.delivery_error")
            LOG.error("%s: could not deliver the footprint of %s: %s: %s", self.config.robot_name,
                      footprint.robot, type(err).__name__, err)
        return True

    def _on_identity(self, topic, data):
        """An agent's Identity advert: its name, so that a Discover from it says which robot asks. Under
        authenticate_sources a name is taken only from the sourceId derived from it (a Coaty JS agent's
        own name is not a robot's)."""
        obj = data.get("object") if isinstance(data, dict) else None
        name = obj.get("name") if isinstance(obj, dict) else None
        if not isinstance(name, str):
            raise WrongTypeError("Identity advert without a name string")
        check_name(name, "Identity name")
        if self.config.authenticate_sources and topic.source_id != identity_for(self.config.namespace, name):
            self._count("ignored")
            return
        self._note_robot_of(topic.source_id, name)

    def _note_robot_of(self, source_id, robot):
        """sourceId -> robot, from heartbeats and Identity adverts; bounded, a known sourceId is always updated."""
        if len(self._robot_of) < _MAX_KNOWN_AGENTS or source_id in self._robot_of:
            self._robot_of[source_id] = robot

    def _on_deadvertise(self, topic, object_ids):
        """A Deadvertise: when it names a footprint sender's agent or advert series, that robot is gone.
        When it names a known agent (a clean stop, or the last will of a robot the broker lost), that
        robot is not counted on to answer Discovers for the obstacles it created, and the agent is
        forgotten (a robot reconnecting advertises its Identity again)."""
        peer = None
        if topic.source_id in object_ids and topic.source_id != self.identity_id:
            peer = self._robot_of.pop(topic.source_id, None)
        if peer is not None:
            self.liveness.departed(peer)
            self._count("peers_departed")
        with self._lock:
            known = self._footprint_senders.get(topic.source_id)
            if known is None or not ({topic.source_id, known[1]} & set(object_ids)):
                if peer is None:
                    self._counters["ignored"] += 1
                return
            del self._footprint_senders[topic.source_id]
        self._count("footprints_withdrawn")
        if self._on_footprint_withdrawn is not None:
            try:
                self._on_footprint_withdrawn(known[0], topic)
            except Exception as err:
                self._count("dropped.delivery_error")
                LOG.error("%s: could not withdraw the footprint of %s: %s: %s", self.config.robot_name,
                          known[0], type(err).__name__, err)

    def withdraw_footprint(self):
        """Takes this robot's footprint back (a Deadvertise of its advert series): peers forget it now,
        not when a parked advert's validFor runs out. Returns False when not connected."""
        if not self._connected:
            return False
        self._count("footprints_withdrawn_sent")
        self._send(self._dad_topic, codec.deadvertise_payload([self.footprint_object_id]), queue=False)
        return True

    def _resolve_obstacles(self, reply, updates):
        """Answers a Discover with these obstacles in as few Resolves (on ``reply``) as fit: up to
        RESOLVE_BATCH objects each, the first as ``object`` and the rest as ``relatedObjects``, each within
        RESOLVE_BATCH_BYTES (an obstacle alone within max_payload_bytes). One Resolve per obstacle cost a
        joining robot a message per obstacle per robot answering, and at 40 robots about half of those never
        reached it (bench_join)."""
        objects = [codec.obstacle_to_object(u, self.config.object_type, self.config.compact_indexes) for u in updates]
        for start in range(0, len(objects), RESOLVE_BATCH):
            self._send_resolve(reply, objects[start:start + RESOLVE_BATCH])

    def _send_resolve(self, reply, objects):
        payload = codec.resolve_payload(objects[0], objects[1:])
        limit = self.config.max_payload_bytes if len(objects) == 1 else \
            min(self.config.max_payload_bytes, RESOLVE_BATCH_BYTES)
        if len(payload) > limit:
            if len(objects) == 1:
                self._count("dropped_outgoing.oversized")
                return
            half = len(objects) // 2
            self._send_resolve(reply, objects[:half])
            self._send_resolve(reply, objects[half:])
            return
        self._send(reply, payload, queue=False)
        self._count("resolves_sent")
        self._count("obstacles_resolved", len(objects))

    def _left_to_creator(self, creator, requester):
        """True when another robot's obstacle is answered by its creator alone (``discover_answers``
        "creator"): the creator is a live peer and is not the one asking (a robot's Identity advert, which
        it sends before its Discover, names it). Otherwise every robot holding it answers, as when its
        creator is gone: the fleet's copies are all that is left (under authenticate_sources, each
        under its own name: see _as_answered)."""
        if self.config.discover_answers != "creator" or creator == self.config.robot_name:
            return False
        if self._robot_of.get(requester) == creator:
            return False   # the creator itself asks: it restarted, and the fleet's copies are all it has
        return self.liveness.alive(creator)

    def _as_answered(self, update):
        """The copy of an obstacle from our list that answers a Discover. Under authenticate_sources every
        receiver drops an obstacle whose source is not the robot that sent it (forged_source), so another
        robot's obstacle goes under our name, as any update of another robot's obstacle does: same uuid,
        version and cells. Without it, a robot joining after a creator left learnt none of its obstacles."""
        if not self.config.authenticate_sources or update.source == self.config.robot_name:
            return update
        self._count("resolved_under_own_name")
        return dataclasses.replace(update, source=self.config.robot_name)

    def _discover_allowed(self, requester):
        """True when a Discover from `requester` may be answered now (its own token bucket; the
        longest-quiet requesters, whose buckets are full again, are forgotten first)."""
        with self._lock:
            return self._discover_buckets.allow(requester, self._clock())

    def _answer_discover(self, topic, request):
        if not self._discover_allowed(topic.source_id):
            self._count("dropped.discover_rate_limited")
            return
        ns = self.config.namespace
        reply = str(Topic(ns, "RSV", self.identity_id, correlation_id=topic.correlation_id))
        self._count("discovers_answered")
        if request.identity:
            self._send(reply, codec.resolve_payload(self._identity), queue=False)
            self._count("resolves_sent")
        answers = []
        if request.areas and not request.obstacles and self.config.obstacle_area_size > 0:
            # a robot entering these areas: the updates it did not hear there (each robot replays its own)
            answers = [u for u in self._replayable_own_updates() if self._obstacle_area(u) in request.areas]
        if request.obstacles:
            answers = self._replayable_own_updates()
            with self._lock:
                current, as_of = self._current, self._current_as_of
            elapsed = self._clock() - as_of
            for update in current:
                if self._left_to_creator(update.source, topic.source_id):
                    self._count("resolves_left_to_creator")
                    continue
                # the list's deadlines were valid at as_of: age them to now (a copy made from
                # a Resolve must not outlive the original)
                update = lifetimes.aged(update, elapsed)
                if update is None:
                    self._count("resolve_skipped_expired")
                    continue
                answers.append(self._as_answered(update))
        if answers:
            self._resolve_obstacles(reply, answers)
