"""Copies never outlive the original (issue 15, item 2): a property test (hypothesis) over random
delays, outages and restarts.

Three robots, each the real pure SharingHandler plus the real CoatyBridgeClient, share one fake
clock; the clients' MQTT transport is replaced by an in-memory network (QoS 0: a message is
delivered within MAX_TRANSIT or never). robot_0 shares one obstacle with a deadline of D s, so
the original expires at T0 + D; each update by robot_0 marks a cell, an observation that renews
the lease (issue 12), so the original then expires D s after it. Random steps: time passes,
robot_0 updates it, a robot loses its
broker for a while (its updates wait in the offline queue), a robot restarts (empty handler, new
agent, Discover -> Resolves made from its peers' lists), Discovers are answered from lists of
any age. After every step, every robot that holds the obstacle must expire it no later than
the original's lease + 1 s.
"""
from types import SimpleNamespace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coaty_bridge.client import BridgeConfig, CoatyBridgeClient

from handler_link import to_obstacle, to_update  # (puts sharing_handler_py on the path)
from sharing_handler_py.logic import SharingHandler  # noqa: E402
from sharing_handler_py.validation import Geometry, Obstacle, Rectangle  # noqa: E402

GRID = Geometry(0.05, -5.0, -2.5, 200, 100)
DURATION = 60
MAX_TRANSIT = 0.05   # s, one MQTT hop on a LAN; the bound below allows for a chain of them
BOUND = 1.0          # s a copy may outlive the original (the requirement)
NAMES = ("robot_0", "robot_1", "robot_2")


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


class Network:
    """Messages in flight; deliver() hands them to every other robot's client."""

    def __init__(self):
        self.in_flight = []
        self.robots = {}

    def deliver(self, clock, transit):
        """Everything in flight arrives `transit` (<= MAX_TRANSIT) s later; the answers it
        causes (Resolves to a Discover) follow in further rounds, each with the same transit.
        Nothing stays in flight while time passes otherwise: QoS 0 over TCP delivers at once
        or never."""
        while self.in_flight:
            clock.now += transit
            batch, self.in_flight = self.in_flight, []
            for sender, topic, payload in batch:
                for robot in list(self.robots.values()):
                    if robot.client.identity_id != sender and robot.client.connected:
                        robot.client.handle(topic, payload)


class FakeMqtt:
    def __init__(self, network, owner):
        self.network, self.owner = network, owner

    def publish(self, topic, payload, qos=0):
        self.network.in_flight.append((self.owner(), topic, payload))
        return SimpleNamespace(rc=0)

    # The network hands every message to every robot; a Discover's subscription to its own Resolves
    # changes nothing here.
    def subscribe(self, topic, qos=0):
        return 0, 1

    def unsubscribe(self, topic):
        return 0, 1


class Robot:
    """Handler + bridge client, wired as the two nodes wire them (list -> Discover answers)."""

    def __init__(self, name, clock, network):
        self.name, self.clock, self.network = name, clock, network
        self.handler = SharingHandler(name, clock, DURATION, on_to_layer=lambda o: None,
                                      on_to_fleet=self._to_fleet, on_expired=lambda u: None,
                                      geometry=GRID, on_change=self._list_changed)
        self.client = CoatyBridgeClient(BridgeConfig(name), self._from_fleet, clock=clock)
        self.client._mqtt = FakeMqtt(network, lambda: self.client.identity_id)
        network.robots[name] = self
        self.connect()

    def _to_fleet(self, obstacle):
        self.client.publish_obstacle(to_update(obstacle))

    def _from_fleet(self, update, topic):
        self.handler.on_external(to_obstacle(update))

    def _list_changed(self):
        # the handler publishes its list at `now`; the bridge gets it at once
        self.client.set_current_obstacles([to_update(h.to_obstacle()) for h in self.handler.obstacles()],
                                          as_of=self.clock())

    def connect(self):
        self.client._connected = True
        self.client._flush_queue()
        self.client._discover_obstacles()

    def disconnect(self):
        self.client._connected = False

    def expiry(self, uuid):
        held = self.handler.get(uuid)
        return None if held is None else self.clock() + held.remaining


STEPS = st.lists(st.one_of(
    st.tuples(st.just("wait"), st.floats(0.0, 25.0)),
    st.tuples(st.just("deliver"), st.floats(0.0, MAX_TRANSIT)),
    st.tuples(st.just("update"), st.just(0)),
    st.tuples(st.just("outage"), st.integers(0, 2)),
    st.tuples(st.just("heal"), st.integers(0, 2)),
    st.tuples(st.just("restart"), st.integers(0, 2)),
    st.tuples(st.just("discover"), st.integers(0, 2)),
), min_size=1, max_size=30)


@settings(max_examples=300, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(steps=STEPS, first_wait=st.floats(0.0, 30.0))
def test_no_copy_outlives_the_original_by_more_than_a_second(steps, first_wait):
    clock, network = Clock(), Network()
    robots = [Robot(name, clock, network) for name in NAMES]
    network.deliver(clock, 0.0)
    clock.now += first_wait
    shared = robots[0].handler.add_manual([0.0, 0.0, 0.5, 0.5])
    original_expiry = clock.now + DURATION
    uuid = shared.uuid
    network.deliver(clock, 0.01)

    def check(after):
        for robot in robots:
            expiry = robot.expiry(uuid)
            if expiry is not None:
                assert expiry <= original_expiry + BOUND, (
                    "%s keeps %s until %.3f, the original expires at %.3f (after %s)"
                    % (robot.name, uuid, expiry, original_expiry, after))

    for step, arg in steps:
        if step == "wait":
            network.deliver(clock, 0.0)
            clock.now += arg
            for robot in robots:
                robot.handler.expire()
        elif step == "deliver":
            network.deliver(clock, arg)
        elif step == "update" and uuid in robots[0].handler:
            sent = robots[0].handler.on_internal_update(Obstacle(
                uuid=uuid, marked=(2105 + len(steps),), cleared=(), deadline=DURATION,
                rectangle=Rectangle(0.0, 0.0, 0.5, 0.5), source="robot_0", geometry=GRID, version=1,
                frame_id="", stamp=clock.now))
            if sent is not None:  # a renewal: the original lives DURATION from now
                assert sent.deadline == DURATION
                original_expiry = clock.now + DURATION
        elif step == "outage":
            robots[arg].disconnect()
        elif step == "heal" and not robots[arg].client.connected:
            robots[arg].connect()
        elif step == "restart":
            network.robots.pop(robots[arg].name)
            robots[arg] = Robot(NAMES[arg], clock, network)
        elif step == "discover" and robots[arg].client.connected:
            robots[arg].client._discover_obstacles()
        check("%s %r" % (step, arg))
    for robot in robots:
        if not robot.client.connected:
            robot.connect()
    network.deliver(clock, MAX_TRANSIT)
    check("healing everything")
    clock.now = original_expiry + BOUND
    for robot in robots:
        robot.handler.expire()
        assert uuid not in robot.handler, robot.name


def test_the_property_fails_without_aging():
    """The property test can fail: with Resolves made from an unaged list it does."""
    import coaty_bridge.lifetimes as lifetimes
    original = lifetimes.aged
    lifetimes.aged = lambda update, elapsed: update
    try:
        with pytest.raises(AssertionError, match="the original expires"):
            test_no_copy_outlives_the_original_by_more_than_a_second()
    finally:
        lifetimes.aged = original
