"""Issue 43's attacks through real nodes, in the secure default: one robot's valid login must not blind or erase
the fleet. The same fleet as test_attacks_nodes.py (its NodeFleet: run_broker as the fleet launch starts it, three
robots each a real sharing_handler and coaty_bridge node with the launch's parameters, plausible evidence on,
fleet_probe playing the map and the robots' footprints at ROBOT_POSES); the attacker holds robot_3's login,
advertises robot_3's pose where it says it stands and publishes raw Coaty messages.

Every case: the attack; then (1) no good obstacle is lost or changed on any robot (uuid, cells, rectangle,
source) and none got a longer lease, (2) a fresh obstacle added on robot_0 reaches every robot (the latency is
printed; asserted <= 1 s only with FLEET_ASSERT_LATENCY=1), (3) the attack is named in /diagnostics (its
counter rises on every robot; the bridge's status WARNs naming robot_3 for what it claimed and could not have
seen). Outcomes are judged after the attacker's sentinel obstacle (sent last, on the same connection) is listed
everywhere, not after a sleep. Items 7 (VDA 5050), 8 (crashes) and 9 (credentials, certificates) have their
node tests in vda5050_bridge/test/test_vda_secure.py, tests/test/test_fleet_crashes.py, test_logins.py and
test_tls_errors.py; item 9's adding of a robot is also shown here on this running fleet."""
import dataclasses
import json
import math
import os
import subprocess
import sys
import time
import uuid as uuidlib

import pytest

from coaty_bridge import codec
from coaty_bridge.identity import identity_for
from coaty_bridge.topics import Topic

from attack_fleet import (ATTACKER, ATTACKER_POSE, DURATION, NS, OT, OX, OY, RES, ROBOTS, SX, SY, GOOD, cell, evil,
                          wait_until)
from test_attacks_nodes import fleet  # noqa: F401 (the module's running fleet, a fixture)
from test_secure_default import Peer

pytestmark = [pytest.mark.ros, pytest.mark.broker]

#: s ahead of now the attacker stamps a claim (within the handlers' max_clock_skew 5 s, beyond evidence_window 2 s)
AHEAD = 3.0
#: s between the stamps of two claims from different poses: more than twice evidence_window (2 s)
APART = 4.2
SQUARE_RADIUS = math.hypot(0.3, 0.3)   # the attacker's footprint: a 0.6 m square
# the evidence rule's allowance at the advert's own stamp (sharing_msgs README, "Plausible evidence")
ALLOWANCE = 4.0 + SQUARE_RADIUS + RES / math.sqrt(2) + 0.25


def centre(index):
    return OX + (index % SX + 0.5) * RES, OY + (index // SX + 0.5) * RES


def one_cell(index):
    x, y = OX + (index % SX) * RES, OY + (index // SX) * RES
    return (x, y, x + RES, y + RES)


def bridges_warned_naming_the_attacker(fleet, mark):
    with fleet.probe._cond:
        events = fleet.probe.events[mark:]
    named = {s["name"] for e in events if e.get("event") == "diagnostics" for s in e["status"]
             if s["name"].startswith("coaty_bridge: ") and s["level"] >= 1
             and (ATTACKER in s["message"] or fleet.login[:8] in s["message"])}
    return named == {"coaty_bridge: " + r for r in ROBOTS}


def claim(fleet, update, stamp=None, pose=None, points=None, message_stamp=None):
    """The attacker advertises a pose (its current one, or ``pose``/``points``) and sends ``update`` right after, on
    one connection. Both are stamped AHEAD s from now (or ``stamp``; the message ``message_stamp``): no earlier
    pose of robot_3 (the sentinels' and earlier tests', all stamped before now) lies within the window of it, so
    what is judged is this pose alone."""
    stamp = time.time() + AHEAD if stamp is None else stamp
    where = (pose or fleet.attacker_pose, points)
    last = getattr(fleet, "last_claim", None)
    if last is not None and last[1] != where and stamp - last[0] < APART:
        # an earlier claim's pose must not vouch for this one: their stamps lie more than twice the window apart
        time.sleep(APART - (stamp - last[0]))
        stamp += APART - (stamp - last[0])
    fleet.last_claim = (stamp, where)
    fleet.advertise_pose(pose, points, stamp=stamp)
    if isinstance(message_stamp, str):                    # "offset:<s>": that far from the (possibly moved) stamp
        message_stamp = stamp + float(message_stamp.split(":", 1)[1])
    update = dataclasses.replace(update, stamp=stamp if message_stamp is None else message_stamp)
    obj = codec.obstacle_to_object(update, OT)
    fleet.publish(str(Topic(NS, "ADV", fleet.login, object_type=OT)), json.dumps({"object": obj}).encode())


def attackers_covering(fleet, robot, index):
    """robot_3's obstacles listed on ``robot`` whose rectangle covers cell ``index``: a taken message of robot_3's
    may merge with its other obstacles (one creator), so its own uuid need not be listed."""
    cx, cy = centre(index)
    return [u for u, (source, rect, _) in fleet.held(robot).items()
            if source == ATTACKER and rect[0] <= cx <= rect[2] and rect[1] <= cy <= rect[3]]


def taken_everywhere(fleet, update, index):
    """Whether every robot took ``update`` (cell ``index``): its uuid listed, or an obstacle of robot_3's covering
    the cell (none did before: the callers check that first); False when no robot did."""
    taken = [update.uuid in fleet.list_of(r)["uuids"] or bool(attackers_covering(fleet, r, index)) for r in ROBOTS]
    assert all(taken) or not any(taken), "robots disagree: %s" % dict(zip(ROBOTS, taken))
    return all(taken)


def listed_everywhere(fleet, uuid):
    return all(uuid in fleet.list_of(r)["uuids"] for r in ROBOTS)


def after_each(fleet, before, what):
    fleet.assert_good_unchanged(before)
    fleet.fresh_obstacle_reaches_everyone(what)


# -------------------------------------------------------------------------------------------------- item 1

def test_item_1_a_one_cell_rectangle_cannot_carry_a_region_of_cells(fleet):
    """The issue's ~600-byte message: one cell's rectangle, compact-encoded cells of a whole region."""
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.more_cells_than_rectangle")
    x, y = ATTACKER_POSE
    region = tuple(cell(x - 1.0 + 0.05 * i, y - 1.0 + 0.05 * j) for i in range(40) for j in range(40))
    bomb = evil(rectangle=one_cell(region[0]), marked=region)
    assert len(json.dumps({"object": codec.obstacle_to_object(bomb, OT)})) < 1000
    claim(fleet, bomb)
    fleet.sentinel()
    for robot in ROBOTS:
        assert bomb.uuid not in fleet.list_of(robot)["uuids"]
    fleet.wait_counted("bridge", "dropped.more_cells_than_rectangle", counted)
    after_each(fleet, before, "item 1 one-cell rectangle")


def test_item_1_a_cell_just_beyond_the_advertised_reach_is_refused_one_just_within_taken(fleet):
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.implausible_evidence")
    mark = fleet.mark()
    ax, ay = fleet.attacker_pose = (-2.0, 0.5)
    inside = cell(ax, ay)
    while math.hypot(centre(inside + 1)[0] - ax, centre(inside + 1)[1] - ay) <= ALLOWANCE:
        inside += 1
    outside = inside + 1
    assert not any(attackers_covering(fleet, r, c) for r in ROBOTS for c in (inside, outside))
    stamp = time.time() + AHEAD
    near = evil(rectangle=one_cell(inside), marked=(inside,))
    far = evil(rectangle=one_cell(outside), marked=(outside,))
    claim(fleet, far, stamp=stamp)
    claim(fleet, near, stamp=stamp)
    fleet.sentinel()
    # (the two are robot_3's and adjacent: taken, they merge into one, whose rectangle then covers both cells)
    assert taken_everywhere(fleet, near, inside), "refused a cell %.3f m from the pose" % (
        math.hypot(centre(inside)[0] - ax, centre(inside)[1] - ay))
    assert not taken_everywhere(fleet, far, outside), "took a cell %.3f m from the pose" % (
        math.hypot(centre(outside)[0] - ax, centre(outside)[1] - ay))
    fleet.wait_counted("bridge", "dropped.implausible_evidence", counted)
    wait_until(lambda: bridges_warned_naming_the_attacker(fleet, mark), "every bridge WARNing naming robot_3")
    fleet.attacker_at(*ATTACKER_POSE)
    after_each(fleet, before, "item 1 reach")


@pytest.mark.parametrize("offset,taken", [(1.95, True), (2.05, False)])
def test_item_1_a_pose_is_evidence_only_within_the_window_of_the_stamp(fleet, offset, taken):
    """A message stamped just inside / just past evidence_window (2 s) after the pose it relies on."""
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.implausible_evidence")
    x, y = ATTACKER_POSE
    index = cell(x + 0.5 + offset, y - (1.3 if taken else 2.0))   # a cell of its own for each case, 0.7 m apart
    assert not any(attackers_covering(fleet, r, index) for r in ROBOTS)
    update = evil(rectangle=one_cell(index), marked=(index,))
    claim(fleet, update, pose=(x + 0.01 * offset, y), stamp=time.time() + 1.0,   # the message at most 3.05 s ahead
          message_stamp=None if offset is None else "offset:%g" % offset)
    fleet.sentinel()
    assert taken_everywhere(fleet, update, index) is taken
    if not taken:
        fleet.wait_counted("bridge", "dropped.implausible_evidence", counted)
    after_each(fleet, before, "item 1 window %+.2f s" % offset)


def test_item_1_a_footprint_half_a_metre_by_fifty_is_no_evidence(fleet):
    """A 'robot' 0.5 x 50 m long would reach 25 m further: receivers drop it as a footprint (max_footprint_extent
    5 m), so the cells it was to vouch for are refused."""
    before = fleet.snapshot()
    counted = fleet.counters("bridge", "dropped.footprint_too_large")
    refused = fleet.counters("bridge", "dropped.implausible_evidence")
    far = cell(4.5, -2.3)                          # 4.5 m and more from every pose robot_3 advertised so far
    stretched = ((-25.0, -2.3), (25.0, -2.3), (25.0, -1.8), (-25.0, -1.8))
    update = evil(rectangle=one_cell(far), marked=(far,))
    claim(fleet, update, points=stretched)
    fleet.sentinel()
    for robot in ROBOTS:
        assert update.uuid not in fleet.list_of(robot)["uuids"]
    fleet.wait_counted("bridge", "dropped.footprint_too_large", counted)
    fleet.wait_counted("bridge", "dropped.implausible_evidence", refused)
    after_each(fleet, before, "item 1 stretched footprint")


@pytest.mark.parametrize("width,taken", [(8.95, True), (9.05, False)])
def test_item_1_an_obstacle_is_at_most_what_one_robot_can_see_across(fleet, width, taken):
    """9 m with the fleet's 4 m reach (max_obstacle_extent 10 m admitted a whole hall); its cells near robot_3."""
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.oversized_rectangle")
    x, y = ATTACKER_POSE
    # a row of its own each, more than merge_distance from robot_3's other obstacles (robot_3's own merge: a 9 m one
    # would absorb them all and cover the map for its lease); a short lease, waited out at the end
    below = 2.5 if taken else 2.2
    rectangle = (x - width / 2, y - below, x + width / 2, y - below + 0.05)
    index = cell(x - 1.0, y - below + 0.01)
    assert not any(attackers_covering(fleet, r, index) for r in ROBOTS)
    update = evil(rectangle=rectangle, marked=(index,), deadline=10)
    claim(fleet, update)
    fleet.sentinel()
    assert taken_everywhere(fleet, update, index) is taken
    if taken:
        for robot in ROBOTS:
            assert any(fleet.held(robot)[u][1][2] - fleet.held(robot)[u][1][0] >= width - 0.01
                       for u in attackers_covering(fleet, robot, index)), robot
        wait_until(lambda: not any(attackers_covering(fleet, r, index) for r in ROBOTS), "its 10 s lease running out")
    else:
        fleet.wait_counted("bridge", "dropped.oversized_rectangle", counted)
    after_each(fleet, before, "item 1 extent %.2f m" % width)


# -------------------------------------------------------------------------------------------------- item 2

def test_item_2_an_attackers_obstacle_absorbs_no_honest_one_and_takes_no_honest_name(fleet):
    """An 8 m obstacle from robot_3, its cells near it, its rectangle over robot_0's good obstacle at (-1, -2): the
    good one is not absorbed, the attacker's stays robot_3's, and robot_0 proposing beside it makes an obstacle of
    its own (before: an update of the attacker's, renewing it)."""
    before = fleet.snapshot()
    fleet.attacker_at(-1.0, -0.2)
    rectangle = (-4.5, -2.2, 3.5, 0.3)
    bait = evil(rectangle=rectangle, marked=tuple(cell(-1.0 + 0.05 * i, 0.25) for i in range(10)), deadline=600)
    claim(fleet, bait)
    fleet.sentinel()

    def robot_3s(robot):
        """robot_3's listed obstacles (its own may merge with its sentinels: one source) and their leases."""
        held, deadlines = fleet.held(robot), fleet.deadlines(robot)
        return {u: deadlines[u] for u, h in held.items() if h[0] == ATTACKER}
    for robot in ROBOTS:
        covering = [u for u, h in fleet.held(robot).items() if h[1][0] <= -4.49 and h[1][2] >= 3.49]
        assert covering and all(fleet.held(robot)[u][0] == ATTACKER for u in covering), \
            "%s lists the bait under another name: %s" % (robot, [fleet.held(robot)[u] for u in covering])
    left = {r: robot_3s(r) for r in ROBOTS}
    beside = fleet.add("robot_0", [0.2, -0.9, 0.4, -0.7])       # inside the bait's rectangle, near robot_0
    wait_until(lambda: listed_everywhere(fleet, beside), "robot_0's obstacle beside the bait everywhere")
    for robot in ROBOTS:
        assert fleet.held(robot)[beside][0] == "robot_0"
        now = robot_3s(robot)
        # (robot_3's own obstacles may merge with each other, the survivor taking the longest lease of them)
        assert max(now.values()) <= max(left[robot].values()), \
            "robot_0's proposal renewed robot_3's obstacle: %s -> %s" % (left[robot], now)
    fleet.attacker_at(*ATTACKER_POSE)
    after_each(fleet, before, "item 2 merge bait")


# -------------------------------------------------------------------------------------------------- item 3

def test_item_3_a_robot_eight_metres_away_cannot_clear_another_robots_obstacle(fleet):
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.implausible_evidence")
    target, rect = fleet.good[2], GOOD[2][1]                      # robot_1's, at (3, -2)
    cells = fleet.held("robot_0")[target][2]
    fleet.attacker_at(-4.5, 2.0)                                  # 8.7 m away, behind everything
    erase = evil(uuid=target, version=5, rectangle=tuple(rect), marked=(), deadline=1,
                 cleared=tuple(cell(rect[0] + 0.025 + 0.05 * i, rect[1] + 0.025 + 0.05 * j)
                               for i in range(6) for j in range(6)))
    claim(fleet, erase)
    fleet.sentinel()
    for robot in ROBOTS:
        assert fleet.held(robot)[target][2] == cells, "%s: cells cleared from 8.7 m away" % robot
    fleet.wait_counted("bridge", "dropped.implausible_evidence", counted)
    fleet.attacker_at(*ATTACKER_POSE)
    after_each(fleet, before, "item 3 far clear")


def test_item_3_a_plausible_clear_of_one_cell_never_shortens_the_lease_of_the_rest(fleet):
    """From beside it (plausible), a clear of one cell with deadline 1 removes that cell only: before, the whole
    obstacle's lease became 1 s and it was gone fleet-wide."""
    target, rect = fleet.good[2], GOOD[2][1]
    before = fleet.snapshot()
    left = {r: fleet.deadlines(r)[target] for r in ROBOTS}
    fleet.attacker_at(3.2, -0.8)
    one = cell(rect[0] + 0.025, rect[1] + 0.025)
    claim(fleet, evil(uuid=target, version=50, rectangle=tuple(rect), marked=(), cleared=(one,), deadline=1))
    fleet.sentinel()
    for robot in ROBOTS:
        wait_until(lambda r=robot: fleet.held(r)[target][2] == before[r][0][target][2] - 1, "the one cell cleared")
        assert fleet.deadlines(robot)[target] >= left[robot] - 60, "%s: the lease was shortened" % robot
    fleet.attacker_at(*ATTACKER_POSE)
    # the good obstacle lost the one cell it was seen free: the rest unchanged (not lost, not shortened)
    fleet.good_cells_cleared = getattr(fleet, "good_cells_cleared", 0) + 1
    fleet.fresh_obstacle_reaches_everyone("item 3 plausible clear")


def test_item_3_an_obstacle_cleared_fleet_wide_is_shown_again_when_its_robot_sees_it_again(fleet):
    """A plausible clear of every cell ends robot_0's obstacle on every robot's list; robot_0's layer still sees
    the block and marks it again (an update of the uuid it knows): every robot shows it again, all its cells,
    robot_0's. Before, a clear with deadline 1 ended its lease and tombstoned the uuid, and nothing came back in
    the 90 s watched. (The lease is kept, so the uuid is held, hidden, and shown again; were it tombstoned, the
    update would go out as a new obstacle of robot_0's: either passes.)"""
    before = fleet.snapshot()
    rect = [1.0, -1.7, 1.2, -1.5]      # near robot_0 at (0, -1), beyond merge_distance of its other obstacles
    block = fleet.add("robot_0", rect)
    wait_until(lambda: listed_everywhere(fleet, block), "robot_0's block on every robot")
    cells = tuple(cell(rect[0] + 0.025 + 0.05 * i, rect[1] + 0.025 + 0.05 * j) for i in range(4) for j in range(4))
    assert all(fleet.held(r)[block][2] == len(cells) for r in ROBOTS)
    fleet.attacker_at(1.5, -0.5)                           # 1.2 m from it: it may see it free
    claim(fleet, evil(uuid=block, version=50, rectangle=tuple(rect), marked=(), cleared=cells, deadline=1))
    fleet.sentinel()
    for robot in ROBOTS:
        wait_until(lambda r=robot: block not in fleet.list_of(r)["uuids"], "the block cleared on " + robot)
    time.sleep(1.5)                # past the clear's deadline 1 s: a lease it had shortened would have ended
    # robot_0's layer marks the block's cells again
    fleet.command({"cmd": "publish", "robot": "robot_0", "topic": "obstacle_updates", "msg": dict(
        uuid=block, marked_indexes=list(cells), version=51, source="robot_0", deadline=DURATION,
        rectangle_shape=rect, resolution=RES, origin_x=OX, origin_y=OY, size_x=SX, size_y=SY, stamp=time.time(),
        frame_id="map")})
    cx, cy = (rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2

    def shown_again(robot):
        return [u for u, (source, r, n) in fleet.held(robot).items()
                if source == "robot_0" and r[0] <= cx <= r[2] and r[1] <= cy <= r[3] and n == len(cells)]
    for robot in ROBOTS:
        wait_until(lambda r=robot: shown_again(r), "robot_0's block shown again on " + robot)
    print("item 3: the block is shown again as %s" % ("the same uuid" if shown_again("robot_1") == [block] else
                                                       "a new obstacle of robot_0's"))
    fleet.attacker_at(*ATTACKER_POSE)
    after_each(fleet, before, "item 3 shown again")


# -------------------------------------------------------------------------------------------------- item 4

def test_item_4_a_far_robot_cannot_pin_another_robots_obstacle(fleet):
    """Re-marking one cell of robot_0's obstacle every few seconds from far kept it at ~1,200 s forever: refused, its
    lease keeps running down."""
    target, rect = fleet.good[0], GOOD[0][1]
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.implausible_evidence")
    left = {r: fleet.expiries(r)[target] for r in ROBOTS}
    # a renewal would now move the end of the lease on by 3 s at least (the lists say whole seconds)
    time.sleep(max(0.0, max(left.values()) - DURATION + 4.0 - time.time()))
    fleet.attacker_at(3.5, 2.0)                                    # 7.5 m from it
    inside = cell(rect[0] + 0.1, rect[1] + 0.1)
    for k in range(3):
        claim(fleet, evil(uuid=target, version=100 + k, rectangle=tuple(rect), marked=(inside,), deadline=DURATION))
    fleet.sentinel()
    for robot in ROBOTS:
        assert fleet.expiries(robot)[target] <= left[robot] + 1.5, "%s: the lease was renewed from afar: ends %.1f s " \
            "later" % (robot, fleet.expiries(robot)[target] - left[robot])
    fleet.wait_counted("bridge", "dropped.implausible_evidence", counted, at_least=3)
    fleet.attacker_at(*ATTACKER_POSE)
    after_each(fleet, before, "item 4 pin")


# -------------------------------------------------------------------------------------------------- item 6

def test_item_6_a_second_connection_under_a_robots_login_leaves_it_on_the_broker_and_is_reported(fleet):
    victim = "robot_2"
    disconnects = fleet.counter("coaty_bridge: " + victim, "disconnects")
    adverts = len(fleet.identity_adverts(victim))
    before = fleet.snapshot()
    mark = fleet.mark()
    login, password = fleet.creds.login(victim)
    for attempt in range(2):                                       # held, then again
        peer = Peer(fleet.port, login, password, subscribe=None)
        fleet.peers.append(peer)
        wait_until(peer.settled, "the broker's answer")
        assert peer.accepted
        wait_until(lambda n=attempt: _login_level(fleet, victim, mark) >= n + 1,
                   "%s's bridge at %s about the other connection" % (victim, ("WARN", "ERROR")[attempt]))
        peer.close()
    assert "coaty/3/%s/DAD/%s" % (NS, identity_for(NS, victim)) not in fleet.watcher.topics(), victim + " was cut off"
    assert len(fleet.identity_adverts(victim)) == adverts, victim + " had to reconnect"
    assert fleet.counter("coaty_bridge: " + victim, "disconnects") == disconnects
    after_each(fleet, before, "item 6")


def _login_level(fleet, robot, mark):
    status = fleet.status("coaty_bridge: " + robot, after=mark)
    if status and "other connection" in status["message"] and "login" in status["message"]:
        return status["level"]
    return 0


# -------------------------------------------------------------------------------------------------- item 9

def test_item_9_a_robot_added_while_the_fleet_runs_logs_in_without_a_restart(fleet):
    before = fleet.snapshot()
    script = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "fleet_credentials")
    stranger = Peer(fleet.port, identity_for(NS, "robot_4"), "anything", subscribe=None)
    fleet.peers.append(stranger)
    wait_until(stranger.settled, "the broker's answer")
    assert stranger.refused
    done = subprocess.run([sys.executable, script, "add", "robot_4", "--credentials-dir", fleet.credentials],
                          capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    wait_until(lambda: any("added robot_4" in l for l in fleet.broker_out.lines), "run_broker reloading the logins")
    newcomer = Peer(fleet.port, *fleet.creds.login("robot_4"), subscribe=None)
    fleet.peers.append(newcomer)
    wait_until(newcomer.settled, "the broker's answer")
    assert newcomer.accepted, "robot_4's new login was refused"
    after_each(fleet, before, "item 9")


# -------------------------------------------------------------------------------------------------- item 5 (last:
# it leaves the attacker's obstacles held and drains its budgets)

def test_item_5_five_thousand_valid_obstacles_from_one_login_do_not_cut_the_others_off(fleet):
    """5,000 valid new obstacles from robot_3, each within its reach, as fast as paho sends them: every bridge drops
    what exceeds robot_3's bucket and names it; what passes waits in robot_3's own queue in every bridge and
    handler; robot_0's fresh obstacle, sent while the flood is being taken, reaches every robot."""
    before, counted = fleet.snapshot(), fleet.counters("bridge", "dropped.source_rate_limited")
    mark = fleet.mark()
    topic = str(Topic(NS, "ADV", fleet.login, object_type=OT))
    fleet.advertise_pose()
    x0, y0 = ATTACKER_POSE
    infos = []
    for i in range(5000):
        x, y = x0 - 2.0 + 0.05 * (i % 80), y0 - 0.9 + 0.05 * ((i // 80) % 36)
        update = evil(rectangle=(x, y, x + 0.05, y + 0.05), marked=(cell(x + 0.01, y + 0.01),),
                      uuid=str(uuidlib.uuid4()))
        infos.append(fleet.attacker.client.publish(topic, codec.advertise_payload(codec.obstacle_to_object(update, OT))))
        if i == 2500:
            fleet.advertise_pose()      # the pose stays fresh for the later half (they are stamped as sent)
    latency = fleet.fresh_obstacle_reaches_everyone("item 5 (during the flood)")
    for info in infos:
        info.wait_for_publish(30)
    fleet.wait_counted("bridge", "dropped.source_rate_limited", counted, at_least=100)
    wait_until(lambda: bridges_warned_naming_the_attacker(fleet, mark), "every bridge WARNing naming robot_3")
    print("item 5: the fresh obstacle reached every robot %.2f s after it was added, during the flood" % latency)
    after_each(fleet, before, "item 5 (after the flood)")
