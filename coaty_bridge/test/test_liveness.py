"""Truthful liveness (issue 27, attack 6) through a real mosquitto and real bridge clients, and
at 100 robots through an in-process stand-in broker (issue 29: heartbeat bytes per robot).

Three robots (bridge client + handler each, as in test_peer_authority.py), each behind its own
TCP proxy the test controls. The clients get a settable clock and send heartbeats only when the
test says so (``heartbeats=False``), so nothing sleeps: the test advances the clock one heartbeat
interval at a time and waits for the heartbeats that can arrive to have arrived.

- a silent stall (the proxy stops forwarding, the TCP connection stays open, paho still says
  connected): the stalled robot reports ERROR "stalled: own heartbeat not echoed", the others
  WARN "partition: ... robot_1 silent", within liveness_timeout + one interval (<= 5 s);
- a deaf receiver (only broker -> robot stalled): the others WARN "deaf receiver: robot_1";
- a partition (the proxy cuts the connection): the others WARN "partition";
after each, once the link is back, every robot is OK again, the good obstacles are unchanged and
a fresh obstacle reaches every robot. These robots beat to their peers each 1 s
(``peer_heartbeat_interval`` 1.0); the automatic interval is tested in the simulated fleets below.
"""
import json
import random

import paho.mqtt.client as mqtt
import pytest

from coaty_bridge import liveness
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from tcp_proxy import TcpProxy

import test_peer_authority
from test_peer_authority import GOOD, _fresh_obstacle_still_reaches_everyone


NAMES = ("robot_0", "robot_1", "robot_2")
TIMEOUT = 3.0


class Robot(test_peer_authority.Robot):
    def __init__(self, name, url, clock):
        super().__init__(name, url, clock)
        config = BridgeConfig(name, broker_url=url, heartbeat_interval=1.0, liveness_timeout=TIMEOUT,
                              peer_heartbeat_interval=1.0, reconnect_min_delay=0.1, reconnect_max_delay=0.5)
        self.client = CoatyBridgeClient(config, self._from_fleet, clock=clock, heartbeats=False,
                                        on_footprint=lambda f, t: None)

    def status(self):
        return self.client.liveness.status()


def _subscribed(robot, wait_for):
    """Waits until the robot is subscribed (CoatyBridgeClient.subscribed) and hears its own heartbeats."""
    wait_for(lambda: robot.client.subscribed, what="%s subscribed" % robot.name)
    echoed = robot.client.liveness.values()["heartbeats_echoed"]

    def echo():
        if robot.client.liveness.values()["heartbeats_echoed"] > echoed:
            return True
        robot.client.heartbeat()
        return False
    wait_for(echo, what="%s hears its own heartbeat" % robot.name)


@pytest.fixture
def net(broker, wait_for):
    clock = test_peer_authority.Clock()
    proxies = {name: TcpProxy(broker.port) for name in NAMES}
    robots = []
    for name in NAMES:
        robot = Robot(name, proxies[name].url, clock)
        robots.append(robot)
        robot.client.start()
        _subscribed(robot, wait_for)

    class Net:
        pass
    n = Net()
    n.clock, n.proxies, n.robots = clock, proxies, robots
    n.by_name = {r.name: r for r in robots}

    def beat(live=NAMES):
        """Advances the clock one interval; every robot sends a heartbeat; waits until the live
        robots have their own echo and each other's heartbeat of this instant."""
        clock.now += 1.0
        for robot in robots:
            robot.client.heartbeat()
        for name in live:
            lv = n.by_name[name].client.liveness
            wait_for(lambda: lv.values()["heartbeats_echoed"] == lv.values()["heartbeats_sent"],
                     what="%s's own heartbeat echoed" % name)
            for other in live:
                if other != name:
                    wait_for(lambda: lv._peers.get(other, (None,))[0] == clock.now,
                             what="%s hears %s" % (name, other))
    n.beat = beat
    yield n
    for robot in robots:
        robot.client.stop(timeout=0.5)
    for proxy in proxies.values():
        proxy.close()


def _all_ok(net, wait_for):
    # two rounds: the second heartbeat lists the peers heard in the first
    for _ in range(2):
        net.beat()
    for robot in net.robots:
        assert robot.status() == (liveness.OK, ""), robot.name


def _share_good(net, wait_for):
    uuids = [net.by_name[name].add(rect) for name, rect in GOOD]
    for robot in net.robots:
        wait_for(lambda: set(uuids) <= set(robot.held()), what="%s holds the good obstacles" % robot.name)
    return {r.name: r.held() for r in net.robots}


def _after(net, wait_for, before, x):
    for robot in net.robots:
        now = robot.held()
        assert {u: now[u] for u in before[robot.name]} == before[robot.name], "a good obstacle lost or changed"
    _fresh_obstacle_still_reaches_everyone(net, wait_for, x)


@pytest.mark.broker
def test_attack_6_a_silent_stall_is_an_error_within_5_s(net, wait_for):
    _all_ok(net, wait_for)
    before = _share_good(net, wait_for)
    net.proxies["robot_1"].stall()
    seen = {}
    for step in range(1, 6):   # s after the stall
        net.beat(live=("robot_0", "robot_2"))
        assert net.by_name["robot_1"].client.connected       # what the old diagnostics said
        for robot in net.robots:
            level, reason = robot.status()
            if level != liveness.OK and robot.name not in seen:
                seen[robot.name] = (step, level, reason)
    assert set(seen) == set(NAMES)
    assert all(step <= 5 for step, _l, _r in seen.values())
    # 5 s after the stall: the stalled robot knows it is stalled, the others miss it
    level, reason = net.by_name["robot_1"].status()
    assert level == liveness.ERROR and "stalled: own heartbeat not echoed" in reason, reason
    for name in ("robot_0", "robot_2"):
        level, reason = net.by_name[name].status()
        assert level == liveness.WARN and "partition" in reason and "robot_1 silent" in reason, reason
    net.proxies["robot_1"].resume()
    _all_ok(net, wait_for)
    _after(net, wait_for, before, 4.0)


@pytest.mark.broker
def test_attack_6_a_deaf_receiver_is_named_by_its_peers(net, wait_for):
    _all_ok(net, wait_for)
    before = _share_good(net, wait_for)
    net.proxies["robot_1"].stall(up=False, down=True)    # robot_1 sends but hears nothing
    for _ in range(5):
        net.beat(live=("robot_0", "robot_2"))
    level, reason = net.by_name["robot_1"].status()
    assert level == liveness.ERROR and "own heartbeat not echoed" in reason
    for name in ("robot_0", "robot_2"):
        level, reason = net.by_name[name].status()
        assert level == liveness.WARN and "deaf receiver: robot_1 does not hear us" in reason, reason
    net.proxies["robot_1"].resume()
    _all_ok(net, wait_for)
    _after(net, wait_for, before, 4.5)


@pytest.mark.broker
def test_attack_6_a_partition_is_a_warning_on_the_others(net, wait_for):
    _all_ok(net, wait_for)
    before = _share_good(net, wait_for)
    net.proxies["robot_1"].cut()
    wait_for(lambda: not net.by_name["robot_1"].client.connected, what="robot_1 loses the broker")
    for _ in range(4):
        net.beat(live=("robot_0", "robot_2"))
    for name in ("robot_0", "robot_2"):
        level, reason = net.by_name[name].status()
        assert level == liveness.WARN and "robot_1 silent" in reason, reason
    net.proxies["robot_1"].heal()
    _subscribed(net.by_name["robot_1"], wait_for)
    _all_ok(net, wait_for)
    _after(net, wait_for, before, 5.0)


def test_liveness_rules_with_an_injected_clock():
    now = [0.0]
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0, known_robots=("robot_0", "robot_1"),
                           peer_interval=1.0)
    assert lv.status()[0] == liveness.OK
    now[0] = 4.0
    level, reason = lv.status()            # nothing sent, the known robot never heard
    assert level == liveness.ERROR and "robot_1 never heard" in reason
    seq, peer = lv.next_heartbeat()
    assert peer == {"interval": 1.0, "heard": 0, "misses": ["robot_1"]}   # the first one is for the peers
    lv.own_echo(seq)
    lv.peer("robot_1", 1.0, misses=[], heard=1)
    assert lv.status() == (liveness.OK, "")
    lv.next_heartbeat()
    now[0] = 7.5
    assert lv.status()[0] == liveness.ERROR
    lv.forget("robot_1")
    assert "robot_1" not in lv.status()[1]


def test_peers_are_judged_by_the_interval_they_announce():
    now = [0.0]
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0)
    lv.peer("robot_1", 1.0)
    lv.peer("robot_2", 100.0)
    seq, _peer = lv.next_heartbeat()
    lv.own_echo(seq)
    now[0] = 3.5
    level, reason = lv.status()
    assert level == liveness.WARN and "robot_1 silent for 3.5 s" in reason and "robot_2" not in reason, reason
    now[0] = 299.0                  # 3 of robot_2's 100 s intervals: still fine
    lv.peer("robot_1", 1.0)
    seq, _peer = lv.next_heartbeat()
    lv.own_echo(seq)
    assert lv.status() == (liveness.OK, "")
    now[0] = 300.5
    seq, _peer = lv.next_heartbeat()
    lv.own_echo(seq)
    level, reason = lv.status()
    assert level == liveness.WARN and "robot_2 silent for 300.5 s (beats every 100 s)" in reason, reason
    assert "robot_1 silent" not in reason


def test_a_peer_is_alive_while_heard_within_its_timeout_and_not_after_its_last_will():
    now = [0.0]
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0, heartbeat_interval=1.0)
    assert not lv.alive("robot_1")                     # never heard
    lv.departed("robot_1")                             # a will of a robot never heard changes nothing
    lv.peer("robot_1", 10.0)
    assert lv.alive("robot_1")
    now[0] = 30.0                                      # 3 announced intervals: still alive
    assert lv.alive("robot_1")
    now[0] = 30.5
    assert not lv.alive("robot_1")
    lv.peer("robot_1", 10.0)
    lv.departed("robot_1")                             # the broker lost it
    assert not lv.alive("robot_1")
    assert "robot_1" not in lv.status()[1]             # the partition verdict still follows its heartbeats
    lv.peer("robot_1", 10.0)                           # back
    assert lv.alive("robot_1")
    lv.forget("robot_1")                               # a leaving heartbeat
    assert not lv.alive("robot_1") and not lv.alive("robot_0")


def test_the_automatic_peer_interval_grows_with_the_peers_known():
    now = [0.0]
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0, heartbeat_interval=1.0, rng=random.Random(3))
    assert lv.peer_interval() == 1.0                       # nobody known: the floor
    lv.peer("robot_1", 1.0)
    assert lv.peer_interval() == liveness.AUTO_SECONDS_PER_PEER
    for i in range(2, 100):
        lv.peer("robot_%d" % i, 1.0)
    assert lv.peer_interval() == 99 * liveness.AUTO_SECONDS_PER_PEER
    # an echo each tick, a peer heartbeat after a random 0.8..1 of the peer interval it announces
    kinds = []
    for t in range(3000):
        now[0] = float(t)
        seq, peer = lv.next_heartbeat()
        lv.own_echo(seq)
        kinds.append(peer)
    sent = [(t, p) for t, p in enumerate(kinds) if p is not None]
    interval = 99 * liveness.AUTO_SECONDS_PER_PEER
    assert all(p["interval"] == interval for _t, p in sent)
    gaps = [b - a for (a, _p), (b, _q) in zip(sent, sent[1:])]
    assert all(liveness.JITTER * interval - 0.5 <= gap <= interval + 0.5 for gap in gaps), gaps
    assert len(set(gaps)) > 1                   # not in step with robots that started with it
    assert liveness.Liveness("robot_0", lambda: 0.0, peer_interval=5.0).peer_interval() == 5.0


def test_a_peer_that_misses_us_is_deaf_and_legacy_hears_still_count():
    now = [10.0]
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0)
    now[0] = 14.0
    seq, _peer = lv.next_heartbeat()
    lv.own_echo(seq)
    lv.peer("robot_1", 5.0, misses=["robot_0"], heard=3)
    lv.peer("robot_2", 5.0, misses=["robot_7"], heard=3)
    lv.peer("robot_3", hears=["robot_2"])                  # a bridge of the first design, no robot_0
    lv.peer("robot_4", hears=["robot_0", "robot_2"])
    level, reason = lv.status()
    assert (level, reason) == (liveness.WARN, "deaf receiver: robot_1, robot_3 does not hear us"), reason
    # our own path stalled: the peers that miss us are not to blame
    lv.next_heartbeat()
    now[0] = 17.5
    level, reason = lv.status()
    assert level == liveness.ERROR and "deaf" not in reason, reason


def test_misses_name_the_expected_robots_not_heard():
    now = [0.0]
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0, known_robots=("robot_5",), peer_interval=1.0)
    lv.peer("robot_1", 1.0)
    lv.peer("robot_2", 1.0)
    now[0] = 3.5
    lv.peer("robot_2", 1.0)
    _seq, peer = lv.next_heartbeat()
    assert peer == {"interval": 1.0, "heard": 1, "misses": ["robot_1", "robot_5"]}
    for i in range(300):
        lv.peer("lost_%03d" % i, 1.0)
    now[0] = 10.0
    _seq, peer = lv.next_heartbeat()
    assert len(peer["misses"]) == liveness.MAX_MISSES_SENT and peer["heard"] == 0


# ---------------------------------------------------------------- simulated fleets (issue 29)

class FakeFleet:
    """N real CoatyBridgeClients (not connected) on one simulated clock, their publications routed
    by an in-process broker that matches each client's real subscription list (paho's
    topic_matches_sub): the real encoders, decoders and subscriptions, without sockets. ``cut_up``
    / ``cut_down``: robots whose publications are lost / who receive nothing."""

    def __init__(self, n, seed=1, stagger=0.5, max_deliveries=None, **config):
        self.now = 0.0
        # a design that sends to everyone everything each second fails here, not by the test timeout
        self.deliveries, self.max_deliveries = 0, max_deliveries
        self.rng = random.Random(seed)
        self.clients = []
        self.bytes_in = {}
        self.by_kind = {}
        self.cut_up, self.cut_down = set(), set()
        self._routes = {}
        for i in range(n):
            name = "robot_%03d" % i
            client = CoatyBridgeClient(BridgeConfig(name, heartbeat_interval=1.0, liveness_timeout=3.0, **config),
                                       lambda u, t: None, clock=self, heartbeats=False)
            client._send = (lambda c: lambda topic, payload, queue=True, **_kw: self.publish(c, topic, payload))(client)
            client.start_at = i * stagger
            client.liveness._rng = random.Random(seed * 1000 + i)
            self.clients.append(client)
            self.bytes_in[name] = 0
        self.by_name = {c.config.robot_name: c for c in self.clients}

    def __call__(self):
        return self.now

    def publish(self, sender, topic, payload):
        if sender.config.robot_name in self.cut_up:
            return
        route = self._routes.get(topic)
        if route is None:
            route = self._routes[topic] = [c for c in self.clients if any(
                mqtt.topic_matches_sub(sub, topic)
                for sub in [s for s, _q in c._subscriptions] + sorted(c._area_subscriptions))]
        kind = topic.split("/")[3]
        self.deliveries += len(route)
        if self.max_deliveries is not None and self.deliveries > self.max_deliveries:
            raise AssertionError("more than %d messages delivered by t = %.0f s (last on %s)"
                                 % (self.max_deliveries, self.now, topic))
        for client in route:
            name = client.config.robot_name
            if name in self.cut_down or not client._connected:
                continue
            self.bytes_in[name] += len(payload)
            self.by_kind[kind] = self.by_kind.get(kind, 0) + len(payload)
            client.handle(topic, payload)

    def run(self, until):
        """Advances the clock in 1 s ticks (heartbeat_interval) to ``until``; each robot connects at
        its start time and beats once per tick."""
        while self.now < until:
            self.now += 1.0
            for client in self.rng.sample(self.clients, len(self.clients)):
                if not client._connected and self.now >= client.start_at:
                    client._connected = True
                    client.liveness.reset()
                if client._connected:
                    client.heartbeat()

    def status(self, name):
        return self.by_name[name].liveness.status()


BUDGET_BYTES_PER_MINUTE = 15000


def test_heartbeats_cost_at_most_15_kB_per_robot_per_minute_at_100_robots():
    """Issue 29: the first design (a 1 s heartbeat to every robot listing all robots heard) cost
    each robot 100 x 1.2 kB per s at 100 robots, 2.75 MB per minute."""
    fleet = FakeFleet(100, max_deliveries=400000)
    fleet.run(600)                  # every robot joined (50 s) and knows the others
    before, kinds = dict(fleet.bytes_in), dict(fleet.by_kind)
    busiest, last = 0, dict(before)
    for minute in range(1, 11):     # 10 minutes: a peer heartbeat comes from each robot every 240..297 s
        fleet.run(600 + 60 * minute)
        busiest = max(busiest, max(fleet.bytes_in[name] - last[name] for name in last))
        last = dict(fleet.bytes_in)
    per_minute = {name: (fleet.bytes_in[name] - before[name]) / 10.0 for name in before}
    by_kind = {k: round((v - kinds.get(k, 0)) / 10.0 / 100) for k, v in fleet.by_kind.items()}
    print("heartbeat bytes per robot per minute at 100 robots over 10 min: max %.0f, mean %.0f (busiest single "
          "minute of a robot %d); by kind %s" % (max(per_minute.values()), sum(per_minute.values()) / 100, busiest,
                                                  by_kind))
    assert max(per_minute.values()) <= BUDGET_BYTES_PER_MINUTE, by_kind
    print("messages delivered in 1200 s: %d" % fleet.deliveries)
    assert set(by_kind) == {"CHN:org.fleetsharing.Echo", "CHN:org.fleetsharing.Heartbeat"}, by_kind
    interval = 99 * liveness.AUTO_SECONDS_PER_PEER
    for client in fleet.clients:
        assert client.liveness.status() == (liveness.OK, ""), client.config.robot_name
        values = client.liveness.values()
        assert values["peers_heard"] == 99 and values["peer_heartbeat_interval"] == interval
        # the echo goes to its sender only: nobody else's echo was delivered (nor ignored) here
        assert client.counters().get("ignored", 0) == 0
        assert not any(k.startswith("dropped") for k in client.counters()), client.counters()


def test_a_partition_is_warned_within_3_announced_intervals():
    fleet = FakeFleet(20)
    fleet.run(200)
    interval = 19 * liveness.AUTO_SECONDS_PER_PEER                        # 47.5 s
    assert all(fleet.status(c.config.robot_name) == (liveness.OK, "") for c in fleet.clients)
    cut = fleet.now
    fleet.cut_up.add("robot_007")
    fleet.cut_down.add("robot_007")
    fleet.run(cut + 4)
    assert fleet.status("robot_007")[0] == liveness.OK     # its first lost echo is 3.0 s old: not yet
    fleet.run(cut + 5)          # liveness_timeout + one heartbeat_interval, whatever the fleet size
    level, reason = fleet.status("robot_007")
    assert level == liveness.ERROR and "stalled: own heartbeat not echoed" in reason, reason
    warned = {}
    while fleet.now < cut + 3 * interval + 2:
        fleet.run(fleet.now + 1)
        for client in fleet.clients:
            name = client.config.robot_name
            level, reason = client.liveness.status()
            if name != "robot_007" and name not in warned and level != liveness.OK:
                warned[name] = (fleet.now - cut, level, reason)
    assert set(warned) == {c.config.robot_name for c in fleet.clients} - {"robot_007"}
    for took, level, reason in warned.values():
        assert level == liveness.WARN and "partition: no heartbeat from robot_007 silent" in reason, reason
        assert 2 * interval - 1 <= took <= 3 * interval + 1, took       # its last beat was before the cut


def test_a_deaf_robot_is_named_through_its_misses():
    fleet = FakeFleet(20)
    fleet.run(200)
    interval = 19 * liveness.AUTO_SECONDS_PER_PEER
    cut = fleet.now
    fleet.cut_down.add("robot_007")                 # it sends, but receives nothing
    fleet.run(cut + 3 * interval + interval + 2)    # it misses the others, then says so
    assert fleet.status("robot_007")[0] == liveness.ERROR
    for client in fleet.clients:
        if client.config.robot_name != "robot_007":
            level, reason = client.liveness.status()
            assert (level, reason) == (liveness.WARN, "deaf receiver: robot_007 does not hear us"), reason
    fleet.cut_down.clear()     # back: it hears each peer within an interval, and says so in its next one
    fleet.run(fleet.now + 2 * interval + 2)
    assert all(fleet.status(c.config.robot_name) == (liveness.OK, "") for c in fleet.clients)


def _heartbeat(robot="robot_1", **fields):
    obj = {"objectType": liveness.OBJECT_TYPE, "coreType": "CoatyObject",
           "objectId": "5f0e1c4e-8a57-4f6e-9a8e-0a1b2c3d4e5f", "name": robot, "robot": robot, "seq": 1,
           "interval": 5.0, "heard": 1}
    obj.update(fields)
    return json.dumps({"object": {k: v for k, v in obj.items() if v is not None}}).encode()


def test_bad_heartbeats_are_counted_and_dropped():
    fleet = FakeFleet(2, stagger=0)
    fleet.run(2)
    client = fleet.by_name["robot_000"]
    ns = client.config.namespace
    topic = "coaty/3/%s/CHN:%s/5f0e1c4e-8a57-4f6e-9a8e-0a1b2c3d4e5f" % (ns, liveness.CHANNEL)
    bad = [(_heartbeat(interval="5"), "wrong_type"), (_heartbeat(interval=None), "wrong_type"),
           (_heartbeat(heard=True), "wrong_type"), (_heartbeat(misses="robot_0"), "wrong_type"),
           (_heartbeat(misses=[1]), "wrong_type"), (_heartbeat(interval=0), "out_of_range"),
           (_heartbeat(interval=1e9), "out_of_range"), (_heartbeat(heard=-1), "out_of_range"),
           (_heartbeat(misses=["r%d" % i for i in range(1001)]), "out_of_range"),
           (_heartbeat(interval=None, hears=["r%d" % i for i in range(1001)]), "out_of_range"),
           (_heartbeat(interval=None, hears={"robot_0": 1}), "wrong_type"),
           (_heartbeat(seq="1"), "wrong_type"), (b"[]", "wrong_type")]
    for payload, reason in bad:
        before = client.counters().get("dropped." + reason, 0)
        client.handle(topic, payload)
        assert client.counters().get("dropped." + reason, 0) == before + 1, (payload[:120], client.counters())
    assert "robot_1" not in client.liveness._peers
    # somebody else's echo (we subscribe to our own only) is ignored; a bad own echo is dropped
    client.handle("coaty/3/%s/CHN:%s/5f0e1c4e-8a57-4f6e-9a8e-0a1b2c3d4e5f" % (liveness.echo_namespace(ns),
                                                                            liveness.ECHO_CHANNEL),
                  liveness.echo_payload("5f0e1c4e-8a57-4f6e-9a8e-0a1b2c3d4e5f", 1))
    assert client.counters()["ignored"] == 1
    client.handle(client._echo_topic,
                  b'{"object": {"objectType": "%s", "seq": "x"}}' % liveness.ECHO_OBJECT_TYPE.encode())
    assert client.counters()["dropped.wrong_type"] == 9   # 8 above and this echo
    # a heartbeat of the first design is still taken (a fleet half upgraded)
    client.handle(topic, _heartbeat(interval=None, heard=None, hears=["robot_0"]))
    assert client.counters()["heartbeats_received_legacy"] == 1
    assert client.liveness._peers["robot_1"][1] == liveness.LEGACY_INTERVAL


def test_peer_heartbeat_interval_is_checked():
    with pytest.raises(ValueError, match="peer_heartbeat_interval"):
        BridgeConfig("robot_0", peer_heartbeat_interval=0.5)          # below heartbeat_interval
    with pytest.raises(ValueError, match="peer_heartbeat_interval"):
        BridgeConfig("robot_0", peer_heartbeat_interval="10")
    with pytest.raises(ValueError, match="peer_heartbeat_interval"):
        BridgeConfig("robot_0", peer_heartbeat_interval=-1)
    assert BridgeConfig("robot_0", peer_heartbeat_interval=30).peer_heartbeat_interval == 30


@pytest.mark.broker
def test_the_echo_reaches_its_sender_only(broker, wait_for):
    """Through a real mosquitto: each robot hears its own echoes; the peer hears none of them,
    only the peer heartbeats (the first one, then each peer_heartbeat_interval), and neither does
    a subscriber of every event of the fleet's namespace (coaty/+/<ns>/+/+ and two-way)."""
    clock = test_peer_authority.Clock()
    robots = [Robot(name, broker.url, clock) for name in ("robot_0", "robot_1")]
    heard = {r.name: [] for r in robots}
    ns = robots[0].client.config.namespace
    everything = []
    catch_all = mqtt.Client(client_id="catch-all")
    catch_all.on_message = lambda c, u, m: everything.append(m.topic)
    catch_all.on_connect = lambda c, u, f, rc: c.subscribe([("coaty/+/%s/+/+" % ns, 0), ("coaty/+/%s/+/+/+" % ns, 0)])
    catch_all.connect("127.0.0.1", broker.port)
    catch_all.loop_start()
    for robot in robots:
        client = robot.client
        client.config = BridgeConfig(robot.name, broker_url=broker.url, peer_heartbeat_interval=10.0)
        client.liveness.fixed_peer_interval = 10.0
        handle = client.handle
        client.handle = (lambda name, h: lambda topic, payload: heard[name].append(topic) or h(topic, payload))(
            robot.name, handle)
        client.start()
        _subscribed(robot, wait_for)
    try:
        for _ in range(12):   # after the first peer heartbeat, an idle robot echoes every other tick
            clock.now += 1.0
            for robot in robots:
                robot.client.heartbeat()
                lv = robot.client.liveness
                wait_for(lambda: lv.values()["heartbeats_echoed"] == lv.values()["heartbeats_sent"],
                         what="%s's echoes back" % robot.name)
        for robot, peer in (robots, robots[::-1]):
            own_echo = robot.client._echo_topic
            sent = robot.client.counters().get("echoes_sent", 0)
            assert sent >= 5 and heard[robot.name].count(own_echo) == sent
            assert own_echo not in heard[peer.name]
            assert not any(liveness.ECHO_CHANNEL in t and robot.client.identity_id in t for t in heard[peer.name])
        wait_for(lambda: any(liveness.CHANNEL in t for t in everything), what="the catch-all hears heartbeats")
        assert not any(liveness.ECHO_CHANNEL in t for t in everything)
    finally:
        catch_all.loop_stop()
        catch_all.disconnect()
        for robot in robots:
            robot.client.stop(timeout=0.5)


@pytest.mark.broker
def test_a_robot_that_stops_cleanly_is_not_missed(net, wait_for):
    _all_ok(net, wait_for)
    net.by_name["robot_2"].client.stop(timeout=2.0)
    wait_for(lambda: "robot_2" not in net.by_name["robot_0"].client.liveness._peers, what="robot_2 forgotten")
    for _ in range(4):
        net.beat(live=("robot_0", "robot_1"))
    assert net.by_name["robot_0"].status() == (liveness.OK, "")
    with pytest.raises(ValueError, match="liveness_timeout"):
        BridgeConfig("robot_0", heartbeat_interval=2.0, liveness_timeout=3.0)


def test_a_robot_joining_a_large_fleet_listens_first_and_announces_a_fitting_interval():
    """Issue 29, the 1,000-robot run: robots that beat to every robot each second until they had heard
    them all made 10^6 deliveries a second when 1,000 joined. A newcomer listens first; one heartbeat of
    a peer saying it hears 999 robots is enough to announce 3 s per peer."""
    now = [100.0]
    newcomer = liveness.Liveness("robot_1000", lambda: now[0], rng=random.Random(3))
    seq, fields = newcomer.next_heartbeat()
    assert fields is None, "a peer heartbeat before listening"
    newcomer.peer("robot_7", interval=2997.0, misses=(), heard=999)
    now[0] += liveness.LISTEN_BEFORE_FIRST
    seq, fields = newcomer.next_heartbeat()
    assert fields is not None and fields["interval"] == liveness.AUTO_SECONDS_PER_PEER * 999
    # a fixed interval beats at once, as configured
    fixed = liveness.Liveness("robot_1", lambda: now[0], peer_interval=1.0)
    assert fixed.next_heartbeat()[1] is not None
