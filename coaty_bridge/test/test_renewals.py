"""Lease renewals of far copies in one Coaty Channel event (issue 29, traffic): what they cost on the
wire, that each entry means the obstacle object it stands for, that bad events and bad entries are
refused by name without losing the good ones, and that a bridge sends the renewals it has due (and
those due soon) together. Pure codec tests, then real mosquitto."""
import json
import re
import uuid as uuidlib

import pytest

from coaty_bridge import codec, renewals
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.errors import CoatyError, MissingFieldError, OutOfRangeError, WrongTypeError
from coaty_bridge.topics import Topic

OT = codec.DEFAULT_OBJECT_TYPE
FAR = (45.0, 5.0)


def payload_of(updates):
    (chunk, obj), = renewals.renewals_objects(updates, lambda: str(uuidlib.uuid4()))
    assert chunk == tuple(updates)
    return json.loads(renewals.renewals_payload(obj))


def test_a_renewals_event_means_the_obstacles_it_carries_at_a_third_of_their_bytes(make_update):
    updates = [make_update(version=v, deadline=600 + v, marked=(880221 + v,), cleared=(882223,))
               for v in range(2, 12)]
    data = payload_of(updates)
    content = renewals.decode_renewals(data, OT)
    assert content.errors == () and content.obstacles == tuple(updates)
    one_by_one = sum(len(codec.advertise_payload(codec.obstacle_to_object(u))) for u in updates)
    together = len(renewals.renewals_payload(data["object"]))
    assert together < 0.4 * one_by_one, "%d bytes for 10 renewals, %d one by one" % (together, one_by_one)


def test_renewals_are_grouped_by_source_and_grid_and_capped_per_event(make_update):
    updates = [make_update() for _ in range(renewals.MAX_ENTRIES + 1)] + [make_update(source="robot_1")]
    events = renewals.renewals_objects(updates, lambda: str(uuidlib.uuid4()))
    assert sorted(len(chunk) for chunk, _obj in events) == [1, 1, renewals.MAX_ENTRIES]
    for chunk, obj in events:
        assert {u.source for u in chunk} == {obj["source"]}
        assert renewals.decode_renewals({"object": obj}, OT).obstacles == chunk


@pytest.mark.parametrize("change, error, shown", [
    (lambda o: o.pop("obstacles"), MissingFieldError, "obstacles"),
    (lambda o: o.update(obstacles={"a": 1}), WrongTypeError, "obstacles"),
    (lambda o: o.update(obstacles=o["obstacles"] * (renewals.MAX_ENTRIES + 1)), OutOfRangeError, "more than 64"),
    (lambda o: o.update(objectType="org.fleetsharing.Heartbeat"), WrongTypeError, "objectType"),
    (lambda o: o.update(coreType="Identity"), WrongTypeError, "coreType"),
    (lambda o: o.pop("size"), MissingFieldError, "size"),
])
def test_a_bad_renewals_event_is_refused_naming_the_field(make_update, change, error, shown):
    data = payload_of([make_update(version=2)])
    change(data["object"])
    with pytest.raises(error, match=shown):
        renewals.decode_renewals(data, OT)


@pytest.mark.parametrize("entry, shown", [
    ("not a list", "is not \\[uuid"),
    ([1, 2, 3], "is not \\[uuid"),
    (["not-a-uuid", 2, 1700000000.5, 60, [1.0, 2.0, 3.5, 4.0], [880221], []], "objectId"),
    ([None, 2, 1700000000.5, 60, [1.0, 2.0, 3.5, 4.0], [880221], []], "objectId"),
    ([str(uuidlib.uuid4()), 0, 1700000000.5, 60, [1.0, 2.0, 3.5, 4.0], [880221], []], "version"),
    ([str(uuidlib.uuid4()), 2, float("nan"), 60, [1.0, 2.0, 3.5, 4.0], [880221], []], "stamp"),
    ([str(uuidlib.uuid4()), 2, 1700000000.5, 60, [1.0, 2.0], [880221], []], "rectangle"),
    ([str(uuidlib.uuid4()), 2, 1700000000.5, 60, [1.0, 2.0, 3.5, 4.0], [4000000], []], "index|outside"),
    ([str(uuidlib.uuid4()), 2, 1700000000.5, 60, [1.0, 2.0, 3.5, 4.0], "%%%", []], "compact|base64"),
])
def test_a_bad_entry_is_reported_alone_and_the_good_ones_are_kept(make_update, entry, shown):
    good = make_update(version=2)
    data = payload_of([good])
    data["object"]["obstacles"].insert(0, entry)
    content = renewals.decode_renewals(json.loads(json.dumps(data)), OT)
    assert content.obstacles == (good,)
    assert len(content.errors) == 1 and isinstance(content.errors[0], CoatyError)
    assert re.search(shown, str(content.errors[0])), content.errors[0]


def _clocked(broker, name, now):
    client = CoatyBridgeClient(BridgeConfig(name, broker_url=broker.url), lambda u, t: None, clock=lambda: now[0])
    client.start()
    return client


@pytest.mark.broker
def test_the_renewals_a_bridge_has_due_go_out_in_one_event(broker, make_client, make_update, observer, wait_for):
    """Three obstacles shared and then updated in their area at different times: when the first renewal
    is due, the others (due within their margin) go along, in one event, and the far robot renews all
    three."""
    now = [1000.0]
    source = _clocked(broker, "robot_0", now)
    far = make_client("robot_2")
    try:
        wait_for(lambda: source.subscribed and far.subscribed, what="subscribed")
        source.note_own_position((5.0, 5.0))
        far.note_own_position(FAR)
        firsts = [make_update(version=1, deadline=100) for _ in range(3)]
        for k, first in enumerate(firsts):
            now[0] = 1000.0 + 4 * k          # far copies until 1100, 1104, 1108: due at 1090, 1094, 1098
            wait_for(lambda f=first: source.publish_obstacle(f) and 1 in [u.version for u in far.received_updates
                                                                          if u.uuid == f.uuid], what="v1")
        for k, first in enumerate(firsts):
            now[0] = 1010.0 + 5 * k          # each monitored in its area: near copies until 1110..1120
            assert source.publish_obstacle(make_update(uuid=first.uuid, version=2, marked=(880250,), cleared=(),
                                                       deadline=100))
        assert source.counters()["published_to_area"] == 3
        now[0] = 1080.0
        assert source.renew_due() == 0, "renewed long before the far copies expire"
        now[0] = 1090.0                      # the first is due (margin 10 s): the other two go along
        assert source.renew_due() == 3
        wait_for(lambda: {u.uuid for u in far.received_updates if u.version == 2} == {f.uuid for f in firsts},
                 what="the three renewals at the far robot")
        assert source.counters()["renewal_events_sent"] == 1
        # the observer is a client of its own: it may hear the event after the far robot does
        events = wait_for(lambda: observer.on("CHN:" + renewals.CHANNEL), what="the renewal event at the observer")
        assert len(events) == 1 and len(events[0][1]["object"]["obstacles"]) == 3
        deadlines = sorted(u.deadline for u in far.received_updates if u.version == 2)
        assert deadlines == [20, 25, 30], "each aged by the time since its update: far copies end with the near"
        assert far.counters()["renewals_received"] == 3
        assert not [k for k in far.counters() if k.startswith("dropped.")]
        now[0] = 1095.0
        assert source.renew_due() == 0, "renewed twice"
    finally:
        source.stop(timeout=0.5)


@pytest.mark.broker
def test_bad_renewals_on_the_wire_are_counted_and_the_good_entries_delivered(make_client, make_update, observer,
                                                                             wait_for):
    robot = make_client("robot_1", authenticate_sources=False)
    wait_for(lambda: robot.subscribed, what="subscribed")
    sender = str(uuidlib.uuid4())
    topic = str(Topic("fleet", "CHN", sender, filter=renewals.CHANNEL))
    good = make_update(version=2, source="robot_0")
    data = payload_of([good])
    data["object"]["obstacles"].append(["bad"])
    for payload in (b"{broken", json.dumps({"object": {"objectType": renewals.OBJECT_TYPE}}), json.dumps(data)):
        observer.publish(topic, payload)
    wait_for(lambda: [u for u in robot.received_updates if u.uuid == good.uuid], what="the good entry delivered")
    wait_for(lambda: sum(v for k, v in robot.counters().items() if k.startswith("dropped.")) == 3,
             what="three drops counted")
    counters = robot.counters()
    assert counters["dropped.invalid_json"] == 1 and counters["dropped.missing_field"] == 1
    assert counters["dropped.wrong_type"] == 1


@pytest.mark.broker
def test_a_renewal_of_another_robots_obstacle_under_a_forged_source_is_dropped(make_client, make_update, observer,
                                                                               wait_for):
    robot = make_client("robot_1", authenticate_sources=True)
    wait_for(lambda: robot.subscribed, what="subscribed")
    forged = make_update(version=2, source="robot_0")
    observer.publish(str(Topic("fleet", "CHN", str(uuidlib.uuid4()), filter=renewals.CHANNEL)),
                     json.dumps(payload_of([forged])))
    wait_for(lambda: robot.counters().get("dropped.forged_source") == 1, what="the forged renewal dropped")
    assert robot.received_updates == []
