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
