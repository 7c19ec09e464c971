"""When a robot advertises its footprint (issue 29, fleet traffic): at the rate while it moves, rarely
while parked with a validFor that keeps it known between adverts, and withdrawn (a Deadvertise) so that
peers do not keep a robot that is gone. Pure tests, then real mosquitto."""
import json
import uuid as uuidlib

import pytest

from coaty_bridge import footprint as fp
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.errors import CoatyError
from coaty_bridge.topics import Topic

SQUARE = ((0.0, 0.0), (0.6, 0.0), (0.6, 0.6), (0.0, 0.6))


def shifted(points, dx, dy=0.0):
    return tuple((x + dx, y + dy) for x, y in points)


def run(schedule, poses, rate=2.0):
    """Ticks at ``rate`` over (time, points) poses; returns (time, validFor) of every advert sent."""
    sent = []
    for now, points in poses:
        for valid_for in (schedule.on_footprint(points, now), schedule.on_tick(points, now)):
            if valid_for is not None:
                schedule.sent(points, now, valid_for)
                sent.append((now, valid_for))
    return sent


def test_a_parked_robot_advertises_every_parked_interval_with_a_validity_beyond_it():
    schedule = fp.AdvertSchedule(rate=2.0, min_move=0.1, parked_interval=10.0)
    sent = run(schedule, [(t * 0.5, SQUARE) for t in range(121)])   # 60 s standing
    assert sent[0] == (0.0, 0.0)
    parked = [s for s in sent if s[1] > 0]
    assert all(v == fp.PARKED_VALIDITY * 10.0 for _, v in parked)
    assert len(sent) <= 8, "%d adverts in 60 s parked (2 Hz would be 120)" % len(sent)
    gaps = [b[0] - a[0] for a, b in zip(parked, parked[1:])]
    assert gaps and all(9.5 <= g <= 10.5 for g in gaps), gaps


def test_a_driving_robot_advertises_at_the_rate_and_at_every_min_move():
    schedule = fp.AdvertSchedule(rate=2.0, min_move=0.1, parked_interval=10.0)
    # 0.5 m/s, a footprint every 0.1 s: a motion advert every 0.1 m, never a parked one
    poses = [(t * 0.1, shifted(SQUARE, 0.05 * t)) for t in range(100)]
    sent = []
    for now, points in poses:
        valid_for = schedule.on_footprint(points, now)
        if valid_for is None and abs(now * 2 - round(now * 2)) < 1e-9:
            valid_for = schedule.on_tick(points, now)
        if valid_for is not None:
            schedule.sent(points, now, valid_for)
            sent.append((now, valid_for))
    assert all(v == 0.0 for _, v in sent), "a driving robot sent a parked advert"
    assert len(sent) >= 30, "%d adverts over 4.95 m of driving" % len(sent)


def test_a_turn_on_the_spot_is_motion():
    """The centroid stays put; the corners move."""
    schedule = fp.AdvertSchedule(rate=2.0, min_move=0.1, parked_interval=10.0)
    schedule.sent(SQUARE, 0.0, 0.0)
    turned = ((0.6, 0.0), (0.6, 0.6), (0.0, 0.6), (0.0, 0.0))
    assert schedule.on_footprint(turned, 0.1) == 0.0


def test_parked_interval_zero_keeps_the_rate():
    schedule = fp.AdvertSchedule(rate=2.0, min_move=0.1, parked_interval=0.0)
    sent = run(schedule, [(t * 0.5, SQUARE) for t in range(21)])
    assert len(sent) == 21 and all(v == 0.0 for _, v in sent)


def test_the_table_keeps_a_parked_robot_for_its_validity_and_forgets_it_on_withdrawal():
    now = [0.0]
    table = fp.FleetRobotTable("robot_0", 3.0, lambda: now[0])
    table.heard(fp.RobotFootprint("robot_1", 1.0, "map", SQUARE, valid_for=25.0))
    table.heard(fp.RobotFootprint("robot_2", 1.0, "map", SQUARE))
    now[0] = 20.0
    assert table.expire() == ["robot_2"]
    assert [r.footprint.robot for r in table.robots()] == ["robot_1"]
    assert table.forget("robot_1") and not table.forget("robot_1")
    assert table.robots() == []


def test_a_parked_robot_is_vouched_for_until_its_validity_runs_out_and_a_driving_one_from_when_heard():
    """The stamp on fleet_robots, from which a layer's robot_timeout (3 s) counts: a parked robot's
    adverts come every 10 s, so a stamp of when it was heard would let the layer forget it between them."""
    timeout = 3.0
    parked = fp.HeardRobot(fp.RobotFootprint("robot_1", 1.0, "map", SQUARE, valid_for=25.0), heard_at=100.0)
    for now in (100.0, 105.0, 109.9, 121.0):
        assert now - parked.vouched_at(now, timeout) <= timeout, "a layer forgets robot_1 at %g" % now
    assert parked.vouched_at(125.0, timeout) == 122.0, "the layer keeps it to the end of validFor, not beyond"
    assert parked.vouched_at(200.0, timeout) == 122.0
    driving = fp.HeardRobot(fp.RobotFootprint("robot_2", 1.0, "map", SQUARE), heard_at=100.0)
    assert driving.vouched_at(105.0, timeout) == 100.0
    brief = fp.HeardRobot(fp.RobotFootprint("robot_3", 1.0, "map", SQUARE, valid_for=1.0), heard_at=100.0)
    assert brief.vouched_at(105.0, timeout) == 100.0, "a validity below robot_timeout never backdates the stamp"


@pytest.mark.parametrize("bad", [-1.0, fp.MAX_VALID_FOR + 1, float("nan"), float("inf"), "10", True])
def test_a_bad_valid_for_is_refused_by_name(bad):
    obj = fp.footprint_to_object(fp.RobotFootprint("robot_1", 1.0, "map", SQUARE), str(uuidlib.uuid4()))
    obj["validFor"] = bad
    with pytest.raises(CoatyError, match="validFor"):
        fp.footprint_from_object(obj)


def test_valid_for_is_on_the_wire_only_when_parked():
    moving = fp.footprint_to_object(fp.RobotFootprint("robot_1", 1.0, "map", SQUARE), str(uuidlib.uuid4()))
    assert "validFor" not in moving, "an older receiver sees the adverts it knows"
    parked = fp.footprint_to_object(fp.RobotFootprint("robot_1", 1.0, "map", SQUARE, valid_for=25.0),
                                    str(uuidlib.uuid4()))
    assert fp.footprint_from_object(parked).valid_for == 25.0


@pytest.mark.broker
def test_a_withdrawn_footprint_is_forgotten_at_once_and_only_its_sender_may_withdraw(broker, observer, wait_for):
    heard, gone = [], []

    def client(name):
        made = CoatyBridgeClient(BridgeConfig(name, broker_url=broker.url), lambda u, t: None,
                                 on_footprint=lambda f, t: heard.append(f.robot),
                                 on_footprint_withdrawn=lambda robot, t: gone.append(robot))
        made.start()
        return made
    listener, parked = client("robot_0"), client("robot_1")
    try:
        wait_for(lambda: listener.subscribed and parked.subscribed, what="subscribed")
        listener.note_own_position((1.0, 1.0))
        parked.note_own_position((2.0, 2.0))
        advert = fp.RobotFootprint("robot_1", 1.0, "map", shifted(SQUARE, 2.0, 2.0), valid_for=25.0)
        wait_for(lambda: parked.publish_footprint(advert) and "robot_1" in heard, what="the parked advert")
        # somebody else's Deadvertise naming robot_1's agent does not withdraw it
        stranger = str(uuidlib.uuid4())
        observer.publish(str(Topic("fleet", "DAD", stranger)),
                         json.dumps({"objectIds": [parked.identity_id, parked.footprint_object_id]}))
        # then a bad one from the same sender: once it is counted, the first has been handled
        observer.publish(str(Topic("fleet", "DAD", stranger)), json.dumps({"objectIds": "x"}))
        wait_for(lambda: listener.counters().get("dropped.wrong_type") == 1, what="the stranger's Deadvertises")
        assert gone == [], "a stranger's Deadvertise withdrew robot_1"
        assert parked.withdraw_footprint()
        wait_for(lambda: gone == ["robot_1"], what="robot_1 withdrawn")
        assert listener.counters()["footprints_withdrawn"] == 1
    finally:
        listener.stop(timeout=0.5)
        parked.stop(timeout=0.5)


# --- far from every known robot: adverts every far_move, not every min_move ----------------------------------------

def drive(schedule, speed, seconds, near=lambda t: True, topic_rate=5.0, rate=2.0):
    """A robot driving along x at ``speed`` with its footprint topic at ``topic_rate`` and the tick at ``rate``;
    ``near(t)`` says whether a known robot is within the near distance. Returns (time, x, validFor) per advert."""
    sent = []
    steps = int(round(seconds * topic_rate))
    for k in range(steps + 1):
        now = k / topic_rate
        points = shifted(SQUARE, speed * now)
        valid_for = schedule.on_footprint(points, now, near(now))
        if valid_for is None and abs(now * rate - round(now * rate)) < 1e-9:
            valid_for = schedule.on_tick(points, now, near(now))
        if valid_for is not None:
            schedule.sent(points, now, valid_for)
            sent.append((now, round(speed * now, 6), valid_for))
    return sent


def far_schedule():
    return fp.AdvertSchedule(rate=2.0, min_move=0.1, parked_interval=30.0, far_move=1.0)


def test_a_driving_robot_far_from_every_known_robot_advertises_every_far_move():
    near = drive(far_schedule(), 0.65, 30.0)
    far = drive(far_schedule(), 0.65, 30.0, near=lambda t: False)
    assert len(near) >= 150, len(near)            # 0.65 m/s at 5 Hz: every footprint moved 0.13 m
    assert 18 <= len(far) <= 22, len(far)          # 19.5 m: one advert per metre
    # after the first (precise) advert and the first far one, the next heartbeat tick: one per metre driven
    moves = [b[1] - a[1] for a, b in zip(far[1:], far[2:])]
    assert all(0.99 <= m <= 1.2 for m in moves), moves
    assert all(v == fp.PARKED_VALIDITY * fp.FAR_INTERVAL for _, _, v in far[1:]), "peers must keep it between adverts"


def test_far_move_just_inside_and_just_outside():
    schedule = far_schedule()
    schedule.sent(SQUARE, 0.0, 0.0)
    assert schedule.on_footprint(shifted(SQUARE, 0.99), 0.5, False) is None
    assert schedule.on_footprint(shifted(SQUARE, 1.0), 0.6, False) == fp.PARKED_VALIDITY * fp.FAR_INTERVAL


def test_a_far_robot_coming_near_advertises_at_once():
    sent = drive(far_schedule(), 0.65, 10.0, near=lambda t: t >= 5.1)
    assert any(t == 5.2 or abs(t - 5.2) < 1e-9 for t, _, _ in sent), sent   # the first near footprint that moved 0.1 m
    after = [s for s in sent if s[0] > 5.1]
    assert all(v == 0.0 for _, _, v in after) and len(after) >= 20


def test_a_slow_far_robot_beats_every_far_interval_and_is_not_parked():
    sent = drive(far_schedule(), 0.08, 40.0, near=lambda t: False)   # 0.1 m in 1.25 s: moving; 1 m in 12.5 s
    gaps = [b[0] - a[0] for a, b in zip(sent, sent[1:])]
    assert gaps and all(g <= fp.FAR_INTERVAL + 0.5 for g in gaps), gaps
    # the first second is a start from standing (parked, as before); once it moved 0.1 m it is a far driving robot
    assert all(v == fp.PARKED_VALIDITY * fp.FAR_INTERVAL for t, _, v in sent if t > 2.0), "taken for parked while moving"
    assert len([s for s in sent if s[0] > 2.0]) >= 3


def test_far_move_zero_keeps_every_robot_near():
    assert len(drive(fp.AdvertSchedule(2.0, 0.1, 30.0, far_move=0.0), 0.65, 30.0, near=lambda t: False)) >= 150


def test_near_distance_just_inside_and_just_outside():
    peer = shifted(SQUARE, 4.99)
    assert fp.near_any(SQUARE, [peer], 5.0)
    assert not fp.near_any(SQUARE, [shifted(SQUARE, 5.01)], 5.0)
    assert not fp.near_any(SQUARE, [], 5.0)
    assert fp.near_any(SQUARE, [], 0.0), "near_distance 0: every advert precise"


@pytest.mark.parametrize("kwargs, error", [
    (dict(near_distance=100.0), None), (dict(near_distance=100.1), "footprint_near_distance = 100.1"),
    (dict(near_distance=-0.1), "footprint_near_distance = -0.1"),
    (dict(far_move=10.0), None), (dict(far_move=10.1), "footprint_far_move = 10.1"),
    (dict(far_move=0.1), None), (dict(far_move=0.09), "footprint_far_move = 0.09"),
    (dict(far_move=0.05, near_distance=0.0), None),
])
def test_the_node_checks_near_distance_and_far_move(kwargs, error):
    from coaty_bridge.footprint_config import FootprintConfig
    if error is None:
        config = FootprintConfig(**kwargs)
        assert config.schedule().far_move == (config.far_move if config.near_distance > 0 else 0.0)
    else:
        with pytest.raises(ValueError, match=error.replace(".", r"\.")):
            FootprintConfig(**kwargs)
