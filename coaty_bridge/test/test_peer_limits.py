"""Bounded authority of a peer (issue 27, attacks 4 and 5) through a real mosquitto.

Same set-up as test_peer_authority.py (real CoatyBridgeClient + real SharingHandler per robot,
the attacker a plain MQTT client on the broker). After every attack the good obstacles are held
unchanged on every robot and a fresh valid obstacle still reaches every robot.
"""
import json
import shutil
import subprocess
import uuid as uuidlib

import pytest

from coaty_bridge import codec
from coaty_bridge.broker import Broker
from coaty_bridge.client import _make_paho_client, mqtt_client_id
from coaty_bridge.connection import masked_client_id
from coaty_bridge.identity import identity_for
from coaty_bridge.topics import Topic

from test_peer_authority import (ATTACKER, GRID, OT, _attack, _fresh_obstacle_still_reaches_everyone,  # noqa: F401
                                 _share_good, evil, fleet)
import test_peer_authority

pytestmark = pytest.mark.broker


def _bridge_counter(robot, name):
    return robot.client.counters().get(name, 0)


# ------------------------------------------------------------------------- attack 4a: cells

def test_attack_4_a_few_bytes_declaring_a_million_cells_are_not_expanded(fleet, observer, wait_for):
    robots = [fleet.join("robot_0"), fleet.join("robot_1")]
    good = _share_good(fleet, wait_for)
    before = [r.held() for r in robots]
    # the message: 10^6 cells on a made-up 1000 x 1000 grid, compact: under 2 kB
    bomb = evil(fleet.clock, size_x=1000, size_y=1000, marked=tuple(range(10 ** 6)))
    obj = codec.obstacle_to_object(bomb, OT)
    payload = json.dumps({"object": obj}).encode()
    assert len(payload) < 2500
    observer.publish(str(Topic("fleet", "ADV", ATTACKER, object_type=OT)), payload)
    # a whole-map rectangle is refused by the bridge as well (before its indexes are read)
    whole_map = evil(fleet.clock, uuid=str(uuidlib.uuid4()), rectangle=(-10.0, -5.0, 10.0, 5.0))
    _attack(observer, whole_map)
    for robot in robots:
        # a 1 m square holds 400 cells: refused on that, before any expansion (issue 43: cells within the rectangle)
        wait_for(lambda: _bridge_counter(robot, "dropped.more_cells_than_rectangle") >= 1,
                 what="%s's bridge drops the 10^6 cells before expanding them" % robot.name)
        wait_for(lambda: _bridge_counter(robot, "dropped.oversized_rectangle") >= 1,
                 what="%s's bridge drops the whole-map rectangle" % robot.name)
    # nothing of either reached a handler. (Not "the bridges' received counters did not move": since
    # delivery is fair per sender, a late Resolve of the good obstacle may still be counted here.)
    for robot in robots:
        assert bomb.uuid not in robot.held() and whole_map.uuid not in robot.held()
    for robot, held in zip(robots, before):
        now = robot.held()
        assert {u: now[u] for u in good} == {u: held[u] for u in good}, "a good obstacle was lost or changed"
        assert set(now) == set(good)
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 4.0)


def test_the_bridge_cell_cap_is_the_handlers_rule():
    from sharing_msgs.authority import PeerPolicy
    from coaty_bridge.client import BridgeConfig
    limits = BridgeConfig("robot_0").limits
    assert limits.obstacle_cell_cap(0.05) == PeerPolicy(10.0, 60).cell_cap(GRID) == 202 * 202
    assert BridgeConfig("robot_0", max_obstacle_cells=500).limits.obstacle_cell_cap(0.05) == 500
    with pytest.raises(ValueError, match="max_obstacle_extent"):
        BridgeConfig("robot_0", max_obstacle_extent=-1.0)
    with pytest.raises(ValueError, match="max_obstacle_cells"):
        BridgeConfig("robot_0", max_obstacle_cells=-1)


# -------------------------------------------------------------------- attack 4b: Discovers

def _discover(observer, requester, correlation_id):
    observer.publish(str(Topic("fleet", "DSC", requester, correlation_id=correlation_id)),
                     codec.discover_object_types_payload([OT]))


def _answered(observer, robot, correlation_ids):
    """Correlation ids of ``correlation_ids`` that ``robot`` sent a Resolve to."""
    prefix = "/RSV/%s/" % robot.client.identity_id
    return {t.rsplit("/", 1)[1] for t, _ in observer.on(prefix)} & set(correlation_ids)


def test_attack_4_a_discover_flood_is_rate_limited_per_requester(fleet, observer, wait_for):
    # a rate that refills nothing during the test: what is answered is the burst alone
    robots = [fleet.join(name, discover_answer_rate=1e-4, discover_answer_burst=3)
              for name in ("robot_0", "robot_1")]
    good = _share_good(fleet, wait_for)
    before = [r.held() for r in robots]
    flood = [str(uuidlib.uuid4()) for _ in range(40)]
    for cid in flood:
        _discover(observer, ATTACKER, cid)
    for robot in robots:
        wait_for(lambda: _bridge_counter(robot, "dropped.discover_rate_limited") >= len(flood) - 3,
                 what="%s drops the flood beyond the burst" % robot.name)
    # another requester, after the flood: answered in full at once
    other = "00000000-0000-4000-8000-00000000a11c"
    polite = str(uuidlib.uuid4())
    _discover(observer, other, polite)
    for robot in robots:
        wait_for(lambda: _answered(observer, robot, [polite]), what="%s answers the other requester" % robot.name)
        # every obstacle the robot holds, in its Resolves to the other requester (several per Resolve)
        wait_for(lambda: sum(1 + len(data.get("relatedObjects", []))
                             for _, data in observer.on("/RSV/%s/%s" % (robot.client.identity_id, polite)))
                 >= len(good), what="%s's full answer" % robot.name)
        assert len(_answered(observer, robot, flood)) == 3
        assert _bridge_counter(robot, "dropped.discover_rate_limited") == len(flood) - 3
    for robot, held in zip(robots, before):
        assert robot.held() == held
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 4.5)


def test_discover_answers_refill_with_the_injected_clock(broker, make_update):
    from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
    now = [100.0]
    client = CoatyBridgeClient(BridgeConfig("robot_0", broker_url=broker.url, discover_answer_rate=0.5,
                                            discover_answer_burst=2), lambda u, t: None, clock=lambda: now[0])
    assert [client._discover_allowed("a") for _ in range(3)] == [True, True, False]
    assert client._discover_allowed("b")          # another requester has its own bucket
    now[0] += 1.0                                  # half a token
    assert not client._discover_allowed("a")
    now[0] += 1.0
    assert client._discover_allowed("a") and not client._discover_allowed("a")
    with pytest.raises(ValueError, match="discover_answer_rate"):
        BridgeConfig("robot_0", discover_answer_rate=0)
    with pytest.raises(ValueError, match="discover_answer_burst"):
        BridgeConfig("robot_0", discover_answer_burst=0)


# ---------------------------------------------------------------- attack 5: client-id takeover

def _old_client_id(identity_id):
    """The id the bridge used before (computable from the public Identity id)."""
    return "Coaty" + identity_id.replace("-", "")[:18]


def _connect(url, client_id, wait_for, username=None, password=None):
    from coaty_bridge.client import parse_broker_url
    address = parse_broker_url(url)
    results = []
    client = _make_paho_client(client_id)
    if username:
        client.username_pw_set(username, password)
    client.on_connect = lambda c, u, f, rc, p=None: results.append(rc)
    client.connect(address.host, address.port)
    client.loop_start()
    wait_for(lambda: results, what="the attacker's CONNACK")
    return client, results[0]


def _takeover(fleet, url, wait_for, victim, other, **login):
    """The attacker connects under every client id it can compute for ``victim``; then the victim
    must still be on its first connection and its fresh obstacle must reach ``other``."""
    disconnects = _bridge_counter(victim, "disconnects")
    attackers = []
    try:
        for client_id in (_old_client_id(victim.client.identity_id),
                          "Coaty" + victim.client.identity_id.replace("-", "")[:8]):
            client, rc = _connect(url, client_id, wait_for, **login)
            attackers.append(client)
            assert rc == 0
        # the victim's fresh obstacle can only arrive over a live connection: had the broker
        # closed the old one, the victim would have counted a disconnect before it reconnects
        uuid = victim.add([3.0, 1.0, 3.3, 1.3])
        wait_for(lambda: uuid in other.held(), what="%s gets the victim's fresh obstacle" % other.name)
        assert _bridge_counter(victim, "disconnects") == disconnects, "the victim was cut off"
        assert victim.client.connected
    finally:
        for client in attackers:
            client.loop_stop()
            client.disconnect()


def test_attack_5_a_peer_cannot_take_a_robots_client_id(fleet, broker, wait_for):
    robots = [fleet.join("robot_0"), fleet.join("robot_1")]
    good = _share_good(fleet, wait_for)
    before = [r.held() for r in robots]
    _takeover(fleet, broker.url, wait_for, robots[0], robots[1])
    assert not robots[0].client.client_id.startswith(_old_client_id(robots[0].client.identity_id))
    for robot, held in zip(robots, before):
        now = robot.held()
        assert {u: now[u] for u in good} == {u: held[u] for u in good}
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 5.0)


def test_client_ids_are_fresh_per_start_and_fit_mqtt_3_1_1():
    identity = "0d9c4f0e-1a2b-4c3d-8e4f-5a6b7c8d9e0f"
    ids = {mqtt_client_id(identity) for _ in range(50)}
    assert len(ids) == 50
    assert all(len(i) == 23 and i.startswith("Coaty0d9c4f0e") for i in ids)


@pytest.fixture
def logins_broker(tmp_path):
    """Per-robot logins and the shipped ACL, as run_broker sets them up (the client id is not the login: issue 43)."""
    if not shutil.which("mosquitto_passwd"):
        pytest.skip("mosquitto_passwd not installed")
    passwords = str(tmp_path / "passwords")
    for i, robot in enumerate(("robot_0", "robot_1", "robot_9")):
        subprocess.run(["mosquitto_passwd", "-b"] + (["-c"] if i == 0 else []) +
                       [passwords, identity_for("fleet", robot), "pw-" + robot], check=True, timeout=30)
    import os
    acl = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config",
                       "mosquitto_acl.conf")
    with Broker(allow_anonymous=False, extra_config=["password_file " + passwords, "acl_file " + acl]) as broker:
        yield broker


def test_attack_5_what_the_logs_show_of_a_client_id_cannot_take_it_over(logins_broker, observer_factory, wait_for):
    """The client id's nonce is never logged (masked_client_id): robot_9, a fleet member with its own login,
    connecting under what robot_0's log shows of its id, or under robot_0's login name, does not cut it off.
    (Before issue 43 the broker made the login the client id; then any connection under robot_0's own login cut
    robot_0 off: test_logins.py.)"""
    clock = test_peer_authority.Clock()
    robots = []
    try:
        for name in ("robot_0", "robot_1"):
            robot = test_peer_authority.Robot(name, logins_broker.url, clock, authenticate_sources=True,
                                              password="pw-" + name)
            robots.append(robot)
            robot.client.start()
            wait_for(lambda: robot.client.subscribed, what="%s connected" % name)
        uuid = robots[1].add([-3.0, -3.0, -2.7, -2.7])
        wait_for(lambda: uuid in robots[0].held(), what="robot_0 holds robot_1's obstacle")
        disconnects = _bridge_counter(robots[0], "disconnects")
        # robot_9 (a fleet member with its own login) connects under robot_0's real client id
        # and under robot_0's login name as client id
        attackers = []
        shown = masked_client_id(robots[0].client.client_id)
        assert shown != robots[0].client.client_id and robots[0].client.client_id[13:] not in shown
        for client_id in (shown, robots[0].client.identity_id, identity_for("fleet", "robot_0")):
            client, rc = _connect(logins_broker.url, client_id, wait_for,
                                  username=identity_for("fleet", "robot_9"), password="pw-robot_9")
            attackers.append(client)
            assert rc == 0
        fresh = robots[0].add([3.0, 1.0, 3.3, 1.3])
        wait_for(lambda: fresh in robots[1].held(), what="robot_1 gets robot_0's fresh obstacle")
        assert _bridge_counter(robots[0], "disconnects") == disconnects, "robot_0 was cut off"
        for client in attackers:
            client.loop_stop()
            client.disconnect()
    finally:
        for robot in robots:
            robot.client.stop(timeout=0.5)
