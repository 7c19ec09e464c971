"""Partitions and restarts on a real mosquitto (issue 15, item 4).

Each robot is the real SharingHandler wired to the real CoatyBridgeClient as the two nodes wire
them (to_fleet -> Advertise, fleet -> on_external, list -> Discover answers), on the wall clock.
robot_1 talks to the broker through a TCP proxy the test controls.

Bound: after the link (or the broker, or a robot) is back, the lists are equal once the client
has reconnected (at most ~reconnect_max_delay, here 1 s) and the Discover round trip is done
(milliseconds); the test waits for the condition up to CONVERGE s.
"""
import functools
import threading
import time

import pytest

from coaty_bridge.broker import Broker
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.codec import ObstacleUpdate
from polling import wait_until
from tcp_proxy import TcpProxy

from test_lifetimes_property import to_obstacle, to_update  # noqa: E402

from sharing_handler_py.logic import SharingHandler
from sharing_handler_py.validation import Geometry, Obstacle, Rectangle

pytestmark = pytest.mark.broker
GRID = Geometry(0.05, 0.0, 0.0, 100, 100)
RECONNECT_MAX = 1.0
CONVERGE = RECONNECT_MAX + 9.0   # generous: a condition is waited for, not a time


wait_for = functools.partial(wait_until, timeout=CONVERGE)


class LiveRobot:
    """One robot: handler + bridge client on a real broker, an expiry ticker."""

    def __init__(self, name, url, duration=60):
        self.name = name
        self.lock = threading.RLock()
        self.handler = SharingHandler(name, time.monotonic, duration, on_to_layer=lambda o: None,
                                      on_to_fleet=self._to_fleet, on_expired=lambda u: None,
                                      geometry=GRID, on_change=self._list_changed)
        self.client = CoatyBridgeClient(BridgeConfig(name, broker_url=url, reconnect_min_delay=0.1,
                                                     reconnect_max_delay=RECONNECT_MAX, keepalive=5),
                                        self._from_fleet)
        self._running = True
        self._ticker = threading.Thread(target=self._tick, daemon=True)
        self._ticker.start()
        self.client.start()

    def _to_fleet(self, obstacle):
        self.client.publish_obstacle(to_update(obstacle))

    def _from_fleet(self, update, topic):
        with self.lock:
            self.handler.on_external(to_obstacle(update))

    def _list_changed(self):
        # as the node does: an emptied obstacle is not offered as a full state (no cells)
        self.client.set_current_obstacles([to_update(h.to_obstacle()) for h in self.handler.obstacles() if h.cells])

    def _tick(self):
        while self._running:
            with self.lock:
                self.handler.expire()
            time.sleep(0.05)

    def share(self, rect, deadline=0):
        with self.lock:
            return self.handler.add_manual(rect, deadline=deadline)

    def update(self, uuid, marked=(), cleared=()):
        with self.lock:
            held = self.handler.get(uuid)
            return self.handler.on_internal_update(Obstacle(
                uuid=uuid, marked=tuple(marked), cleared=tuple(cleared), deadline=held.deadline,
                rectangle=held.rectangle, source=self.name, geometry=GRID, version=held.version + 1,
                stamp=time.time()))

    def state(self):
        with self.lock:
            return [(h.uuid, h.source, h.cells) for h in self.handler.obstacles()]

    def stop(self):
        self._running = False
        self.client.stop(timeout=0.5)


@pytest.fixture
def fleet():
    made = []

    def make(*args, **kwargs):
        robot = LiveRobot(*args, **kwargs)
        made.append(robot)
        return robot
    yield make
    for robot in made:
        robot.stop()


def converged(a, b):
    return a.state() == b.state()


def test_partition_heals_and_lists_converge_without_resurrecting_cleared_cells(fleet):
    with Broker() as broker:
        proxy = TcpProxy(broker.port)
        try:
            r0 = fleet("robot_0", broker.url)
            r1 = fleet("robot_1", proxy.url)
            wait_for(lambda: r0.client.subscribed and r1.client.subscribed, "both connected and subscribed")
            x = r0.share([0.0, 0.0, 0.5, 0.5])
            wait_for(lambda: converged(r0, r1) and r1.state(), "x on both")
            cleared_cell, remarked_cell = x.marked[:2]

            proxy.cut()
            wait_for(lambda: not r1.client.connected, "robot_1 cut off")
            y = r0.share([2.0, 2.0, 2.5, 2.5])                        # a new share
            r0.update(x.uuid, cleared=(cleared_cell, remarked_cell))  # a clear ...
            r0.update(x.uuid, marked=(remarked_cell,))                # ... and an update marking one again
            z = r0.share([3.5, 3.5, 4.0, 4.0])                        # beyond merge_distance of y
            r0.update(z.uuid, cleared=z.marked)                       # z emptied entirely
            assert len(r1.state()) == 1, "robot_1 must not have heard anything while cut off"

            proxy.heal()
            wait_for(lambda: converged(r0, r1), "lists equal after the partition healed")
            held = dict((u, cells) for u, _, cells in r1.state())
            # z, every cell of it cleared, is listed by neither robot (issue 26: evidence ends an obstacle)
            assert set(held) == {x.uuid, y.uuid}
            assert cleared_cell not in held[x.uuid] and remarked_cell in held[x.uuid]
            assert r1.handler.get(z.uuid).cells == () and r0.handler.get(z.uuid).cells == ()  # held until its lease ends
            assert r1.client.counters()["reconnects"] >= 1
        finally:
            proxy.close()


def test_broker_restart_with_a_share_in_flight_loses_nothing(fleet):
    with Broker() as first:
        port = first.port
        r0 = fleet("robot_0", first.url)
        r1 = fleet("robot_1", first.url)
        wait_for(lambda: r0.client.subscribed and r1.client.subscribed, "both connected and subscribed")
        x = r0.share([0.0, 0.0, 0.5, 0.5])
        wait_for(lambda: converged(r0, r1) and r1.state(), "x on both")
    # the broker is gone; robot_0 shares and updates meanwhile (queued), then it comes back
    wait_for(lambda: not r0.client.connected and not r1.client.connected, "both notice the broker is gone")
    y = r0.share([2.0, 2.0, 2.5, 2.5])
    r0.update(x.uuid, cleared=x.marked[:1])
    with Broker(port=port):
        wait_for(lambda: converged(r0, r1) and len(r1.state()) == 2, "lists equal after the broker restart")
    held = dict((u, cells) for u, _, cells in r1.state())
    assert y.uuid in held and x.marked[0] not in held[x.uuid] and x.marked[1] in held[x.uuid]


def test_robot_restart_gets_live_obstacles_back_but_not_expired_or_cleared_ones(fleet):
    with Broker() as broker:
        r0 = fleet("robot_0", broker.url)
        r1 = fleet("robot_1", broker.url)
        wait_for(lambda: r0.client.subscribed and r1.client.subscribed, "both connected and subscribed")
        x = r0.share([0.0, 0.0, 0.5, 0.5])
        short = r0.share([2.0, 2.0, 2.5, 2.5], deadline=2)
        w = r1.share([3.5, 3.5, 4.0, 4.0])
        r0.update(x.uuid, cleared=x.marked[:3])
        wait_for(lambda: converged(r0, r1) and len(r1.state()) == 3, "three obstacles on both")
        wait_for(lambda: short.uuid not in dict((u, c) for u, _, c in r0.state())
                 and short.uuid not in dict((u, c) for u, _, c in r1.state()), "the short one expired")

        # robot_1 restarts (new process: empty handler, no tombstones); robot_0 keeps running
        r1.stop()
        r1 = fleet("robot_1", broker.url)
        wait_for(lambda: converged(r0, r1) and len(r1.state()) == 2, "robot_1 back with the live obstacles")
        held = dict((u, cells) for u, _, cells in r1.state())
        assert short.uuid not in held                       # expired: not resurrected
        assert not set(x.marked[:3]) & set(held[x.uuid])    # cleared cells: not resurrected
        assert w.uuid in held                               # its own obstacle, given back by robot_0

        # and the creator restarts: robot_1 gives robot_0 its own obstacle back
        r0.stop()
        r0 = fleet("robot_0", broker.url)
        wait_for(lambda: converged(r0, r1) and len(r0.state()) == 2, "robot_0 back with its own obstacle")
