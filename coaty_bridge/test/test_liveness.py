"""Truthful liveness (issue 27, attack 6) through a real mosquitto and real bridge clients.

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
a fresh obstacle reaches every robot.
"""
import pytest

from coaty_bridge import liveness
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from tcp_proxy import TcpProxy

import test_peer_authority
from test_peer_authority import GOOD, _fresh_obstacle_still_reaches_everyone

pytestmark = pytest.mark.broker

NAMES = ("robot_0", "robot_1", "robot_2")
TIMEOUT = 3.0


class Robot(test_peer_authority.Robot):
    def __init__(self, name, url, clock):
        super().__init__(name, url, clock)
        config = BridgeConfig(name, broker_url=url, heartbeat_interval=1.0, liveness_timeout=TIMEOUT,
                              reconnect_min_delay=0.1, reconnect_max_delay=0.5)
        self.client = CoatyBridgeClient(config, self._from_fleet, clock=clock, heartbeats=False,
                                        on_footprint=lambda f, t: None)

    def status(self):
        return self.client.liveness.status()


def _subscribed(robot, wait_for):
    """Waits until the robot hears its own heartbeats: connected is set before the broker has
    taken the subscriptions, and a heartbeat published before that is not delivered."""
    wait_for(lambda: robot.client.connected, what="%s connected" % robot.name)
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
    lv = liveness.Liveness("robot_0", lambda: now[0], timeout=3.0, known_robots=("robot_0", "robot_1"))
    assert lv.status()[0] == liveness.OK
    now[0] = 4.0
    level, reason = lv.status()            # nothing sent, the known robot never heard
    assert level == liveness.ERROR and "robot_1 never heard" in reason
    seq, hears = lv.next_heartbeat()
    lv.own_echo(seq)
    lv.peer("robot_1", ["robot_0"])
    assert lv.status() == (liveness.OK, "")
    lv.next_heartbeat()
    now[0] = 7.5
    assert lv.status()[0] == liveness.ERROR
    lv.forget("robot_1")
    assert "robot_1" not in lv.status()[1]


def test_a_robot_that_stops_cleanly_is_not_missed(net, wait_for):
    _all_ok(net, wait_for)
    net.by_name["robot_2"].client.stop(timeout=2.0)
    wait_for(lambda: "robot_2" not in net.by_name["robot_0"].client.liveness._peers, what="robot_2 forgotten")
    for _ in range(4):
        net.beat(live=("robot_0", "robot_1"))
    assert net.by_name["robot_0"].status() == (liveness.OK, "")
    with pytest.raises(ValueError, match="liveness_timeout"):
        BridgeConfig("robot_0", heartbeat_interval=2.0, liveness_timeout=3.0)
