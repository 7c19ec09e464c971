"""The MQTT side of a bridge: one Coaty agent on Debian's python3-paho-mqtt
(1.x callback API; on paho 2.x the VERSION1 API is requested explicitly).

The agent advertises its Identity on every (re)connect, leaves a last-will
Deadvertise, answers Identity Discovers, publishes obstacle updates as
Advertise events of one custom objectType, answers obstacle Discovers from the
robot's current list with one Resolve per obstacle, and on every connect asks
its peers for their obstacles (late joiner). Bad input is dropped, logged once
and counted; the MQTT thread never sees an exception.

The agent is one class, CoatyBridgeClient, made of one part per concern: connection.py (start, stop,
paho's connection callbacks, the broker watch), heartbeats.py (end-to-end liveness), outgoing.py
(publishing), incoming.py (receiving), discovery.py (Discover and Resolve). This module builds the
agent's state and keeps the names callers import from it (BridgeConfig, choose_broker_url, ...).
"""
import collections
import logging
import threading
import time

from coaty_bridge import codec, logins, renewals
from coaty_bridge import liveness as liveness_rules
from coaty_bridge.config import (BridgeConfig, BrokerAddress, BrokerUrlChoice, choose_broker_url,  # noqa: F401
                                 parse_broker_url)
from coaty_bridge.connection import (FIRST_UNREACHABLE_WARN_AFTER, ConnectionMixin, _make_paho_client,  # noqa: F401
                                     mqtt_client_id)
from coaty_bridge.catchup import CatchUpMixin
from coaty_bridge.evidence import EvidenceMixin
from coaty_bridge.discovery import (RESOLVE_BATCH, RESOLVE_BATCH_BYTES, _MAX_DISCOVER_REQUESTERS,  # noqa: F401
                                    DiscoveryMixin)
from coaty_bridge.heartbeats import HeartbeatMixin
from coaty_bridge.incoming import IncomingMixin
from coaty_bridge.liveness import CHANNEL as HEARTBEAT_CHANNEL, ECHO_CHANNEL, Liveness
from coaty_bridge.outgoing import OWN_LOG_PER_OBSTACLE, OutgoingMixin  # noqa: F401
from coaty_bridge.topics import Topic, new_uuid, subscription
from sharing_msgs.authority import DropReport, FairQueue, PoseHistory, TokenBuckets

LOG = logging.getLogger(__name__)

#: this robot's recent footprints kept as evidence (2 Hz and more: the last minute or so)
OWN_FOOTPRINTS_KEPT = 128


class CoatyBridgeClient(ConnectionMixin, HeartbeatMixin, OutgoingMixin, IncomingMixin, DiscoveryMixin, CatchUpMixin,
                        EvidenceMixin):
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
        # plausible evidence (evidence.py): what each peer advertised, and this robot's latest footprint
        self._poses = PoseHistory(config.evidence_rule)
        self._own_footprints = collections.deque(maxlen=OWN_FOOTPRINTS_KEPT)
        self._evidence_warned = None
        self._area_mismatch_warned = set()   # robots warned about advertising at another footprint_area_size
        # obstacle messages kept back until this robot's first footprint (evidence.py); only for a robot that
        # advertises its footprint (the node says so: expect_footprints)
        self._awaiting_evidence = []
        self._expect_footprints = False
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
        self.client_id = mqtt_client_id(self.identity_id)
        self.login_alerts = logins.LoginAlerts(config.robot_name, self.client_id, clock)
        self._subscriptions = [
            (subscription(ns, "ADV::" + config.object_type), qos),
            (subscription(ns, "ADV::" + config.footprint_object_type), qos),
            (subscription(ns, "DSC", two_way=True), qos),
            (subscription(ns, "CHN:" + HEARTBEAT_CHANNEL), qos),
            (subscription(ns, "CHN:" + renewals.CHANNEL), qos),
            (subscription(ns, "DAD"), qos),
            # agents' Identity adverts (one per connection): which robot a Discover comes from
            (subscription(ns, "ADV:" + codec.IDENTITY_CORE_TYPE), qos),
            (self._echo_topic, qos),
            # run_broker's alerts about other connections under this robot's login (logins.py)
            (subscription(ns, "CHN:" + logins.channel(self.identity_id)), qos),
        ]
        # Footprint and obstacle areas heard now (the 3 x 3 around the own robot, each at its own size);
        # none until the robot's position is known.
        self._own_area = None
        # Until then it hears every one-level event of the namespace (every area's updates too), so that
        # a robot without a known position (no footprint yet, a host without one) misses no update.
        self._area_subscriptions = {subscription(ns, "+")} if config.obstacle_area_size > 0 else set()
        self._obstacle_areas = set()
        # Obstacle areas holding own updates: their catch-up requests are observed (catchup.py); and each
        # requester's last request, requester -> (correlation id, its areas answered)
        self._catchup_areas = set()
        self._catchup_last = {}
        # obstacle areas this robot stopped hearing -> clock time it left them: a catch-up on coming back asks only
        # for what was sent since (catchup.py)
        self._areas_left = {}
        # Obstacle areas (issue 29): uuid -> clock time at which the copies of robots that hear only
        # fleet-wide messages expire (the newest fleet-wide message's deadline), and this robot's pending
        # renewals, uuid -> (due, update, sent_at): its last area-scoped update, sent fleet-wide before
        # those copies would expire while the robots near the obstacle hold it longer.
        self._fleet_expiry = {}
        self._renewals = {}
        self._mqtt = _make_paho_client(self.client_id)
        self._mqtt.will_set(self._dad_topic, codec.deadvertise_payload([self.identity_id]), qos=0)
        # TLS files are checked before paho gets them (connection.py): an absent, unreadable or expired one is
        # named with what to do, and the bridge checks again until it is right
        self.tls_problem = None
        self._tls_ready = not config.use_tls
        self._tls_checked_at = None
        self._network_started = False
        self._password = config.password
        if config.username:
            self._mqtt.username_pw_set(config.username, config.password or None)
        self._mqtt.reconnect_delay_set(min_delay=config.reconnect_min_delay,
                                       max_delay=config.reconnect_max_delay)
        self._mqtt.on_connect = self._on_connect
        self._mqtt.on_disconnect = self._on_disconnect
        self._mqtt.on_connect_fail = self._on_connect_fail
        self._mqtt.on_message = self._on_mqtt_message
        self._mqtt.on_subscribe = self._on_subscribe
