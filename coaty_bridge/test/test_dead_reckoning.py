"""Dead-reckoned footprint adverts (issue 46: footprint adverts scale with what a robot needs to hear).

A driving robot near others advertised every footprint_min_move (0.1 m: 5 adverts a second at 0.65 m/s, 279 kB of the
475 kB a robot received per minute in the 100-robot bench with a quarter driving). Now its adverts state its velocity,
receivers move the footprint on, and the robot advertises again only when its true footprint leaves the believed one by
min_move, or every footprint_driving_interval as a heartbeat. What must not change: the peers' view of the robot lags by
at most min_move (plus one footprint's travel), through a drive, a turn and a stop. Pure tests: the schedule, the wire
form and the receiver's table, no broker."""
import math

import pytest

from coaty_bridge import footprint as fp

SQUARE = ((0.0, 0.0), (0.6, 0.0), (0.6, 0.6), (0.0, 0.6))
TOPIC_RATE, TICK_RATE, MIN_MOVE, INTERVAL = 5.0, 2.0, 0.1, 2.0


def placed(x, y, yaw):
    """SQUARE turned by ``yaw`` about its centre, its centre at (x, y)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return tuple((x + c * (px - 0.3) - s * (py - 0.3), y + s * (px - 0.3) + c * (py - 0.3)) for px, py in SQUARE)


def drive_turn_stop(t):
    """10 s east at 0.65 m/s, a quarter turn at the same speed over 2 s, 10 s north, then standing."""
    v = 0.65
    if t <= 10.0:
        return placed(v * t, 0.0, 0.0)
    if t <= 12.0:
        r, a = v * 2.0 / (math.pi / 2), (t - 10.0) / 2.0 * (math.pi / 2)
        return placed(v * 10.0 + r * math.sin(a), r * (1 - math.cos(a)), a)
    r = v * 2.0 / (math.pi / 2)
    return placed(v * 10.0 + r, r + v * (min(t, 22.0) - 12.0), math.pi / 2)


def simulate(schedule, path, seconds):
    """Runs ``schedule`` over ``path`` (footprints at TOPIC_RATE, ticks at TICK_RATE); every advert goes over the wire
    (encoded and decoded) into a receiver's table. Returns (adverts sent, the largest gap between the receiver's belief
    and the true footprint seen at a footprint before the sender's decision, the largest after it)."""
    clock = [0.0]
    table = fp.FleetRobotTable("robot_1", 3.0, lambda: clock[0])
    sent, before, after = [], 0.0, 0.0
    for k in range(int(round(seconds * TOPIC_RATE)) + 1):
        now = clock[0] = k / TOPIC_RATE
        points = path(now)
        heard = table.robots()
        if heard:
            before = max(before, fp.largest_move(heard[0].points_at(now), points))
        ticks = abs(now * TICK_RATE - round(now * TICK_RATE)) < 1e-9
        for decide in (schedule.on_footprint, schedule.on_tick if ticks else None):
            valid_for = decide(points, now) if decide else None   # one after the other, as the node's threads
            if valid_for is None:
                continue
            advert = fp.RobotFootprint(robot="robot_0", stamp=now, frame_id="map", points=points, valid_for=valid_for,
                                       velocity=schedule.advert_velocity)
            obj = fp.footprint_to_object(advert, "8d6a3c3e-9c1e-4f7e-a5d4-2b1f0e9d8c7b")
            table.heard(fp.footprint_from_object(obj))
            schedule.sent(points, now, valid_for)
            sent.append((now, valid_for, advert.velocity))
        after = max(after, fp.largest_move(table.robots()[0].points_at(now), points))
    return sent, before, after


def schedule(driving_interval=INTERVAL, **kwargs):
    return fp.AdvertSchedule(TICK_RATE, MIN_MOVE, 30.0, driving_interval=driving_interval, **kwargs)


def test_a_straight_drive_costs_a_heartbeat_and_the_peers_view_still_lags_by_min_move():
    dead_reckoned, before, after = simulate(schedule(), drive_turn_stop, 40.0)
    precise, before_precise, after_precise = simulate(schedule(0.0), drive_turn_stop, 40.0)
    one_footprint = 0.65 / TOPIC_RATE
    # the guarantee the layers rely on, unchanged: what a peer believes lags by at most min_move (after the
    # sender's decision), and by min_move plus one footprint's travel just before it
    assert after < MIN_MOVE and after_precise < MIN_MOVE, (after, after_precise)
    assert before <= MIN_MOVE + one_footprint + 1e-6, before
    driving = [s for s in dead_reckoned if s[0] <= 22.0]
    driving_precise = [s for s in precise if s[0] <= 22.0]
    assert len(driving_precise) >= 100, len(driving_precise)   # every 0.1 m over 14 m
    assert len(driving) <= 30, "%d dead-reckoned adverts over 22 s of driving (%d precise)" % (
        len(driving), len(driving_precise))
    straight = [v for t, _, v in dead_reckoned if 2.0 <= t <= 9.5]
    assert straight and all(abs(vx - 0.65) < 0.01 and abs(vy) < 0.01 for vx, vy in straight), straight


def test_without_extrapolating_receivers_the_view_would_lag_a_whole_interval():
    """The receiver's side is what makes the heartbeat enough: the same adverts held still lag by metres."""
    clock = [0.0]
    table = fp.FleetRobotTable("robot_1", 3.0, lambda: clock[0])
    advert = fp.RobotFootprint(robot="robot_0", stamp=0.0, frame_id="map", points=SQUARE,
                               valid_for=fp.PARKED_VALIDITY * INTERVAL, velocity=(0.65, 0.0))
    table.heard(advert)
    clock[0] = 1.9
    held = table.robots()[0]
    assert fp.largest_move(held.footprint.points, placed(0.3 + 0.65 * 1.9, 0.3, 0.0)) > 1.2
    assert fp.largest_move(held.points_at(1.9), placed(0.3 + 0.65 * 1.9, 0.3, 0.0)) < 1e-9


def test_far_from_every_robot_a_straight_drive_costs_a_far_heartbeat_and_the_view_lags_by_far_move():
    """Far adverts are dead-reckoned too: along a straight aisle a far driver beat every far_move (1 m: every 1.5 s at
    0.65 m/s), more often than a near one with dead reckoning; now every FAR_INTERVAL (10 s), and a turn or a stop at
    once. What a peer believes lags by at most far_move plus one footprint's travel."""
    def far_simulate(driving_interval):
        s = schedule(driving_interval, far_move=1.0)
        on_footprint, on_tick = s.on_footprint, s.on_tick
        s.on_footprint = lambda points, now, near=True: on_footprint(points, now, False)
        s.on_tick = lambda points, now, near=True: on_tick(points, now, False)
        return simulate(s, drive_turn_stop, 40.0)
    dead_reckoned, _, after = far_simulate(INTERVAL)
    every_metre, _, _ = far_simulate(0.0)
    driving = [a for a in dead_reckoned if 1.0 <= a[0] <= 22.0]
    assert after < 1.0, after
    assert len([a for a in every_metre if 1.0 <= a[0] <= 22.0]) >= 12
    assert len(driving) <= 6, "%d far adverts over 21 s of driving: %s" % (len(driving), driving)
    assert all(v == fp.PARKED_VALIDITY * fp.FAR_INTERVAL for _, v, _ in driving)


def test_a_stop_is_advertised_within_one_min_move_and_then_the_robot_parks():
    sent, _, after = simulate(schedule(), drive_turn_stop, 40.0)
    assert after < MIN_MOVE
    stopped = [s for s in sent if 22.0 < s[0] <= 23.0]
    assert stopped and stopped[-1][2] == (0.0, 0.0), "no advert without velocity within 1 s of the stop: %s" % stopped
    parked = [s for s in sent if s[0] > 22.0 and s[1] == fp.PARKED_VALIDITY * 30.0]
    assert parked and parked[0][0] <= 25.0, "not parked 3 s after the stop: %s" % sent[-5:]


def test_heartbeats_come_every_driving_interval_just_inside_and_not_before():
    sent, _, _ = simulate(schedule(), lambda t: placed(0.65 * t, 0.0, 0.0), 30.0)
    gaps = [b[0] - a[0] for a, b in zip(sent[3:], sent[4:])]
    # the tick comes every 0.5 s: a heartbeat at 2.0 s (a tick's quarter early still counts), never at 1.5 s
    assert gaps and all(INTERVAL - 0.25 / TICK_RATE <= g <= INTERVAL + 1.0 / TICK_RATE for g in gaps), gaps
    assert all(v == fp.PARKED_VALIDITY * INTERVAL for _, v, _ in sent[1:]), "receivers must keep it between adverts"


def test_a_speed_just_below_one_min_move_per_interval_states_no_velocity():
    slowest = MIN_MOVE / INTERVAL                      # 0.05 m/s: drifts one min_move per interval
    for speed, stated in ((slowest * 0.98, False), (slowest * 1.02, True)):
        s = schedule()
        for k in range(20):
            s.on_footprint(placed(speed * k / TOPIC_RATE, 0.0, 0.0), k / TOPIC_RATE)
        s.sent(SQUARE, 0.0, 5.0)
        valid_for = s.on_tick(placed(speed * 4.0, 0.0, 0.0), 4.0)
        assert valid_for is not None
        assert (s.advert_velocity != (0.0, 0.0)) == stated, (speed, s.advert_velocity)


def test_entering_another_area_advertises_at_once():
    s = schedule(area_size=10.0)
    s.on_footprint(placed(9.5, 5.0, 0.0), 0.0)
    s.sent(placed(9.5, 5.0, 0.0), 0.0, 5.0, ("driving", (0.65, 0.0)))
    assert s.on_footprint(placed(9.5 + 0.65 * 0.2, 5.0, 0.0), 0.2) is None       # still in area (0, 0)
    assert s.on_footprint(placed(9.5 + 0.65 * 0.8, 5.0, 0.0), 0.8) is not None   # centroid 10.02: area (1, 0)


def test_receivers_move_an_advert_on_for_at_most_the_senders_interval():
    clock = [10.0]
    table = fp.FleetRobotTable("robot_1", 3.0, lambda: clock[0])
    table.heard(fp.RobotFootprint(robot="robot_0", stamp=10.0, frame_id="map", points=SQUARE,
                                  valid_for=fp.PARKED_VALIDITY * INTERVAL, velocity=(0.5, 0.0)))
    held = table.robots()[0]
    assert held.points_at(9.0) == SQUARE, "never moved back before it was heard"
    assert abs(held.points_at(11.99)[0][0] - 0.5 * 1.99) < 1e-9
    assert abs(held.points_at(12.01)[0][0] - 0.5 * INTERVAL) < 1e-9, "a lost heartbeat must not drive it on"
    still = fp.HeardRobot(fp.RobotFootprint(robot="robot_0", stamp=10.0, frame_id="map", points=SQUARE,
                                            velocity=(0.5, 0.0)), 10.0)
    assert still.points_at(12.0) == SQUARE, "a velocity without validFor promises nothing to move on"


@pytest.mark.parametrize("velocity, error", [
    ((19.99, 0.0), None), ((20.01, 0.0), "faster than 20"), ((0.0, -20.01), "faster than 20"),
    ((float("nan"), 0.0), "not finite"), ("fast", "not \\[vx, vy\\]"), ((1.0,), "not \\[vx, vy\\]"),
    ((True, 0.0), "not a number"),
])
def test_a_bad_velocity_is_refused_by_name(velocity, error):
    obj = fp.footprint_to_object(fp.RobotFootprint(robot="robot_0", stamp=1.0, frame_id="map", points=SQUARE),
                                 "8d6a3c3e-9c1e-4f7e-a5d4-2b1f0e9d8c7b")
    obj["velocity"], obj["validFor"] = velocity, 5.0
    if error is None:
        assert fp.footprint_from_object(obj).velocity == velocity
    else:
        with pytest.raises(fp.CoatyError if hasattr(fp, "CoatyError") else Exception, match=error):
            fp.footprint_from_object(obj)


def test_after_an_advert_with_a_bad_velocity_the_next_good_one_is_taken():
    clock = [10.0]
    table = fp.FleetRobotTable("robot_1", 3.0, lambda: clock[0])
    obj = fp.footprint_to_object(fp.RobotFootprint(robot="robot_0", stamp=10.0, frame_id="map", points=SQUARE,
                                                   valid_for=5.0, velocity=(0.5, 0.0)),
                                 "8d6a3c3e-9c1e-4f7e-a5d4-2b1f0e9d8c7b")
    bad = dict(obj, velocity=[25.0, 0.0])
    with pytest.raises(fp.OutOfRangeError):
        table.heard(fp.footprint_from_object(bad))
    assert table.robots() == []
    assert table.heard(fp.footprint_from_object(obj)) and table.robots()[0].footprint.velocity == (0.5, 0.0)


def test_velocity_is_on_the_wire_only_in_a_dead_reckoned_advert():
    base = dict(robot="robot_0", stamp=1.0, frame_id="map", points=SQUARE)
    oid = "8d6a3c3e-9c1e-4f7e-a5d4-2b1f0e9d8c7b"
    assert "velocity" not in fp.footprint_to_object(fp.RobotFootprint(**base), oid)
    assert "velocity" not in fp.footprint_to_object(fp.RobotFootprint(valid_for=5.0, **base), oid)
    moving = fp.footprint_to_object(fp.RobotFootprint(valid_for=5.0, velocity=(0.6504, -0.1), **base), oid)
    assert moving["velocity"] == [0.65, -0.1]


def test_a_dead_reckoned_advert_is_evidence_for_its_stamp_only():
    """A parked robot's validFor says its pose holds; a driving one's does not (it drives on)."""
    from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
    client = CoatyBridgeClient(BridgeConfig("robot_1", require_evidence=True), lambda *a: None)
    client._note_sighting(fp.RobotFootprint(robot="robot_0", stamp=100.0, frame_id="map", points=SQUARE, reach=4.0,
                                            valid_for=5.0, velocity=(0.65, 0.0)))
    client._note_sighting(fp.RobotFootprint(robot="robot_2", stamp=100.0, frame_id="map", points=SQUARE, reach=4.0,
                                            valid_for=75.0))
    poses = client._poses
    assert poses.covering("robot_0", 104.0) == [], "a driving robot's advert vouched for a pose 4 s later"
    assert poses.covering("robot_2", 104.0), "a parked robot's advert holds for its validFor"


@pytest.mark.parametrize("interval, error", [
    (0.0, None), (240.0, None), (240.1, "footprint_driving_interval = 240.1"),
    (-0.1, "footprint_driving_interval = -0.1"),
])
def test_the_node_checks_the_driving_interval(interval, error):
    """(and its default is the one the scale bench runs with)"""
    from coaty_bridge.footprint_config import FootprintConfig
    assert FootprintConfig().driving_interval == fp.DEFAULT_DRIVING_INTERVAL
    if error is None:
        assert FootprintConfig(driving_interval=interval).schedule(10.0).driving_interval == interval
    else:
        with pytest.raises(ValueError, match=error.replace(".", r"\.")):
            FootprintConfig(driving_interval=interval)
