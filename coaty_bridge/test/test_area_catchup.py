"""Area catch-up (catchup.py): a robot entering obstacle areas asks each area on its own Channel, and only
the robots holding their own updates there hear the request. As a Discover, every robot of the fleet
received every driving robot's request. Real mosquitto, real clients."""
import json
import uuid as uuidlib

import pytest

from coaty_bridge import catchup, codec
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.errors import CoatyError
from coaty_bridge.topics import Topic

OT = codec.DEFAULT_OBJECT_TYPE
#: m, the obstacle squares the positions below are laid out for (the default is smaller; the rules are the same)
AREA_M = 10.0
# make_update's rectangle (1, 2)-(3.5, 4) and cell 880221: obstacle area (0, 0) at 10 m. Others (grid origin
# (-10, -20), 0.05 m, 2000 cells a row), each with a cell inside: area (2, 0), area (4, 4)
OTHER_AREA_RECT, OTHER_AREA_CELL = (25.0, 2.0, 26.0, 3.0), 445 * 2000 + 705
FAR_AREA_RECT, FAR_AREA_CELL = (44.0, 44.0, 45.0, 45.0), 1285 * 2000 + 1085


@pytest.fixture
def obstacle_area_m():
    return AREA_M


def versions(client, uuid):
    return sorted({u.version for u in client.received_updates if u.uuid == uuid})


def answered(observer, client, correlation_id="+"):
    """(uuid, version) of every obstacle in the Resolves ``client`` sent (to one correlation id, or any)."""
    found = []
    for topic, payload in observer.on("/RSV/%s/" % client.identity_id):
        if correlation_id in ("+", topic.rsplit("/", 1)[1]):
            found += [(o["objectId"], o["version"]) for o in [payload["object"]] + payload.get("relatedObjects", [])]
    return found


def seen_published(observer, update):
    """True once the observer got ``update`` from the broker. The sender subscribed to the update's catch-up channel
    before publishing it, on the same connection, so from then on the broker has that subscription (an ordered
    event: a request sent earlier could reach the broker before it)."""
    return any(isinstance(payload, dict) and payload.get("object", {}).get("objectId") == update.uuid
               and payload["object"].get("version") == update.version for _, payload in observer.on("/ADV::" + OT))


def request(observer, area, correlation_id, sender):
    observer.publish(str(Topic("fleet", "CHN", sender, filter=catchup.channel(area))),
                     catchup.request_payload(correlation_id))


@pytest.mark.broker
def test_a_robot_entering_an_area_catches_up_from_the_robots_holding_updates_there_and_no_other_hears_it(
        make_client, make_update, observer, wait_for):
    source, far, bystander = make_client("robot_0"), make_client("robot_2"), make_client("robot_3")
    wait_for(lambda: all(c.subscribed for c in (source, far, bystander)), what="all connected")
    source.note_own_position((5.0, 5.0))
    far.note_own_position((45.0, 5.0))
    bystander.note_own_position((45.0, 45.0))
    first = make_update(version=1)
    assert source.publish_obstacle(first)
    # the bystander holds an update of its own, far from where robot_2 goes: it observes that area only
    assert bystander.publish_obstacle(make_update(source="robot_3", rectangle=FAR_AREA_RECT,
                                                     marked=(FAR_AREA_CELL,), cleared=()))
    wait_for(lambda: versions(far, first.uuid) == [1], what="the first share at the far robot")
    second = make_update(uuid=first.uuid, version=2, marked=(880250,), cleared=())
    assert source.publish_obstacle(second)   # to area (0, 0) only
    far_id = far.identity_id
    discovers_before = len([t for t, _ in observer.on("/DSC/") if far_id in t])

    far.note_own_position((5.0, 15.0))        # 3 x 3 areas around (0, 1): nine new ones, (0, 0) among them
    wait_for(lambda: len([t for t, _ in observer.on("CHN:" + catchup.CHANNEL) if far_id in t]) == 9,
             what="a request to each of the nine areas")
    # (v2 may also have reached it before its subscriptions moved: the answer itself is what shows the catch-up)
    wait_for(lambda: (first.uuid, 2) in answered(observer, source), what="robot_0's answer with v2")
    wait_for(lambda: 2 in versions(far, first.uuid), what="v2 at the robot that entered the area")
    assert len([t for t, _ in observer.on("/DSC/") if far_id in t]) == discovers_before, \
        "the catch-up went out as a fleet-wide Discover"
    wait_for(lambda: source.counters().get("catchups_answered") == 1, what="robot_0 answered once")
    assert far.counters()["catchup_requests_sent"] == 9
    assert not [k for k in bystander.counters() if "catchup" in k], \
        "a robot with no update in the areas asked heard the request: %s" % bystander.counters()
    assert not [k for c in (source, far, bystander) for k in c.counters() if k.startswith("dropped.")]


@pytest.mark.broker
def test_a_robot_coming_back_to_an_area_gets_only_what_was_sent_there_since_it_left(make_client, make_update, observer,
                                                                                      wait_for):
    now = [1000.0]
    source = make_client("robot_0", clock=lambda: now[0])
    driver = make_client("robot_2", clock=lambda: now[0])
    newcomer = make_client("robot_3", clock=lambda: now[0])
    wait_for(lambda: all(c.subscribed for c in (source, driver, newcomer)), what="all connected")
    source.note_own_position((5.0, 5.0))
    driver.note_own_position((5.0, 5.0))          # hears area (0, 0)
    newcomer.note_own_position((45.0, 45.0))
    first = make_update(version=1, deadline=600)      # all alive throughout
    assert source.publish_obstacle(first)
    before = make_update(uuid=first.uuid, version=2, marked=(880250,), cleared=(), deadline=600)
    assert source.publish_obstacle(before)        # area (0, 0): the driver hears it
    wait_for(lambda: 2 in versions(driver, first.uuid), what="v2 at the driver")
    now[0] = 1010.0
    driver.note_own_position((45.0, 5.0))         # leaves area (0, 0)
    now[0] = 1050.0
    since = make_update(uuid=first.uuid, version=3, marked=(880260,), cleared=(), deadline=600)
    assert source.publish_obstacle(since)         # while the driver is away
    wait_for(lambda: seen_published(observer, since), what="v3 published")
    now[0] = 1100.0
    driver.note_own_position((5.0, 5.0))          # back: it missed area (0, 0) for 90 s
    wait_for(lambda: [p for t, p in observer.on("CHN:" + catchup.channel((0, 0))) if driver.identity_id in t],
             what="the driver's request for area (0, 0)")
    asked = [p for t, p in observer.on("CHN:" + catchup.channel((0, 0))) if driver.identity_id in t]
    assert asked[-1]["object"]["missedFor"] == 90.0
    wait_for(lambda: answered(observer, source, asked[-1]["object"]["objectId"]), what="robot_0's answer")
    assert answered(observer, source, asked[-1]["object"]["objectId"]) == [(first.uuid, 3)]
    # a robot that never heard the area gets everything alive there
    newcomer.note_own_position((5.0, 5.0))
    wait_for(lambda: [p for t, p in observer.on("CHN:" + catchup.channel((0, 0))) if newcomer.identity_id in t],
             what="the newcomer's request")
    fresh = [p for t, p in observer.on("CHN:" + catchup.channel((0, 0))) if newcomer.identity_id in t][-1]
    assert "missedFor" not in fresh["object"]
    wait_for(lambda: answered(observer, source, fresh["object"]["objectId"]), what="robot_0's answer to the newcomer")
    assert answered(observer, source, fresh["object"]["objectId"]) == [(first.uuid, 1), (first.uuid, 2),
                                                                       (first.uuid, 3)]
    assert driver.counters()["catchup_requests_since_left"] >= 1


@pytest.mark.parametrize("sent_at, answered_", [(1005.0, True), (1004.9, False), (1100.0, True)])
def test_an_update_sent_within_the_margin_before_the_robot_left_is_answered(sent_at, answered_):
    # left 90 s before the request at 1100: what was sent from 1010 - MISSED_FOR_MARGIN (5 s) on may have been under way
    assert catchup.answered_since(sent_at, 1100.0, 90.0) is answered_
    assert catchup.answered_since(sent_at, 1100.0, None)


@pytest.mark.parametrize("missed_for, error", [
    (0, None), (catchup.MAX_MISSED_FOR, None), (-0.1, "out_of_range"), (catchup.MAX_MISSED_FOR + 1, "out_of_range"),
    ("90", "wrong_type"), (True, "wrong_type"), ([90], "wrong_type")])
def test_a_request_says_how_long_it_missed_the_area_within_bounds(missed_for, error):
    correlation_id = str(uuidlib.uuid4())
    data = json.loads(catchup.request_payload(correlation_id))
    data["object"]["missedFor"] = missed_for
    if error is None:
        assert catchup.decode_request(data) == (correlation_id, float(missed_for))
    else:
        with pytest.raises(CoatyError) as raised:
            catchup.decode_request(data)
        assert raised.value.reason == error and "missedFor" in str(raised.value)


@pytest.mark.broker
def test_a_robot_stops_observing_an_area_once_its_updates_there_have_expired(make_client, make_update, observer,
                                                                             wait_for):
    now = [1000.0]
    source = make_client("robot_0", clock=lambda: now[0])
    wait_for(lambda: source.subscribed, what="subscribed")
    source.note_own_position((5.0, 5.0))
    assert source.publish_obstacle(make_update(version=1, deadline=20))                    # area (0, 0)
    lasting = make_update(version=1, deadline=600, rectangle=OTHER_AREA_RECT, marked=(OTHER_AREA_CELL,),
                          cleared=())                                                           # area (2, 0)
    assert source.publish_obstacle(lasting)
    wait_for(lambda: seen_published(observer, lasting), what="both published (their channels observed)")
    now[0] = 1030.0                                                # the first one has expired everywhere
    asker = str(uuidlib.uuid4())
    c1, c2, c3 = (str(uuidlib.uuid4()) for _ in range(3))
    request(observer, (0, 0), c1, asker)
    wait_for(lambda: source.counters().get("catchup_areas_left") == 1, what="area (0, 0) left")
    # its UNSUBSCRIBE and the observer's next requests travel on two connections: only once something the robot
    # sent after the UNSUBSCRIBE is back has the broker dropped the subscription (an ordered event, not a sleep)
    after = make_update(uuid=lasting.uuid, version=2, deadline=600, rectangle=OTHER_AREA_RECT,
                        marked=(OTHER_AREA_CELL,), cleared=())
    assert source.publish_obstacle(after)
    wait_for(lambda: seen_published(observer, after), what="the robot's next update back from the broker")
    # then a request for (0, 0) that must not reach it, and one for (2, 0) that must (in order)
    request(observer, (0, 0), c2, asker)
    request(observer, (2, 0), c3, asker)
    wait_for(lambda: answered(observer, source, c3), what="the answer to c3")
    assert answered(observer, source, c3) == [(lasting.uuid, 1), (lasting.uuid, 2)]
    assert source.counters().get("catchup_areas_left") == 1, "still observing area (0, 0) after leaving it"
    assert not observer.on("/RSV/%s/%s" % (source.identity_id, c1))
    # the same request again: each area of one request is answered once
    request(observer, (2, 0), c3, asker)
    wait_for(lambda: source.counters().get("dropped.discover_rate_limited") == 1, what="the repeat dropped")
    assert len(observer.on("/RSV/%s/%s" % (source.identity_id, c3))) == 1


@pytest.mark.broker
def test_bad_catch_up_requests_are_counted_and_dropped_and_a_good_one_is_still_answered(
        make_client, make_update, observer, wait_for):
    source = make_client("robot_0")
    wait_for(lambda: source.subscribed, what="subscribed")
    source.note_own_position((5.0, 5.0))
    first = make_update(version=1)
    assert source.publish_obstacle(first)
    asker = str(uuidlib.uuid4())
    topic = str(Topic("fleet", "CHN", asker, filter=catchup.channel((0, 0))))
    wait_for(lambda: seen_published(observer, first), what="published (its channel observed)")
    bad = [{"object": {"objectType": catchup.OBJECT_TYPE, "coreType": "CoatyObject", "objectId": "not-a-uuid",
                       "name": "x"}},
           {"object": {"objectType": "org.fleetsharing.Other", "coreType": "CoatyObject",
                       "objectId": str(uuidlib.uuid4()), "name": "x"}},
           {"object": [1, 2]},
           {"objects": []},
           {"object": {"objectType": catchup.OBJECT_TYPE, "coreType": "CoatyObject",
                       "objectId": str(uuidlib.uuid4()), "name": "x", "missedFor": -5}}]
    for payload in bad:
        observer.publish(topic, json.dumps(payload))
    observer.publish(topic, b"\xff not json")
    good = str(uuidlib.uuid4())
    request(observer, (0, 0), good, asker)
    wait_for(lambda: observer.on("/RSV/%s/%s" % (source.identity_id, good)), what="the good request answered")
    counters = source.counters()
    dropped = {k: v for k, v in counters.items() if k.startswith("dropped.")}
    assert sum(dropped.values()) == 6, dropped
    assert dropped.get("dropped.wrong_type") == 3 and dropped.get("dropped.missing_field") == 1, dropped
    assert dropped.get("dropped.out_of_range") == 1, dropped
    assert counters["catchups_answered"] == 1


class _FakeMqtt:
    def __init__(self):
        self.subscribed = []

    def socket(self):
        return None

    def subscribe(self, topics, qos=0):
        self.subscribed += [t for t, _ in topics] if isinstance(topics, list) else [topics]
        return 0, 1

    def unsubscribe(self, topics):
        return 0, 2

    def publish(self, topic, payload, qos=0):
        class Info:
            rc = 0
        return Info()


def test_the_areas_a_robot_observes_are_subscribed_again_on_every_connect(make_update):
    client = CoatyBridgeClient(BridgeConfig("robot_0", obstacle_area_size=AREA_M), lambda u, t: None)   # never started
    client.note_own_position((5.0, 5.0))
    client.publish_obstacle(make_update(version=1))                                   # queued offline
    client.publish_obstacle(make_update(version=1, rectangle=OTHER_AREA_RECT, marked=(OTHER_AREA_CELL,), cleared=()))
    expected = ["coaty/+/fleet/CHN:%s/+" % catchup.channel(a) for a in ((0, 0), (2, 0))]
    assert client._catchup_topics() == expected
    fake = client._mqtt = _FakeMqtt()
    client._on_connect(fake, None, {}, 0)
    assert set(expected) <= set(fake.subscribed), fake.subscribed


def test_an_update_published_while_its_expired_area_is_being_left_keeps_the_area_observed(make_update):
    """The incoming thread reads the area's live own updates (none: they expired), then the publishing thread sends
    a new one there, then the incoming thread stops observing the area. The new update's area must stay observed,
    or a robot entering it later would not be answered. The interleaving is forced, not waited for."""
    now = [1000.0]
    client = CoatyBridgeClient(BridgeConfig("robot_0", obstacle_area_size=AREA_M), lambda u, t: None,
                               clock=lambda: now[0])                                     # never started
    client.note_own_position((5.0, 5.0))
    client.publish_obstacle(make_update(version=1, deadline=20))                        # area (0, 0)
    now[0] = 1030.0                                                                      # expired
    read_alive = client._replayable_own_updates_sent
    fresh = make_update(version=1, deadline=600)

    def read_then_publish():
        alive = read_alive()
        if not client._obstacle_area_published:
            client._obstacle_area_published = client.publish_obstacle(fresh)           # same area, after the read
        return alive
    client._obstacle_area_published = False
    client._replayable_own_updates_sent = read_then_publish
    asker = str(uuidlib.uuid4())
    topic = Topic("fleet", "CHN", asker, filter=catchup.channel((0, 0)))
    client._answer_catchup(topic, json.loads(catchup.request_payload(str(uuidlib.uuid4()))))
    assert client._obstacle_area_published
    assert client.counters().get("catchup_areas_left") == 1
    assert client._catchup_topics() == ["coaty/+/fleet/CHN:%s/+" % catchup.channel((0, 0))]


def test_without_obstacle_areas_nothing_is_observed(make_update):
    client = CoatyBridgeClient(BridgeConfig("robot_0", obstacle_area_size=0), lambda u, t: None)
    client.publish_obstacle(make_update(version=1))
    assert client._catchup_topics() == []


def _catchup_memory_after(requesters):
    """A client (burst 1, no refill) that has answered a first request for area (0, 0) and then ``requesters`` - 1
    other requesters; returns it and the first request (requester, correlation id)."""
    client = CoatyBridgeClient(BridgeConfig("robot_0", discover_answer_burst=1), lambda u, t: None,
                               clock=lambda: 1000.0)   # never started
    first = (str(uuidlib.uuid4()), str(uuidlib.uuid4()))
    assert client._catchup_allowed(first[0], first[1], (0, 0))
    for _ in range(requesters - 1):
        assert client._catchup_allowed(str(uuidlib.uuid4()), str(uuidlib.uuid4()), (0, 0))
    return client, first


def test_max_requesters_requests_are_remembered():
    """Each requester's last request is remembered for MAX_REQUESTERS requesters: another area of it is answered
    without a token (the first requester has none left), the same area not again."""
    client, (requester, correlation_id) = _catchup_memory_after(catchup.MAX_REQUESTERS)
    assert client._catchup_allowed(requester, correlation_id, (1, 0))
    assert not client._catchup_allowed(requester, correlation_id, (0, 0))


def test_one_more_requester_and_the_memory_starts_again():
    """Beyond MAX_REQUESTERS the memory is cleared: a repeat then costs a token (here a fresh bucket, as the Discover
    buckets forget the oldest requester beyond the same number) and is answered."""
    client, (requester, correlation_id) = _catchup_memory_after(catchup.MAX_REQUESTERS + 1)
    assert client._catchup_allowed(requester, correlation_id, (0, 0))


@pytest.mark.parametrize("more, kept", [(1, catchup.MAX_AREAS_LEFT), (2, 2)])
def test_a_robot_remembers_when_it_left_at_most_max_areas_left_areas(more, kept):
    client = CoatyBridgeClient(BridgeConfig("robot_0"), lambda u, t: None, clock=lambda: 1000.0)   # never started
    client._note_areas_left({(i, 0) for i in range(catchup.MAX_AREAS_LEFT - 1)}, connected=True)
    client._note_areas_left({(-i, 1) for i in range(more)}, connected=True)
    assert len(client._areas_left) == kept   # beyond the bound the memory starts again: the next catch-ups ask all
    client._note_areas_left({(-1, -1)}, connected=False)
    assert (-1, -1) not in client._areas_left   # left while offline: the reconnect's Discover asks for everything
