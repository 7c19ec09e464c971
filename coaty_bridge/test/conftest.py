"""Shared fixtures of the coaty_bridge tests. The pure modules are imported from
src/ so the pure and broker tests run without a built workspace."""
import os
import sys
import time
import uuid as uuidlib

import pytest

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
if SRC not in sys.path:
    sys.path.insert(0, SRC)


def pytest_configure(config):
    config.addinivalue_line("markers", "broker: needs /usr/sbin/mosquitto (each test starts its own)")
    config.addinivalue_line("markers", "npm: installs @coaty/core from the npm registry and runs node")
    config.addinivalue_line("markers", "ros: starts a private rosmaster and the coaty_bridge node")


@pytest.fixture
def make_update():
    """Factory for valid ObstacleUpdates; keyword arguments override fields."""
    from coaty_bridge.codec import ObstacleUpdate

    def make(**fields):
        values = dict(uuid=str(uuidlib.uuid4()), source="robot_0", version=1, stamp=1700000000.5,
                      frame_id="map", deadline=60, rectangle=(1.0, 2.0, 3.5, 4.0), resolution=0.05,
                      origin_x=-10.0, origin_y=-20.0, size_x=2000, size_y=2000,
                      marked=(2001000, 2001001, 2003002), cleared=(2000999,))
        values.update(fields)
        return ObstacleUpdate(**values)
    return make


@pytest.fixture
def wait_for():
    def wait(predicate, timeout=5.0, what="condition"):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return
            time.sleep(0.01)
        raise AssertionError("timed out after %.1f s waiting for %s" % (timeout, what))
    return wait


@pytest.fixture
def broker():
    from coaty_bridge.broker import Broker
    if not os.access("/usr/sbin/mosquitto", os.X_OK):
        pytest.skip("mosquitto is not installed (/usr/sbin/mosquitto)")
    with Broker() as running:
        yield running


@pytest.fixture
def make_client(broker):
    """Factory for started CoatyBridgeClients on the test broker; all are stopped after."""
    from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
    clients = []

    def make(robot_name, received=None, start=True, **config):
        config.setdefault("broker_url", broker.url)
        sink = received if received is not None else []
        client = CoatyBridgeClient(BridgeConfig(robot_name, **config), lambda u, t: sink.append(u))
        client.received_updates = sink
        clients.append(client)
        if start:
            client.start()
        return client
    yield make
    for client in clients:
        client.stop(timeout=0.5)


class Observer:
    """A plain paho client that records every message on the broker and can publish."""

    def __init__(self, url):
        import paho.mqtt.client as mqtt
        from coaty_bridge.client import _make_paho_client, parse_broker_url
        address = parse_broker_url(url)
        self.messages = []
        self._client = _make_paho_client("observer-" + uuidlib.uuid4().hex[:8])
        self._client.on_message = lambda c, u, m: self.messages.append((m.topic, bytes(m.payload)))
        subscribed = []
        self._client.on_subscribe = lambda *a: subscribed.append(True)
        self._client.connect(address.host, address.port)
        self._client.subscribe("#")
        self._client.loop_start()
        deadline = time.monotonic() + 5
        while not subscribed and time.monotonic() < deadline:
            time.sleep(0.01)
        assert subscribed, "observer could not subscribe"
        self._mqtt = mqtt

    def publish(self, topic, payload):
        self._client.publish(topic, payload).wait_for_publish(2)

    def on(self, fragment):
        """(topic, decoded JSON) of every message whose topic contains ``fragment``."""
        import json
        found = []
        for topic, payload in list(self.messages):
            if fragment in topic:
                try:
                    found.append((topic, json.loads(payload)))
                except ValueError:
                    found.append((topic, payload))
        return found

    def close(self):
        self._client.disconnect()
        self._client.loop_stop()


@pytest.fixture
def observer(broker):
    obs = Observer(broker.url)
    yield obs
    obs.close()
