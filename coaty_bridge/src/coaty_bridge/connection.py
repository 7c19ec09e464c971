"""The bridge's connection to the broker: start and stop, paho's connect/disconnect callbacks, the MQTT
client id, and the watch that WARNs while the broker cannot be reached. A part of CoatyBridgeClient
(client.py), whose state it works on."""
import logging
import secrets
import socket
import ssl
import threading

import paho.mqtt.client as mqtt

from coaty_bridge import codec
from sharing_msgs import tls_files
from coaty_bridge.topics import Topic

LOG = logging.getLogger("coaty_bridge.client")

#: s after start() without a connection (and no failed attempt yet) before the first WARN.
FIRST_UNREACHABLE_WARN_AFTER = 5.0


def mqtt_client_id(identity_id, nonce=None):
    """The MQTT client id: "Coaty", 8 hex digits of the Identity id (to tell agents apart in the
    broker's log) and a random per-start nonce of 10 hex digits (40 bits), 23 characters, the
    longest every MQTT 3.1.1 broker must accept. The Identity id is public (and, with
    authenticate_sources, computable from the robot's name), so an id made of it alone let any
    peer connect under it and make the broker drop the robot (issue 27, attack 5: 19 s cut off).
    The bridge connects with a clean session (nothing persists under the id), so a fresh id per
    start costs nothing; it stays the same across reconnects of one start. The broker does not make
    the login the client id (issue 43, item 6: a second connection under a robot's login then took the
    robot off the broker), so the nonce is what keeps the id from others: it is never logged
    (``masked_client_id``)."""
    if nonce is None:
        nonce = secrets.token_hex(5)
    return "Coaty" + identity_id.replace("-", "")[:8] + nonce


def masked_client_id(client_id):
    """The client id as logged: its nonce hidden, so a log reader cannot take the connection over."""
    return client_id[:13] + "*" * max(0, len(client_id) - 13)


def _make_paho_client(client_id):
    if hasattr(mqtt, "CallbackAPIVersion"):  # paho-mqtt >= 2.0
        return mqtt.Client(mqtt.CallbackAPIVersion.VERSION1, client_id=client_id, clean_session=True)
    return mqtt.Client(client_id=client_id, clean_session=True)


class ConnectionMixin:
    """Lifecycle, counters and the broker connection of CoatyBridgeClient."""

    def start(self):
        """Connects in the background; reconnects with backoff until stop(). With TLS files that are absent,
        unreadable or expired it says which and what to do, and checks again until they are right."""
        with self._lock:
            self._down_since = self._clock()
        self._inbox_thread = threading.Thread(target=self._serve_inbox, name="coaty_bridge inbox", daemon=True)
        self._inbox_thread.start()
        self._start_network()
        # check_broker on a wall-clock second: the MQTT thread sleeps in its backoff, and ROS time may stand
        self._watch_thread = threading.Thread(target=self._watch_broker, name="coaty_bridge broker watch",
                                              daemon=True)
        self._watch_thread.start()
        if self._auto_heartbeats:
            threading.Thread(target=self._heartbeats, name="coaty_bridge heartbeat", daemon=True).start()

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

    def _check_tls(self):
        """True when the TLS files are right (or TLS is off); else the problem is logged (ERROR, once per change, and
        every 10 min while it lasts) and kept for /diagnostics (issue 43, item 9)."""
        config = self.config
        if not config.use_tls:
            return True
        problem = tls_files.tls_problem(config.tls_ca, config.tls_cert, config.tls_key)
        self._tls_checked_at = self._clock()
        if problem is None:
            if self.tls_problem is not None:
                LOG.info("%s: the TLS files are right now; connecting to %s", config.robot_name, config.broker_url)
            self.tls_problem = None
            return True
        if problem != self.tls_problem or self._count_and_get("tls_problem_reports") % 60 == 0:
            LOG.error("%s: not connecting to %s: %s", config.robot_name, config.broker_url, problem)
        self.tls_problem = problem
        return False

    def _count_and_get(self, key):
        with self._lock:
            self._counters[key] += 1
            return self._counters[key]

    def _start_network(self):
        """Hands the TLS files to paho and starts its network thread, once they are right."""
        if self._network_started or not self._check_tls():
            return False
        config = self.config
        if config.use_tls and not self._tls_ready:
            try:
                self._mqtt.tls_set(ca_certs=config.tls_ca or None, certfile=config.tls_cert or None,
                                   keyfile=config.tls_key or None, cert_reqs=ssl.CERT_REQUIRED)
            except (ssl.SSLError, OSError, ValueError) as err:
                self.tls_problem = "the TLS files could not be loaded (%s); tls_ca %r, tls_cert %r, tls_key %r" % (
                    err, config.tls_ca, config.tls_cert, config.tls_key)
                LOG.error("%s: not connecting to %s: %s", config.robot_name, config.broker_url, self.tls_problem)
                return False
            self._tls_ready = True
        address = config.address
        self._mqtt.connect_async(address.host, address.port, keepalive=config.keepalive)
        self._mqtt.loop_start()
        self._network_started = True
        return True

    def _keep_network_alive(self):
        """paho's network thread can die on an exception it does not expect (issue 43: an expired certificate ended
        it and the bridge only said "unreachable"): say why, and start it again."""
        thread = getattr(self._mqtt, "_thread", None)   # paho's own; None before loop_start and after loop_stop
        if not self._network_started or self._stopping or thread is None or thread.is_alive():
            return
        self._count("network_thread_restarts")
        self._check_tls()
        LOG.error("%s: the MQTT network thread ended%s; starting it again", self.config.robot_name,
                  ": " + self.tls_problem if self.tls_problem else "")
        self._mqtt.loop_stop()
        self._mqtt.loop_start()

    def _watch_broker(self):
        while not self._watch_stop.wait(1.0):
            try:
                if not self._network_started:
                    if self._tls_checked_at is None or self._clock() - self._tls_checked_at >= tls_files.RETRY_INTERVAL:
                        self._start_network()
                else:
                    self._keep_network_alive()
                with self._source_drops_lock:
                    self._source_drops.flush(self._clock())
                self.check_broker()
                if self._connected:
                    self.renew_due()
                self.release_unevidenced()
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
                    "every %g s at most%s", self.config.robot_name, self.config.broker_url, down_for, attempts,
                    self.config.broker_url_source, queued, self.config.reconnect_max_delay,
                    "; the reason is likely: " + self.tls_problem if self.tls_problem else "")
        return True

    def _refresh_password(self):
        """Reads password_file again before the next attempt: a secret rotated while the fleet runs (fleet_credentials
        rotate) is the one the broker knows now."""
        path = self.config.password_file
        if not path or not self.config.username:
            return
        try:
            with open(path) as handle:
                secret = handle.readline().rstrip("\r\n")
        except OSError as err:
            LOG.warning("%s: cannot read password_file %s (%s); trying the secret read before",
                        self.config.robot_name, path, err.strerror or err)
            return
        if secret and secret != self._password:
            self._password = secret
            self._mqtt.username_pw_set(self.config.username, secret)
            self._count("password_reloaded")
            LOG.info("%s: password_file %s changed; the next connection uses the new secret", self.config.robot_name,
                     path)

    def _on_connect_fail(self, client, userdata):
        """paho: a connection attempt failed (nothing listens, no route, TLS handshake, ...)."""
        self._refresh_password()
        if self.config.use_tls:
            self._check_tls()   # a certificate that expired since: say so, not only "unreachable"
        with self._lock:
            self._counters["connect_failures"] += 1
            self._failed_attempts += 1
        self.check_broker()

    def _on_connect(self, client, userdata, flags, rc, properties=None):
        if rc != 0:
            self._refresh_password()
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
            topics = self._subscriptions + [(t, self._qos) for t in sorted(self._area_subscriptions)] + \
                [(t, self._qos) for t in self._catchup_topics()]
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
        self._refresh_password()
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
