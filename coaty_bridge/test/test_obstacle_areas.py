"""Obstacle areas (issue 29, fleet traffic): a shared obstacle's monitoring updates go to the robots
around it; its first share, every update that only clears and a renewal before the far copies'
lease runs out go to every robot; a robot entering an area asks for what it missed there.
Real mosquitto, real clients."""
import json
import time
import uuid as uuidlib

import pytest

from coaty_bridge import areas, codec
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.topics import Topic

OT = codec.DEFAULT_OBJECT_TYPE
#: m, the obstacle squares the positions below are laid out for (the default is smaller; the rules are the same)
AREA_M = 10.0
# make_update's rectangle (1, 2)-(3.5, 4): centre (2.25, 3), obstacle area (0, 0) at 10 m
NEAR, FAR = (12.0, 5.0), (45.0, 5.0)


@pytest.fixture
def obstacle_area_m():
    return AREA_M


def versions(client, uuid):
    return sorted({u.version for u in client.received_updates if u.uuid == uuid})


def marking(make_update, first, version, cells, deadline=60):
    return make_update(uuid=first.uuid, version=version, marked=cells, cleared=(), deadline=deadline)


@pytest.mark.broker
def test_monitoring_updates_reach_the_robots_around_the_obstacle_and_first_shares_and_clears_every_robot(
        make_client, make_update, wait_for):
    source, near, far = make_client("robot_0"), make_client("robot_1"), make_client("robot_2")
    unplaced = make_client("robot_3")   # no footprint yet: hears every area
    wait_for(lambda: all(c.subscribed for c in (source, near, far, unplaced)), what="all connected")
    source.note_own_position((5.0, 5.0))
    near.note_own_position(NEAR)
    far.note_own_position(FAR)

    first = make_update(version=1)
    assert source.publish_obstacle(first)
    wait_for(lambda: versions(near, first.uuid) == [1] and versions(far, first.uuid) == [1]
             and versions(unplaced, first.uuid) == [1], what="the first share on every robot")

    # a monitoring update (it marks): only the robots around the obstacle's area hear it. Sent until
    # the near robot has it: its subscription to the area may still be on its way to the broker.
    second = marking(make_update, first, 2, (880250,))
    wait_for(lambda: source.publish_obstacle(second) and 2 in versions(near, first.uuid), what="v2 near")
    wait_for(lambda: 2 in versions(unplaced, first.uuid), what="v2 at the robot without a position")
    time.sleep(0.3)
    assert versions(far, first.uuid) == [1], "a monitoring update reached a robot 40 m away"
    assert source.counters()["published_to_area"] >= 1 and source.counters()["published_fleet_wide"] == 1

    # an update that only clears may end the obstacle: every robot
    third = make_update(uuid=first.uuid, version=3, marked=(), cleared=(880221,), deadline=50)
    assert source.publish_obstacle(third)
    wait_for(lambda: 3 in versions(far, first.uuid) and 3 in versions(near, first.uuid), what="the clear everywhere")

    # the far robot drives next to the obstacle: it asks the areas it enters for what it missed
    far.note_own_position((5.0, 15.0))
    wait_for(lambda: 2 in versions(far, first.uuid), what="the far robot gets v2 on entering the area")
    assert far.counters()["obstacle_area_catchups"] == 1
    assert not [k for c in (source, near, far) for k in c.counters() if k.startswith("dropped.")]


@pytest.mark.broker
def test_without_obstacle_areas_every_update_goes_to_every_robot(make_client, make_update, wait_for):
    source = make_client("robot_0", obstacle_area_size=0)
    far = make_client("robot_2", obstacle_area_size=0)
    wait_for(lambda: source.subscribed and far.subscribed, what="subscribed")
    source.note_own_position((5.0, 5.0))
    far.note_own_position(FAR)
    first = make_update(version=1)
    wait_for(lambda: source.publish_obstacle(first) and versions(far, first.uuid) == [1], what="v1")
    source.publish_obstacle(marking(make_update, first, 2, (880250,)))
    wait_for(lambda: 2 in versions(far, first.uuid), what="v2 at the far robot")
    assert source.counters().get("published_to_area", 0) == 0


@pytest.mark.broker
def test_far_copies_are_renewed_before_their_lease_runs_out(make_client, make_update, wait_for):
    """The robots near the obstacle hold it until its last update's deadline; the far ones until the
    last fleet-wide one's. The robot that made the last update sends it fleet-wide (aged) shortly
    before the far copies would expire, once."""
    now = [1000.0]
    source = make_client("robot_0", clock=lambda: now[0])
    far = make_client("robot_2")
    wait_for(lambda: source.subscribed and far.subscribed, what="subscribed")
    source.note_own_position((5.0, 5.0))
    far.note_own_position(FAR)
    first = make_update(version=1, deadline=20)        # far copies: until 1020
    wait_for(lambda: source.publish_obstacle(first) and versions(far, first.uuid) == [1], what="v1")
    now[0] = 1005.0
    assert source.publish_obstacle(marking(make_update, first, 2, (880250,), deadline=20))  # near: 1025
    assert source.counters()["published_to_area"] == 1
    now[0] = 1010.0
    assert source.renew_due() == 0, "renewed long before the far copies expire"
    now[0] = 1018.0                                     # 2 s (the least margin) before 1020
    assert source.renew_due() == 1
    wait_for(lambda: 2 in versions(far, first.uuid), what="the renewal at the far robot")
    renewal = [u for u in far.received_updates if u.uuid == first.uuid and u.version == 2][0]
    assert renewal.deadline == 7, "aged by the 13 s since it was made: the far copy ends with the near ones"
    now[0] = 1019.0
    assert source.renew_due() == 0, "renewed twice"


@pytest.mark.broker
def test_a_renewal_covered_by_a_fleet_wide_update_is_not_sent(make_client, make_update, wait_for):
    now = [1000.0]
    source = make_client("robot_0", clock=lambda: now[0])
    wait_for(lambda: source.subscribed, what="subscribed")
    source.note_own_position((5.0, 5.0))
    first = make_update(version=1, deadline=20)
    source.publish_obstacle(first)
    now[0] = 1005.0
    source.publish_obstacle(marking(make_update, first, 2, (880250,), deadline=20))
    # a later update the whole fleet heard, lasting as long: nothing to renew
    source.publish_obstacle(make_update(uuid=first.uuid, version=3, marked=(), cleared=(880221,), deadline=20))
    now[0] = 1030.0
    assert source.renew_due() == 0


@pytest.mark.broker
def test_bad_area_traffic_is_counted_and_dropped(make_client, make_update, observer, wait_for):
    robot = make_client("robot_0")
    wait_for(lambda: robot.subscribed and len(observer.on("/DSC/")) >= 1, what="subscribed")
    robot.note_own_position((5.0, 5.0))
    peer = str(uuidlib.uuid4())
    # a Discover naming 65 obstacle areas (a robot asks for the 9 it enters)
    many = [areas.area_object_type(OT, (i, 0)) for i in range(65)]
    observer.publish(str(Topic("fleet", "DSC", peer, correlation_id=str(uuidlib.uuid4()))),
                     json.dumps({"objectTypes": many}))
    # an area Advertise whose object names another area: Coaty requires the topic's objectType
    update = make_update(version=1)
    observer.publish(str(Topic("fleet", "ADV", peer, object_type=OT + ".area_0_0")),
                     codec.advertise_payload(codec.obstacle_to_object(update, OT + ".area_0_1")))
    # Deadvertises that are not lists of UUIDs
    for bad in ({"objectIds": "x"}, {"objectIds": []}, {"objectIds": ["not-a-uuid"]}, {}):
        observer.publish(str(Topic("fleet", "DAD", peer)), json.dumps(bad))
    wait_for(lambda: robot.counters().get("dropped.out_of_range") == 1
             and robot.counters().get("dropped.wrong_type", 0) == 4
             and robot.counters().get("dropped.missing_field") == 1, what="every bad message counted",
             timeout=10.0)
    assert robot.received_updates == []
    # and a good update in the area still arrives
    good = make_update(version=1)
    observer.publish(str(Topic("fleet", "ADV", peer, object_type=OT + ".area_0_0")),
                     codec.advertise_payload(codec.obstacle_to_object(good, OT + ".area_0_0")))
    wait_for(lambda: [u for u in robot.received_updates if u.uuid == good.uuid], what="the good one")


def test_an_area_update_queued_offline_goes_out_aged_under_its_area_objecttype(make_update):
    """Offline, updates queue; sent later, their deadline is aged and the payload made again. It must
    be made under the objectType of the topic it was queued for, or every receiver drops it
    (wrong_type): the broker-restart test of test_partitions.py lost the update that way."""
    now = [1000.0]
    client = CoatyBridgeClient(BridgeConfig("robot_0"), lambda u, t: None, clock=lambda: now[0])  # never started
    client.note_own_position((5.0, 5.0))
    first = make_update(version=1, deadline=60)
    client.publish_obstacle(first)                                    # queued, fleet-wide
    client.publish_obstacle(marking(make_update, first, 2, (880250,), deadline=60))   # queued, to its area
    now[0] += 5.0
    sent = []
    client._send = lambda topic, payload, **kwargs: sent.append((topic, json.loads(payload)))
    client._flush_queue()
    assert [obj["object"]["deadline"] for _, obj in sent] == [55, 55], "not aged: the test shows nothing"
    for topic, obj in sent:
        assert topic.split("/")[3] == "ADV::" + obj["object"]["objectType"], topic
    assert sent[1][1]["object"]["objectType"] == OT + ".area_0_0"
