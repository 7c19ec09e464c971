"""A minimal VDA 5050 master control for make demo (issue 30): a paho client on the master
control's broker that sends one robot an order and the instant actions fleetBlockArea /
fleetUnblockArea (vda5050_bridge's 2.x way of declaring an area blocked), and keeps what it sent
and what the robot's vda5050_bridge answered (state, connection) as a short log.

Written from the standard's topic and field names only (VDA 5050 2.1 §6), not from the
bridge's code: it is the outside party.

    mc = MasterControl(host, port, "uagv/v2/fleet/robot_0", "2.1.0", "fleet", "robot_0")
    mc.wait_for(lambda: mc.last_state(), 10.0, "the first state")
    mc.send_order("demo-order", [("orange", 13.8, 8.4), ("purple", 11.3, 7.3), ...])
    mc.wait_for(lambda: blocked_edges(mc.last_state()), 10.0, "a blocked edge")
"""
import datetime
import json
import threading
import time


class MasterControlError(Exception):
    """The robot did not answer as expected in time."""


def blocked_edges(state):
    """{edgeId: obstacleId} of the errors of a state that reference an edge and an obstacle."""
    out = {}
    for err in (state or {}).get("errors", []):
        refs = {r.get("referenceKey"): r.get("referenceValue") for r in err.get("errorReferences", [])}
        if "edgeId" in refs:
            out[refs["edgeId"]] = refs.get("obstacleId", "?")
    return out


class MasterControl:
    def __init__(self, host, port, prefix, version, manufacturer, serial_number, client_id="demo_master_control"):
        import paho.mqtt.client as mqtt
        self.prefix, self.version = prefix, version
        self.manufacturer, self.serial_number = manufacturer, serial_number
        self.lock = threading.Lock()
        self.received = []    # (wall time, topic, doc)
        self.log = []         # (wall time, direction, topic, summary)
        self.header_id = 0
        self.start = time.time()
        self.ready = threading.Event()
        self.client = mqtt.Client(client_id=client_id, clean_session=True)
        self.client.on_connect = self._on_connect
        self.client.on_message = self._on_message
        self.client.connect(host, port, keepalive=30)
        self.client.loop_start()

    def _on_connect(self, client, _userdata, _flags, rc):
        if rc == 0:
            client.subscribe([(self.prefix + "/state", 0), (self.prefix + "/connection", 1)])
            self.ready.set()

    def _on_message(self, _client, _userdata, msg):
        now = time.time()
        topic = msg.topic[len(self.prefix) + 1:]
        try:
            doc = json.loads(msg.payload)
        except ValueError:
            doc = {"unparsable": msg.payload[:80].decode(errors="replace")}
        with self.lock:
            previous = [d for _t, tp, d in self.received if tp == topic]
            self.received.append((now, topic, doc))
            if topic == "connection":
                self.log.append((now, "robot -> MC", topic, "connectionState %s" % doc.get("connectionState")))
            elif topic == "state":
                errors = blocked_edges(doc)
                before = blocked_edges(previous[-1]) if previous else None
                if not previous or errors != before or doc.get("orderId") != previous[-1].get("orderId"):
                    self.log.append((now, "robot -> MC", topic, _state_summary(doc)))

    def header(self):
        self.header_id += 1
        stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
        return {"headerId": self.header_id, "timestamp": stamp, "version": self.version,
                "manufacturer": self.manufacturer, "serialNumber": self.serial_number}

    def _send(self, topic, doc, summary):
        with self.lock:
            self.log.append((time.time(), "MC -> robot", topic, summary))
        self.client.publish(self.prefix + "/" + topic, json.dumps(doc), qos=0)

    def send_order(self, order_id, nodes):
        """nodes: [(nodeId, x, y)]; edges join consecutive nodes, edgeId "<a>-<b>"."""
        doc = self.header()
        doc.update({"orderId": order_id, "orderUpdateId": 0, "nodes": [], "edges": []})
        for k, (nid, x, y) in enumerate(nodes):
            doc["nodes"].append({"nodeId": nid, "sequenceId": 2 * k, "released": True, "actions": [],
                                 "nodePosition": {"x": x, "y": y, "mapId": "map"}})
            if k:
                prev = nodes[k - 1][0]
                doc["edges"].append({"edgeId": "%s-%s" % (prev, nid), "sequenceId": 2 * k - 1, "released": True,
                                     "startNodeId": prev, "endNodeId": nid, "actions": []})
        self._send("order", doc, "order %s: %s" % (order_id, " -> ".join(n[0] for n in nodes)))
        return doc

    def _instant(self, action_type, params, summary):
        doc = self.header()
        doc["actions"] = [{"actionId": "%s-%d" % (action_type, self.header_id), "actionType": action_type,
                           "blockingType": "NONE",
                           "actionParameters": [{"key": k, "value": v} for k, v in params.items()]}]
        self._send("instantActions", doc, summary)
        return doc

    def block_area(self, area_id, vertices):
        return self._instant("fleetBlockArea", {"areaId": area_id, "vertices": [{"x": x, "y": y} for x, y in vertices]},
                             "instantActions fleetBlockArea areaId=%s vertices=%s" % (
                                 area_id, " ".join("(%.1f, %.1f)" % v for v in vertices)))

    def unblock_area(self, area_id):
        return self._instant("fleetUnblockArea", {"areaId": area_id},
                             "instantActions fleetUnblockArea areaId=%s" % area_id)

    def note(self, text):
        """A line of what the fleet did (not MQTT), for the log."""
        with self.lock:
            self.log.append((time.time(), "fleet", "", text))

    def last_state(self):
        with self.lock:
            states = [d for _t, tp, d in self.received if tp == "state"]
        return states[-1] if states else None

    def wait_for(self, predicate, timeout, what):
        end = time.time() + timeout
        while time.time() < end:
            value = predicate()
            if value:
                return value
            time.sleep(0.02)
        raise MasterControlError("master control: no %s within %.0f s" % (what, timeout))

    def lines(self):
        """The log as text lines, wall seconds from the start."""
        with self.lock:
            return ["%6.2f s  %-11s  %-15s %s" % (t - self.start, d, topic, text) for t, d, topic, text in self.log]

    def stop(self):
        self.client.loop_stop()
        self.client.disconnect()


def _state_summary(doc):
    errors = doc.get("errors", [])
    parts = ["state orderId=%s" % (doc.get("orderId") or "''")]
    if not errors:
        parts.append("errors=[]")
    for err in errors:
        refs = {r.get("referenceKey"): r.get("referenceValue") for r in err.get("errorReferences", [])}
        parts.append("error %s/%s edgeId=%s nodeId=%s obstacleId=%s obstacleSource=%s obstacleRectangle=%s" % (
            err.get("errorType"), err.get("errorLevel"), refs.get("edgeId", "-"), refs.get("nodeId", "-"),
            str(refs.get("obstacleId", "-"))[:8], refs.get("obstacleSource", "-"), refs.get("obstacleRectangle", "-")))
    return "; ".join(parts)
