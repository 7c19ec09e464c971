"""The MQTT side of the VDA 5050 bridge (python3-paho-mqtt, 1.x API; VERSION1 callbacks on 2.x).

Subscribes ``<prefix>/order``, ``<prefix>/instantActions`` and (3.0) ``<prefix>/zoneSet``, hands
every payload to the ``BridgeCore`` and publishes ``<prefix>/state`` (QoS 0) and
``<prefix>/connection`` (QoS 1, retained, with a CONNECTIONBROKEN last will), as VDA 5050 §6 says.
No ROS in here: the node and the tests drive it the same way.

On the fleet's secure broker (issue 43, item 7) it logs in (``username``, and ``password`` or a
``password_file`` read again before each connection) and can use TLS (``tls_ca``, ``tls_cert``,
``tls_key``, as the Coaty bridge); the broker's ACL lets only master control's login send orders,
instant actions and zone sets, and this vehicle's login read them and report its own state. TLS files
that are absent, unreadable or expired are named with what to do, and checked again until they are right."""
import json
import logging
import secrets
import ssl
import threading
import time

import paho.mqtt.client as mqtt

from sharing_msgs import tls_files
from vda5050_bridge import core

LOG = logging.getLogger("vda5050_bridge")


def _paho_client(client_id):
    if hasattr(mqtt, "CallbackAPIVersion"):  # paho-mqtt >= 2.0
        return mqtt.Client(mqtt.CallbackAPIVersion.VERSION1, client_id=client_id, clean_session=True)
    return mqtt.Client(client_id=client_id, clean_session=True)


class VdaMqttClient:
    """One vehicle on one broker. ``on_areas(areas)`` is called (from paho's thread) whenever the
    master-control blocked areas changed; ``log(level, line)`` gets one line per dropped message."""

    def __init__(self, bridge, host, port, interface_name="uagv", on_areas=None, log=None,
                 clock=time.time, keepalive=60, username="", password="", password_file="", tls_ca="", tls_cert="",
                 tls_key="", tls=False):
        self.bridge = bridge
        self.host, self.port = host, port
        self.prefix = core.topic_prefix(interface_name, bridge.version, bridge.manufacturer, bridge.serial_number)
        self.on_areas = on_areas or (lambda areas: None)
        self.log = log or (lambda level, line: LOG.log(level, line))
        self.clock = clock
        self.keepalive = keepalive
        self.lock = threading.RLock()
        self.connected = threading.Event()
        self._areas = {}
        self.username, self._password, self.password_file = username, password, password_file
        self.tls_files = (tls_ca, tls_cert, tls_key)
        self.use_tls = bool(tls or tls_ca or tls_cert)
        self.tls_problem = None
        self._stop = threading.Event()
        # a nonce in the client id: another connection under this vehicle's login must not take its place
        self._client = _paho_client("vda5050_%s_%s_%s" % (bridge.manufacturer, bridge.serial_number,
                                                          secrets.token_hex(4)))
        if username:
            self._client.username_pw_set(username, self._read_password() or None)
        will = self.bridge.builder.connection("BROKEN", self.clock())
        self._client.will_set(self.prefix + "/connection", json.dumps(will), qos=1, retain=True)
        self._client.on_connect = self._on_connect
        self._client.on_disconnect = self._on_disconnect
        self._client.on_connect_fail = lambda c, u: self._refresh_login()
        self._client.on_message = self._on_message
        self._client.reconnect_delay_set(0.5, 30)

    def _read_password(self):
        if not self.password_file:
            return self._password
        try:
            with open(self.password_file) as handle:
                return handle.readline().rstrip("\r\n") or self._password
        except OSError as err:
            self.log(logging.WARNING, "vda5050_bridge: cannot read password_file %s (%s); trying the secret read before"
                     % (self.password_file, err.strerror or err))
            return self._password

    def _refresh_login(self):
        """A secret rotated while the fleet runs is used on the next connection."""
        if self.username and self.password_file:
            secret = self._read_password()
            if secret != self._password:
                self._password = secret
                self._client.username_pw_set(self.username, secret)

    def _on_disconnect(self, _client, _userdata, _rc):
        self.connected.clear()
        self._refresh_login()

    def start(self):
        """Connects in the background, once the TLS files (if any) are right; until then it says which file is wrong
        and checks again every tls_files.RETRY_INTERVAL s."""
        threading.Thread(target=self._start_when_ready, name="vda5050_bridge connect", daemon=True).start()

    def _start_when_ready(self):
        while not self._stop.is_set():
            problem = tls_files.tls_problem(*self.tls_files) if self.use_tls else None
            if problem is None:
                break
            if problem != self.tls_problem:
                self.log(logging.ERROR, "vda5050_bridge: not connecting to %s:%d: %s" % (self.host, self.port, problem))
            self.tls_problem = problem
            self._stop.wait(tls_files.RETRY_INTERVAL)
        if self._stop.is_set():
            return
        self.tls_problem = None
        if self.use_tls:
            ca, cert, key = self.tls_files
            self._client.tls_set(ca_certs=ca or None, certfile=cert or None, keyfile=key or None,
                                 cert_reqs=ssl.CERT_REQUIRED)
        self._client.connect_async(self.host, self.port, keepalive=self.keepalive)
        self._client.loop_start()

    def stop(self, timeout=2.0):
        self._stop.set()
        if self.connected.is_set():
            with self.lock:
                doc = self.bridge.builder.connection("OFFLINE", self.clock())
            info = self._client.publish(self.prefix + "/connection", json.dumps(doc), qos=1, retain=True)
            try:
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError):
                pass
        self._client.disconnect()
        self._client.loop_stop()

    def _on_connect(self, client, _userdata, _flags, rc):
        if rc != 0:
            self.log(logging.WARNING, "vda5050_bridge: broker %s:%d refused the connection (rc %d: %s; login %s)"
                     % (self.host, self.port, rc, mqtt.connack_string(rc), self.username or "anonymous"))
            self._refresh_login()
            return
        client.subscribe([(self.prefix + "/" + t, 0) for t in self.bridge.topics_in()])
        with self.lock:
            doc = self.bridge.builder.connection("ONLINE", self.clock())
        client.publish(self.prefix + "/connection", json.dumps(doc), qos=1, retain=True)
        self.connected.set()
        self.publish_state()

    def _on_message(self, _client, _userdata, message):
        topic = message.topic[len(self.prefix) + 1:] if message.topic.startswith(self.prefix + "/") else message.topic
        with self.lock:
            line = self.bridge.on_message(topic, message.payload)
            areas = self.bridge.areas.areas()
            changed = areas != self._areas
            self._areas = areas
        if line is not None:
            self.log(logging.WARNING, "vda5050_bridge %s: %s" % (self.bridge.serial_number, line))
            return
        if changed:
            self.on_areas(areas)
        self.publish_state()  # an order (or anything taken) changes what the state reports

    def set_obstacles(self, obstacles):
        """The fleet's current obstacles; publishes a state at once when the errors changed."""
        with self.lock:
            before = core.blocked_elements(self.bridge.order, self.bridge.obstacles.values(), self.bridge.half_width)
            self.bridge.set_obstacles(obstacles)
            after = core.blocked_elements(self.bridge.order, self.bridge.obstacles.values(), self.bridge.half_width)
        if before != after:
            self.publish_state()

    def publish_state(self):
        with self.lock:
            doc = self.bridge.state(self.clock())
        if self.connected.is_set():
            self._client.publish(self.prefix + "/state", json.dumps(doc), qos=0)
        return doc
