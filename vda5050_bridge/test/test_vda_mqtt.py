"""Through a real mosquitto: a master control (plain paho here) sends an order, sees the blocked
edge in the robot's state when an obstacle appears and sees it go after the clear; a zone it
declares blocked reaches the bridge's area callback and leaves when withdrawn; a bad payload on
the way is dropped and counted and the next good one still works. Every state and connection
message on the wire validates against the schema of its version."""
import json
import threading

import paho.mqtt.client as mqtt
import pytest

from vda5050_bridge import core, schemas
from vda5050_bridge.client import VdaMqttClient, _paho_client
from test_vda_core import MAN, SER, actions_doc, order_doc, zone_set_doc

pytestmark = pytest.mark.broker


class Master:
    def __init__(self, host, port, prefix):
        self.prefix = prefix
        self.messages = []  # (topic, doc)
        self.lock = threading.Lock()
        self.client = _paho_client("master")
        self.client.on_message = self._on_message
        self.ready = threading.Event()
        self.client.on_connect = lambda c, u, f, rc: (c.subscribe(prefix + "/#", 1), self.ready.set())
        self.client.connect(host, port)
        self.client.loop_start()

    def _on_message(self, _c, _u, msg):
        topic = msg.topic[len(self.prefix) + 1:]
        if topic in ("state", "connection"):  # what the vehicle sends (not our own order etc.)
            with self.lock:
                self.messages.append((topic, json.loads(msg.payload)))

    def send(self, topic, payload):
        raw = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        self.client.publish(self.prefix + "/" + topic, raw, qos=0)

    def states(self):
        with self.lock:
            return [d for t, d in self.messages if t == "state"]

    def last_state(self):
        s = self.states()
        return s[-1] if s else None

    def stop(self):
        self.client.loop_stop()
        self.client.disconnect()


@pytest.mark.parametrize("version", ["2.1.0", "3.0.0"])
def test_master_control_sees_blocked_edge_and_robot_gets_zone(broker, wait_for, version):
    host, port = broker
    areas_seen = []
    logs = []
    bridge = core.BridgeCore(version, MAN, SER, half_width=0.3)
    robot = VdaMqttClient(bridge, host, port, on_areas=lambda a: areas_seen.append(dict(a)),
                          log=lambda level, line: logs.append(line))
    master = Master(host, port, robot.prefix)
    assert master.ready.wait(10)
    robot.start()
    try:
        wait_for(robot.connected.is_set, what="robot connected")
        wait_for(lambda: master.last_state() is not None, what="first state")
        master.send("order", order_doc(version))
        wait_for(lambda: (master.last_state() or {}).get("orderId") == "order-1", what="state with the order")

        robot.set_obstacles([core.Obstacle("u-1", "robot_1", (1.5, -0.2, 2.0, 0.2))])
        wait_for(lambda: master.last_state()["errors"], what="blocked edge in state")
        refs = {r["referenceKey"]: r["referenceValue"] for r in master.last_state()["errors"][0]["errorReferences"]}
        assert refs["edgeId"] == "e1" and refs["obstacleId"] == "u-1"

        master.send("order", b"{broken")  # dropped, counted, nothing else lost
        wait_for(lambda: bridge.counters["dropped.invalid_json"] == 1, what="bad payload counted")
        assert len(logs) == 1 and "invalid_json" in logs[0]
        assert master.last_state()["errors"]

        robot.set_obstacles([])  # cleared
        wait_for(lambda: master.last_state()["errors"] == [], what="error withdrawn")

        square = [{"x": 5.0, "y": 5.0}, {"x": 6.0, "y": 5.0}, {"x": 6.0, "y": 6.0}, {"x": 5.0, "y": 6.0}]
        if version == "3.0.0":
            master.send("zoneSet", zone_set_doc("zs-1"))
            wait_for(lambda: bridge.counters["received.zoneSet"] == 1, what="zone set received")
            master.send("instantActions", actions_doc(version, ("enableZoneSet", {"zoneSetId": "zs-1"})))
            wait_for(lambda: areas_seen and areas_seen[-1], what="blocked zone")
            assert [a.key for a in areas_seen[-1].values()] == ["zs-1/z-blocked"]
            master.send("instantActions", actions_doc(version, ("deleteZoneSet", {"zoneSetId": "zs-1"})))
        else:
            master.send("instantActions", actions_doc(version, (core.BLOCK_ACTION, {"areaId": "d", "vertices": square})))
            wait_for(lambda: areas_seen and areas_seen[-1], what="blocked area")
            assert [a.key for a in areas_seen[-1].values()] == ["area/d"]
            master.send("instantActions", actions_doc(version, (core.UNBLOCK_ACTION, {"areaId": "d"})))
        wait_for(lambda: areas_seen[-1] == {}, what="area withdrawn")
    finally:
        robot.stop()
    wait_for(lambda: any(t == "connection" and d["connectionState"] == "OFFLINE" for t, d in master.messages),
             what="OFFLINE connection")
    master.stop()
    sent = [(t, d) for t, d in master.messages if t in ("state", "connection")]
    assert len(sent) >= 5
    for topic, doc in sent:
        assert doc["version"] == version
        assert not schemas.errors(version, topic, doc), (topic, doc)
