"""mosquitto's byte counters as the fleet bench reads them: the cumulative $SYS counters over a paho client, and
the bytes of one $SYS message on the wire (taken off the counts: the bench's own traffic)."""
import os
import threading
import time
import urllib.parse

import rospy

from fleet_tests.errors import ScenarioError


def sys_message_bytes(topic, payload):
    """Bytes of one QoS-0 MQTT 3.1.1 PUBLISH on the wire: fixed header (1 + remaining-length
    bytes), topic length (2), topic, payload."""
    remaining = 2 + len(topic.encode()) + len(payload)
    length_bytes = 1
    while remaining >= 128 ** length_bytes:
        length_bytes += 1
    return 1 + length_bytes + remaining


class BrokerCounters:
    """mosquitto's cumulative byte counters, read with a paho client on the broker URL
    (mqtt://host:port, /fleet/broker_url): $SYS/broker/bytes/sent (everything the broker wrote to
    its clients: fan-out to every subscriber, MQTT framing, CONNACK/SUBACK/PINGRESP) and
    $SYS/broker/bytes/received (everything the clients sent it). mosquitto publishes them every
    sys_interval (10 s wall by default), bytes/received before bytes/sent and each only when it
    changed; on subscribing the retained values arrive, which may be up to sys_interval old, so a
    sample is a fresh (not retained) bytes/sent with the bytes/received current at that moment."""

    SENT = "$SYS/broker/bytes/sent"
    RECEIVED = "$SYS/broker/bytes/received"

    def __init__(self, url, monitor=None):
        """``monitor``: run_broker's /fleet/broker_monitor ({username, password_file}), the read-only
        login of the secure default (an anonymous client is refused there)."""
        import paho.mqtt.client as mqtt
        parts = urllib.parse.urlparse(url)
        self.cond = threading.Condition()
        self.values = {}
        self.samples = []    # (wall time, sim time, bytes sent, bytes received), one per fresh publication
        self.own = []        # (wall time, bytes) of every message this client received
        self.client = mqtt.Client(client_id="bench_sys_%d" % os.getpid(), clean_session=True)
        self.client.on_message = self._on_message
        if monitor:
            from coaty_bridge.security import read_password_file
            self.client.username_pw_set(monitor["username"], read_password_file(monitor["password_file"]))
        self.client.connect(parts.hostname, parts.port or 1883, keepalive=60)
        self.client.subscribe([(self.SENT, 0), (self.RECEIVED, 0)])
        self.client.loop_start()

    def _on_message(self, _client, _userdata, msg):
        now = time.time()
        with self.cond:
            self.own.append((now, sys_message_bytes(msg.topic, msg.payload)))
            try:
                self.values[msg.topic] = int(msg.payload)
            except ValueError:
                return
            if msg.topic == self.SENT and not msg.retain and self.RECEIVED in self.values:
                self.samples.append((now, rospy.get_time(), self.values[self.SENT], self.values[self.RECEIVED]))
            self.cond.notify_all()

    def next_sample(self, after, timeout=35.0):
        """The first sample published after wall time `after` (waits up to timeout wall s)."""
        end = time.time() + timeout
        with self.cond:
            while True:
                fresh = [s for s in self.samples if s[0] > after]
                if fresh:
                    return fresh[0]
                left = end - time.time()
                if left <= 0:
                    raise ScenarioError("no $SYS/broker/bytes publication from the broker in %.0f s" % timeout)
                self.cond.wait(left)

    def own_bytes(self, start, end):
        """Bytes of the $SYS messages this client received at wall times in [start, end)."""
        with self.cond:
            return sum(n for t, n in self.own if start <= t < end)

    def close(self):
        self.client.loop_stop()
        self.client.disconnect()
