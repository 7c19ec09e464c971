"""What the bridge receives: paho's messages sorted into a queue per sender (fair delivery, rate limit
before parsing), then each one validated and handed on: obstacles, footprints, heartbeats, Identity
adverts, Deadvertises, Discovers and Resolves. Bad input is counted, logged once and dropped; the
MQTT thread never sees an exception. A part of CoatyBridgeClient (client.py)."""
import logging
import select
import time

from coaty_bridge import areas, catchup, codec, footprint as footprints, logins, renewals
from coaty_bridge.errors import (CoatyError, FootprintTooLargeError, ForgedSourceError, ReservedSourceError,
                                 UnknownRobotError, WrongTypeError)
from coaty_bridge.identity import identity_for
from coaty_bridge.liveness import CHANNEL as HEARTBEAT_CHANNEL, ECHO_CHANNEL
from coaty_bridge.topics import check_name, parse_topic
from sharing_msgs.authority import MASTER_CONTROL

LOG = logging.getLogger("coaty_bridge.client")

#: Agents (sourceIds) whose robot names are remembered; one withdrawn by a Deadvertise is forgotten.
_MAX_KNOWN_AGENTS = 4096
# what a bridge remembers per sender is bounded: names and topics from unauthenticated senders must
# not grow memory without bound. Topics admitted (then forgotten all at once, a flood repeats one),
# footprint senders (new ones beyond it are not remembered for their Deadvertise) and robots warned
# about another area size (beyond it: counted, not warned)
MAX_ADMIT_CACHE = 4096
MAX_FOOTPRINT_SENDERS = 4096
MAX_AREA_MISMATCH_WARNED = 4096
#: Longest the worker waits, per message it handled, while paho has unread messages in the socket (s): a continuous
#: flood still leaves it at least 1 / READ_FIRST messages a second.
READ_FIRST = 0.005


class IncomingMixin:
    """Receiving of CoatyBridgeClient."""

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
            if len(self._admit_cache) >= MAX_ADMIT_CACHE:
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
        # socket behind a flood (bench_flood: p99 1.2 s, then 0.8 s). A moment per message still let
        # paho read only a few messages per message handled: the robot_1 stage of bench_flood stayed
        # at 0.3-0.7 s p99. So while the socket has unread data the worker waits (up to READ_FIRST s
        # per message): paho reads the backlog at its own pace, drops a flood's excess and sorts
        # another sender's message into its queue, where it waits for at most one of the flood's.
        deadline = None
        while self._unread():
            now = time.monotonic()
            deadline = now + READ_FIRST if deadline is None else deadline
            if now >= deadline:
                break
            time.sleep(0.0005)
        if deadline is None:
            time.sleep(0)
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
            if topic.event == "CHN" and topic.filter == logins.channel(self.identity_id):
                self._on_login_alert(topic, payload)
                return
            if topic.source_id == self.identity_id:
                self._count("echoes_suppressed")
                self.liveness.own_returned(topic_text, payload)   # proves the path as an echo does
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
                self._check_footprint_area(footprint, topic)
                if self._deliver_footprint(footprint, topic):
                    with self._lock:
                        if len(self._footprint_senders) < MAX_FOOTPRINT_SENDERS \
                                or topic.source_id in self._footprint_senders:
                            self._footprint_senders[topic.source_id] = (footprint.robot,
                                                                        data["object"]["objectId"].lower())
            elif topic.event == "CHN" and topic.filter == renewals.CHANNEL:
                batch = renewals.decode_renewals(data, self.config.object_type, self.config.limits)
                self._count("renewals_received", len(batch.obstacles))
                for update in batch.obstacles:
                    self._sent_fleet_wide(update)
                self._deliver_batch(batch, topic, topic_text, payload)
            elif topic.event == "CHN" and catchup.area_of_channel(topic.filter) is not None:
                self._answer_catchup(topic, data)
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

    def _on_login_alert(self, topic, payload):
        """run_broker says another connection uses this robot's login (logins.py); only its own login may say so."""
        if topic.source_id != identity_for(self.config.namespace, logins.BROKER_LOGIN_NAME):
            raise ForgedSourceError("login alert for %s sent by %s, not by the broker's login"
                                    % (self.config.robot_name, topic.source_id))
        alert = logins.LoginAlert.from_payload(codec.parse_payload(payload, self.config.limits))
        others = self.login_alerts.note(alert)
        self._count("login_alerts")
        if others:
            LOG.warning("%s: another connection under this robot's login %s: client id %s from %s (connected now: %s); "
                        "if it is not this robot, its secret has leaked: rotate it (rosrun coaty_bridge fleet_credentials "
                        "rotate %s)", self.config.robot_name, alert.login, alert.client_id, alert.address,
                        ", ".join(others), self.config.robot_name)

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
        if update.source == MASTER_CONTROL:
            # master control's areas reach a robot through its own VDA 5050 bridge, never from a peer
            self._drop(ReservedSourceError("obstacle %s v%d claims source %r, which no robot may use (sourceId %s)"
                                           % (update.uuid, update.version, update.source, topic.source_id)),
                       str(topic), b"")
            return
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
        operator = self.config.authenticate_sources and update.source in self.config.operators
        if operator:
            # an operator's action (fleet_console): its login is its authority, it has no sensors to judge
            action = ("removed" if update.cleared and not update.marked else
                      "added" if update.version == 1 else "confirmed")
            LOG.info("%s: operator %s %s obstacle %s (v%d, %d cells marked, %d cleared)", self.config.robot_name,
                     update.source, action, update.uuid, update.version, len(update.marked), len(update.cleared))
        elif self.config.require_evidence and topic.event != "RSV":
            # an observation (an Advertise, a renewal) carries only what its sender could have seen; a Resolve
            # restores state and is no observation: the handler never takes it as a renewal (fleet_state)
            update = self._judge(update, topic)
            if update is None:
                return
        self._count("received")
        try:
            self._on_obstacle(update, topic)
        except Exception as err:
            self._count("dropped.delivery_error")
            LOG.error("%s: could not deliver obstacle %s v%d from %s: %s: %s", self.config.robot_name,
                      update.uuid, update.version, update.source, type(err).__name__, err)

    def _check_footprint_area(self, footprint, topic):
        """A peer advertising in a square that does not hold its footprint at our footprint_area_size uses another
        size: the two robots do not hear each other's adverts (each layer may share the other robot as an
        obstacle) nor each other's monitoring updates. The advert is still taken; the WARN says what to set."""
        area = areas.parse_area(topic.object_type, self.config.footprint_object_type)
        size = self.config.footprint_area_size
        if area is None or size <= 0:
            return
        where = footprints.centroid(footprint.points)
        if areas.lies_in(where, area, size):
            return
        self._count("footprint_area_mismatches")
        with self._lock:
            if footprint.robot in self._area_mismatch_warned \
                    or len(self._area_mismatch_warned) >= MAX_AREA_MISMATCH_WARNED:
                return
            self._area_mismatch_warned.add(footprint.robot)
        LOG.warning("%s: robot %r (sourceId %s) advertises its footprint at (%.2f, %.2f) under square %s, but at our "
                    "footprint_area_size %g m that point lies in square %s: it uses another area size, and robots "
                    "with different sizes do not hear each other. Set footprint_area_size and obstacle_area_size "
                    "the same on every robot of the fleet (the default changed from 10 m to 5 m on 2026-11-29)",
                    self.config.robot_name, footprint.robot, topic.source_id, where[0], where[1], area, size,
                    areas.area_of(where, size))

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
        self._note_sighting(footprint)
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
