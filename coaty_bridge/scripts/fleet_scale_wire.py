"""bench_fleet_scale's measuring on the wire (no ROS).

Bytes on the wire, two ways that must agree:
- per robot: every byte its MQTT connection writes to or reads from its TCP socket (paho's
  ``_sock_send`` / ``_sock_recv`` wrapped): topic strings, payloads, MQTT fixed and variable headers,
  PINGREQ/PINGRESP, SUBSCRIBE/UNSUBSCRIBE, CONNECT; all but TCP/IP's own headers;
- per broker: mosquitto's ``$SYS/broker/bytes/received`` and ``.../sent`` (every byte it read and wrote,
  bridge connections and this watcher's own $SYS messages included), published every ``sys_interval``.
"""
import math
import os
import threading
import time

import paho.mqtt.client as paho

#: mosquitto's config line for $SYS every second (default 10 s: too coarse for a 60 s window)
SYS_INTERVAL_CONFIG = "sys_interval 1"
TICK = os.sysconf("SC_CLK_TCK")


def publish_packet_bytes(topic, payload):
    """Bytes of a QoS 0 MQTT 3.1.1 PUBLISH on the wire: fixed header (1 byte + remaining length as a
    1..4-byte varint), the topic with its 2-byte length, the payload (no packet id at QoS 0)."""
    remaining = 2 + len(topic.encode("utf-8") if isinstance(topic, str) else topic) + len(payload or b"")
    length_bytes = 1
    while remaining >= 128 ** length_bytes:
        length_bytes += 1
    return 1 + length_bytes + remaining


def count_wire(mqtt, counter):
    """Wraps a paho client's socket reads and writes; ``counter`` gets ``wire_in`` / ``wire_out`` added."""
    recv, send = mqtt._sock_recv, mqtt._sock_send

    def counting_recv(bufsize):
        data = recv(bufsize)
        counter.wire_in += len(data)
        return data

    def counting_send(buf):
        sent = send(buf)
        counter.wire_out += sent or 0
        return sent
    mqtt._sock_recv, mqtt._sock_send = counting_recv, counting_send


class BrokerBytes:
    """Watches one mosquitto's $SYS byte counters; ``history`` holds (time heard, received, sent)."""

    def __init__(self, host, port):
        self.history = []
        self._values = {}
        self._lock = threading.Lock()
        self._client = paho.Client(client_id="bench-sys-%d" % port, clean_session=True)
        self._client.on_connect = lambda c, u, f, rc: c.subscribe([("$SYS/broker/bytes/received", 0),
                                                                   ("$SYS/broker/bytes/sent", 0)])
        self._client.on_message = self._on_message
        self._client.connect(host, port, keepalive=60)
        self._client.loop_start()

    def _on_message(self, _client, _userdata, message):
        with self._lock:
            self._values[message.topic.rsplit("/", 1)[1]] = int(message.payload)
            if len(self._values) == 2:
                self.history.append((time.time(), self._values["received"], self._values["sent"]))

    def stop(self):
        self._client.loop_stop()
        self._client.disconnect()


def broker_bytes_per_minute(watchers, start, end):
    """(received + sent per minute by all brokers, s covered) between the first counter update at or
    after ``start`` and the last at or before ``end``; (nan, 0) without two updates in the window."""
    total, spans = 0.0, []
    for watcher in watchers:
        inside = [h for h in list(watcher.history) if start <= h[0] <= end]
        if len(inside) < 2:
            return float("nan"), 0.0
        first, last = inside[0], inside[-1]
        total += (last[1] - first[1]) + (last[2] - first[2])
        spans.append(last[0] - first[0])
    span = min(spans)
    return (total / span * 60.0 if span > 0 else float("nan")), span


def rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def proc_cpu_seconds(pid):
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def percentile(values, q):
    values = sorted(values)
    if not values:
        return float("nan")
    return values[min(len(values) - 1, int(math.ceil(q * len(values))) - 1)]


def message_kind(topic):
    """What a received message is, for the byte breakdown: Coaty event and, for Advertises and
    Channels, whether it is an obstacle, a footprint or a heartbeat."""
    parts = topic.split("/")
    event = parts[3] if len(parts) > 3 else "?"
    if event.startswith("ADV::"):
        if "RobotFootprint" in event:
            # with footprint areas, only the evidence before an obstacle message goes under the plain objectType
            return "footprint" if ".area_" in event else "evidence"
        return "obstacle"
    if event.startswith("CHN:"):
        for kind in ("heartbeat", "echo", "catchup"):   # peers' heartbeats; the own echo (liveness.py); catchup.py
            if kind in event.lower():
                return kind
        return "channel"
    return event.split("::")[0].lower()


def samples_note(n):
    """A latency column's sample count, and why when below 30 (a p99 of fewer is its maximum or less)."""
    if n >= 30:
        return "n = %d updates" % n
    return "n = %d < 30: only %d updates in the measured window; raise --duration or --robots" % (n, n)
