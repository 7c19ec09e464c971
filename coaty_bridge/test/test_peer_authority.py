"""Bounded authority of a peer (issue 27, attacks 1, 2, 7, 8, 10) through a real mosquitto.

Each robot is the real CoatyBridgeClient (own MQTT connection) wired to the real SharingHandler,
as the two nodes wire them (from_fleet -> on_external, to_fleet -> publish, the held list ->
Discover answers, stamped when it is listed as the node does). The attacker is a plain MQTT client
on the same broker. After every attack: the good obstacles are held unchanged on every robot and
a fresh valid obstacle still gets through. The handler's clock is a settable one that starts at
the wall clock (the stamps of the peers' messages are compared with it), so leases and replays
are judged without waiting.
"""
import json
import threading
import uuid as uuidlib

import pytest

from coaty_bridge import codec, footprint as fp
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.codec import ObstacleUpdate
from coaty_bridge.topics import Topic

from handler_link import to_obstacle, to_update  # (puts sharing_handler_py on the path)
from sharing_handler_py.logic import SharingHandler  # noqa: E402
from sharing_handler_py.validation import Geometry  # noqa: E402
from sharing_msgs import obstacle_rules  # noqa: E402

pytestmark = pytest.mark.broker

GRID = Geometry(0.05, -10.0, -5.0, 400, 200)   # 20 m x 10 m
DURATION = 60
SKEW = 5.0
OT = codec.DEFAULT_OBJECT_TYPE
ATTACKER = "0bad0bad-0000-4000-8000-000000000000"   # the attacker's sourceId
# the good obstacles (robot, rectangle): 10.6 m apart at the ends of the map, one in the middle
GOOD = [("robot_0", [-9.5, -4.5, -9.0, -4.0]), ("robot_0", [1.6, -4.5, 2.1, -4.0]),
        ("robot_1", [6.0, 3.0, 6.5, 3.5])]


class Clock:
    def __init__(self):
        import time
        self.now = time.time()

    def __call__(self):
        return self.now


class Robot:
    """Handler + bridge client of one robot."""

    def __init__(self, name, broker_url, clock, **bridge):
        self.name, self.clock = name, clock
        self.lock = threading.RLock()   # the node's lock: the handler is called from the MQTT thread
        self.handler = SharingHandler(name, clock, DURATION, on_to_layer=lambda o: None,
                                      on_to_fleet=self._to_fleet, on_expired=lambda u: None, geometry=GRID,
                                      on_change=self._listed, max_clock_skew=SKEW)
        self.client = CoatyBridgeClient(BridgeConfig(name, broker_url=broker_url, **bridge), self._from_fleet,
                                        on_footprint=lambda f, t: self.footprints.append(f))
        self.footprints = []

    def _to_fleet(self, obstacle):
        self.client.publish_obstacle(to_update(obstacle))

    def _from_fleet(self, update, topic):
        with self.lock:
            self.handler.on_external(to_obstacle(update))

    def _listed(self):
        # the node stamps its list with the time it is published (SharedObstacleArray.header.stamp)
        self.client.set_current_obstacles([to_update(h.to_obstacle().replace(stamp=self.clock()))
                                           for h in self.handler.obstacles()])

    def add(self, rectangle):
        with self.lock:
            return self.handler.add_manual(rectangle).uuid

    def held(self):
        """What must not change: uuid -> (source, rectangle, cells)."""
        with self.lock:
            return {h.uuid: (h.source, h.rectangle, h.cells) for h in self.handler.obstacles()}

    def counter(self, name):
        with self.lock:
            return self.handler.counters[name]

    def dropped(self, counter):
        """A handler drop counter plus the bridge's of the same reason: the caps the bridge checks
        before expanding a message (extent, cells; issue 27 attack 4) drop it there first."""
        bridge = self.client.counters().get(counter.replace("dropped_", "dropped.", 1), 0) \
            if counter.startswith("dropped_") else 0
        return self.counter(counter) + bridge

    def remaining(self, uuid):
        with self.lock:
            return self.handler.get(uuid).remaining

    def expire(self):
        with self.lock:
            return self.handler.expire()


@pytest.fixture
def fleet(broker, observer, wait_for):
    clock = Clock()
    robots = []

    def join(name, **bridge):
        robot = Robot(name, broker.url, clock, **bridge)
        robots.append(robot)
        robot.client.start()
        wait_for(lambda: any(robot.client.identity_id in t for t, _ in observer.on("/DSC/")),
                 what="%s subscribed" % name)
        return robot

    class Fleet:
        pass
    f = Fleet()
    f.clock, f.join, f.robots = clock, join, robots
    yield f
    for robot in robots:
        robot.client.stop(timeout=0.5)


def _share_good(fleet, wait_for):
    """robot_0 and robot_1 share the GOOD obstacles; returns their uuids once both hold all."""
    by_name = {r.name: r for r in fleet.robots}
    uuids = [by_name[name].add(rect) for name, rect in GOOD]
    for robot in fleet.robots:
        wait_for(lambda: set(uuids) <= set(robot.held()), what="%s holds the good obstacles" % robot.name)
    return uuids


def _attack(observer, update, source_id=ATTACKER, **raw):
    """Publishes one obstacle Advertise as the attacker; ``raw`` overrides wire fields."""
    obj = codec.obstacle_to_object(update, OT)
    obj.update(raw)
    observer.publish(str(Topic("fleet", "ADV", source_id, object_type=OT)), json.dumps({"object": obj}).encode())


def evil(clock, **fields):
    values = dict(uuid="00000000-0000-4000-8000-0000000000ee", source="robot_9", version=1, stamp=clock(),
                  frame_id="map", deadline=60, rectangle=(-0.5, -0.5, 0.5, 0.5), resolution=GRID.resolution,
                  origin_x=GRID.origin_x, origin_y=GRID.origin_y, size_x=GRID.size_x, size_y=GRID.size_y,
                  marked=(40200,), cleared=())
    values.update(fields)
    return ObstacleUpdate(**values)


def _fresh_obstacle_still_reaches_everyone(fleet, wait_for, x):
    uuid = fleet.robots[0].add([x, 0.0, x + 0.3, 0.3])
    for robot in fleet.robots:
        wait_for(lambda: uuid in robot.held(), what="%s holds the fresh obstacle" % robot.name)


# --------------------------------------------------------------------------------- attack 1

ATTACKS_1 = {
    # the message: whole-map rectangle, version 2^53-1, deadline 2^32-1
    "whole_map": (dict(rectangle=(-10.0, -5.0, 10.0, 5.0), version=obstacle_rules.MAX_VERSION,
                       deadline=obstacle_rules.MAX_UINT32), "dropped_oversized_rectangle"),
    "huge_version": (dict(version=obstacle_rules.MAX_VERSION), "dropped_implausible_version"),
    # more cells than any obstacle may hold, and than its 1 m square holds (issue 43: refused on that first)
    "too_many_cells": (dict(marked=tuple(range(45000))), "dropped_more_cells_than_rectangle"),
    # within every per-message cap, 10 m wide between the good ones: merge bait, taken as an obstacle of
    # its own that absorbs nothing (issue 43: only obstacles first shared by the same source merge)
    "merge_bait": (dict(rectangle=(-8.7, -4.5, 1.3, 4.5), marked=(40200,)), "updates_in"),
}


@pytest.mark.parametrize("attack", sorted(ATTACKS_1))
def test_attack_1_one_message_cannot_take_the_fleets_obstacles(fleet, observer, wait_for, attack):
    robots = [fleet.join("robot_0"), fleet.join("robot_1")]
    good = _share_good(fleet, wait_for)
    before = [r.held() for r in robots]
    fields, counter = ATTACKS_1[attack]
    _attack(observer, evil(fleet.clock, **fields))
    for robot in robots:
        wait_for(lambda: robot.dropped(counter) >= 1, what="%s counts %s" % (robot.name, counter))
    for robot, held in zip(robots, before):
        now = robot.held()
        assert {u: now[u] for u in good} == {u: held[u] for u in good}, "a good obstacle was lost or changed"
        assert all(max(r.max_x - r.min_x, r.max_y - r.min_y) <= 10.0 for _s, r, _c in now.values())
        # the crash of the issue: add_obstacle near the attack still answers with an obstacle
        assert robot.add([-9.2, 4.0, -9.0, 4.2])
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 4.0)


def test_attack_1_through_a_discover_answer(fleet, observer, wait_for):
    """A late joiner asks its peers for their obstacles; the attacker answers its Discover too."""
    fleet.join("robot_0")
    fleet.join("robot_1")
    good = _share_good(fleet, wait_for)
    answered = []
    record = observer._client.on_message

    def answer(client, userdata, message):
        record(client, userdata, message)
        parts = message.topic.split("/")
        if len(parts) == 6 and parts[3] == "DSC" and parts[4] not in answered:
            answered.append(parts[4])
            topic = "coaty/3/fleet/RSV/%s/%s" % (ATTACKER, parts[5])
            for fields, _counter in (ATTACKS_1["whole_map"], ATTACKS_1["huge_version"]):
                update = evil(fleet.clock, uuid=str(uuidlib.uuid4()), **fields)
                client.publish(topic, codec.resolve_payload(codec.obstacle_to_object(update, OT)))
    observer._client.on_message = answer
    late = fleet.join("robot_2")
    wait_for(lambda: set(good) <= set(late.held()), what="robot_2 learns the good obstacles")
    wait_for(lambda: late.dropped("dropped_oversized_rectangle") >= 1
             and late.counter("dropped_implausible_version") >= 1, what="robot_2 drops both answers")
    assert set(late.held()) == set(good)
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 4.5)


# --------------------------------------------------------------------------------- attack 2

def test_attack_2_a_peer_cannot_make_a_lease_longer(fleet, observer, wait_for):
    robots = [fleet.join("robot_0"), fleet.join("robot_1")]
    good = _share_good(fleet, wait_for)
    target = good[2]                                 # robot_1's; robot_0 holds it from the fleet
    before = robots[0].held()[target]
    cell = before[2][0]
    # an observation (a cell it already has) claiming 2^32-1 s: cut to our 60 s
    _attack(observer, evil(fleet.clock, uuid=target, source="robot_9", version=2, marked=(cell,),
                           rectangle=tuple(before[1].as_list()), deadline=obstacle_rules.MAX_UINT32))
    wait_for(lambda: robots[0].counter("capped_deadlines") >= 1, what="the deadline cut")
    assert robots[0].remaining(target) <= DURATION
    # 20 s later a message that does not mark cells claims 2^32-1 s again: the earlier expiry stays
    fleet.clock.now += 20
    left = robots[0].remaining(target)
    _attack(observer, evil(fleet.clock, uuid=target, source="robot_9", version=3, marked=(), cleared=(cell,),
                           rectangle=tuple(before[1].as_list()), deadline=obstacle_rules.MAX_UINT32))
    wait_for(lambda: robots[0].counter("capped_deadlines") >= 2, what="the second message")
    assert robots[0].remaining(target) == pytest.approx(left)
    for robot in robots:
        # the cell it cleared is gone, the rest as before (issue 43: a clear never changes the lease)
        wait_for(lambda: robot.held()[target] == (before[0], before[1], before[2][1:]), what="the clear applied")
    fleet.clock.now += left
    assert target in robots[0].expire()
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 5.0)


# --------------------------------------------------------------------------------- attack 7

def test_attack_7_a_replayed_message_does_not_bring_an_expired_obstacle_back(fleet, observer, wait_for):
    robots = [fleet.join("robot_0"), fleet.join("robot_1")]
    uuid = robots[0].add([-3.0, -3.0, -2.5, -2.5])
    wait_for(lambda: uuid in robots[1].held(), what="robot_1 holds it")

    def captured():
        return [(t, p) for t, p in list(observer.messages) if "/ADV::%s/" % OT in t and uuid.encode() in p]
    wait_for(captured, what="the attacker captures robot_0's Advertise")
    fleet.clock.now += DURATION
    for robot in robots:
        assert uuid in robot.expire()
    fleet.clock.now += DURATION + 2 * SKEW + 1     # the expired uuid is forgotten by now
    for robot in robots:
        robot.expire()
        assert not robot.handler.is_tombstoned(uuid)
    for topic, payload in captured():              # re-sent as captured, under robot_0's sourceId
        observer.publish(topic, payload)
    wait_for(lambda: robots[1].counter("dropped_stale_stamp") >= 1, what="robot_1 drops the replay")
    assert uuid not in robots[1].held() and uuid not in robots[0].held()
    # a message from the far future is no better
    _attack(observer, evil(fleet.clock, stamp=fleet.clock() + 3600))
    wait_for(lambda: robots[1].counter("dropped_future_stamp") >= 1, what="robot_1 drops the future stamp")
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 5.5)


# --------------------------------------------------------------------------------- attack 8

@pytest.mark.parametrize("field,counter", [("source", "dropped.invalid_name"), ("frameId", "dropped.out_of_range")])
def test_attack_8_lone_surrogates_are_refused_at_validation(fleet, observer, wait_for, caplog, field, counter):
    import logging
    robots = [fleet.join("robot_0"), fleet.join("robot_1")]
    good = _share_good(fleet, wait_for)
    bad = evil(fleet.clock)
    with caplog.at_level(logging.WARNING, logger="coaty_bridge"):
        _attack(observer, bad, **{field: ("robot_9" if field == "source" else "map") + "\ud800"})
        for robot in robots:
            wait_for(lambda: robot.client.counters().get(counter, 0) >= 1, what="%s counts %s" % (robot.name, counter))
        # the MQTT threads count before they log: wait for both lines
        wait_for(lambda: caplog.text.count("lone UTF-16 surrogate U+D800") >= 2, what="one warning per robot")
    assert "Traceback" not in caplog.text
    for robot in robots:
        assert set(robot.held()) == set(good)
    _fresh_obstacle_still_reaches_everyone(fleet, wait_for, 6.0)


# -------------------------------------------------------------------------------- attack 10

def _advert(observer, robot, points, source_id=ATTACKER):
    footprint = fp.RobotFootprint(robot=robot, stamp=1700000000.5, frame_id="map", points=points)
    observer.publish(str(Topic("fleet", "ADV", source_id, object_type=fp.DEFAULT_FOOTPRINT_OBJECT_TYPE)),
                     fp.footprint_payload(footprint, str(uuidlib.uuid4())))


SMALL = ((1.0, 1.0), (1.6, 1.0), (1.6, 1.6), (1.0, 1.6))
HUGE = ((0.0, 0.0), (35.0, 0.0), (35.0, 35.0), (0.0, 35.0))


def test_attack_10_a_building_sized_footprint_is_not_a_robot(fleet, observer, wait_for):
    robot = fleet.join("robot_0", footprint_area_size=0)
    _advert(observer, "robot_1", HUGE)
    wait_for(lambda: robot.client.counters().get("dropped.footprint_too_large"), what="the 35 m advert dropped")
    _advert(observer, "robot_1", SMALL)
    wait_for(lambda: robot.footprints, what="a robot-sized advert")
    assert [f.robot for f in robot.footprints] == ["robot_1"] and robot.footprints[0].points == SMALL



def test_attack_10_the_extent_cap_holds_on_the_longer_side_just_outside_and_just_inside(fleet, observer, wait_for):
    """max_footprint_extent (5 m by default) bounds the longer side of the bounding box: 0.5 x 5.05 m and
    5.05 x 0.5 m are dropped, 0.5 x 4.95 m is taken. The taken one is sent last, so when it has arrived the two
    before it have been handled (one sender, one connection: in order)."""
    assert fp.DEFAULT_MAX_FOOTPRINT_EXTENT == 5.0
    robot = fleet.join("robot_0", footprint_area_size=0)

    def box(width, height):
        return ((1.0, 1.0), (1.0 + width, 1.0), (1.0 + width, 1.0 + height), (1.0, 1.0 + height))
    _advert(observer, "robot_1", box(0.5, 5.05))
    _advert(observer, "robot_2", box(5.05, 0.5))
    _advert(observer, "robot_3", box(0.5, 4.95))
    wait_for(lambda: robot.footprints, what="the 0.5 x 4.95 m advert")
    assert [f.robot for f in robot.footprints] == ["robot_3"]
    assert robot.client.counters().get("dropped.footprint_too_large") == 2

def test_attack_10_only_known_robots_footprints_are_taken(fleet, observer, wait_for, caplog):
    import logging
    robot = fleet.join("robot_0", footprint_area_size=0, known_robots=["robot_0", "robot_1"])
    with caplog.at_level(logging.WARNING, logger="coaty_bridge"):
        _advert(observer, "robot_77", SMALL)
        wait_for(lambda: robot.client.counters().get("dropped.unknown_robot"), what="the made-up robot dropped")
        wait_for(lambda: "robot_77" in caplog.text, what="the warning")   # counted before it is logged
    assert ATTACKER in caplog.text
    _advert(observer, "robot_1", SMALL)
    wait_for(lambda: robot.footprints, what="the known robot's advert")
    assert [f.robot for f in robot.footprints] == ["robot_1"]


def test_footprint_policy_parameters_are_checked():
    with pytest.raises(ValueError, match="max_footprint_extent"):
        BridgeConfig("robot_0", max_footprint_extent=100.0)
    with pytest.raises(ValueError, match="known_robots"):
        BridgeConfig("robot_0", known_robots="robot_1")
    with pytest.raises(ValueError, match="known_robots"):
        BridgeConfig("robot_0", known_robots=["a/b"])
    assert BridgeConfig("robot_0", known_robots=["robot_1"]).known_robots == ("robot_1",)


@pytest.mark.parametrize("field", ["robot", "frame_id"])
def test_a_footprint_with_a_lone_surrogate_is_refused_at_validation(field):
    from coaty_bridge.errors import OutOfRangeError
    values = dict(robot="robot_1", stamp=1700000000.5, frame_id="map", points=SMALL)
    values[field] += "\udc00"
    with pytest.raises(OutOfRangeError, match="lone UTF-16 surrogate U\\+DC00"):
        fp.RobotFootprint(**values)
