"""The evidence a bridge sends with its own obstacle messages (issues 43 and 46; coaty_bridge/evidence.py): this
robot's footprint taken within evidence_window of the message's stamp goes inside it (``evidence``), and inside the
renewals of it; a message made before any such footprint waits for one (at most EVIDENCE_WAIT s) instead of going
out without and being refused by every peer for good. Pure: the client's publish path with a fake clock, its sends
recorded; no broker."""
import json

import pytest

from coaty_bridge import codec, footprint as footprints
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.evidence import EVIDENCE_WAIT

OT = codec.DEFAULT_OBJECT_TYPE
WINDOW = 2.0


class Clock:
    def __init__(self):
        self.now = 5000.0

    def __call__(self):
        return self.now


@pytest.fixture
def bridge():
    clock = Clock()
    client = CoatyBridgeClient(BridgeConfig("robot_0", evidence_window=WINDOW, sensor_reach=3.0),
                               lambda update, topic: None, clock=clock, heartbeats=False)
    sent = []
    client._send = lambda topic, payload, **_: sent.append((topic, json.loads(payload)["object"]))
    client._connected = True
    client.expect_footprints(True)
    return client, clock, sent


def footprint(stamp, x=1.0):
    return footprints.RobotFootprint(robot="robot_0", stamp=stamp, frame_id="map",
                                     points=((x, 2.0), (x + 0.5, 2.0), (x + 0.5, 2.5), (x, 2.5)))


def sent_obstacles(sent):
    """(uuid, evidence or None) of each obstacle sent, in order; nothing else may have been sent."""
    assert all("uuid" in obj for _topic, obj in sent), "a separate evidence advert went out: %s" % sent
    return [(obj["uuid"], obj.get("evidence")) for _topic, obj in sent]


def test_a_message_before_any_footprint_waits_for_one_and_goes_out_carrying_it(bridge, make_update):
    client, clock, sent = bridge
    update = make_update(stamp=100.0)
    assert client.publish_obstacle(update)
    assert sent == [] and client.counters()["awaiting_evidence"] == 1
    client.note_own_footprint(footprint(101.0))
    # the footprint's centroid (1.25, 2.25), its circumradius and the reach peers judge its cells by
    assert sent_obstacles(sent) == [(update.uuid, [101.0, 1.25, 2.25, 0.354, 3.0])]
    assert client.counters()["published_with_evidence"] == 1


@pytest.mark.parametrize("offset,evidence", [(WINDOW - 0.01, True), (WINDOW + 0.01, False)])
def test_a_footprint_is_evidence_only_within_the_window_of_the_stamp(bridge, make_update, offset, evidence):
    client, clock, sent = bridge
    client.note_own_footprint(footprint(100.0 + offset))
    update = make_update(stamp=100.0)
    client.publish_obstacle(update)
    if evidence:
        assert sent_obstacles(sent) == [(update.uuid, [100.0 + offset, 1.25, 2.25, 0.354, 3.0])]
    else:
        assert sent == [], "sent with a footprint %.2f s from its stamp" % offset


def test_without_a_footprint_within_the_wait_it_goes_out_without_evidence_its_lease_aged(bridge, make_update):
    client, clock, sent = bridge
    update = make_update(stamp=100.0, deadline=60)
    client.publish_obstacle(update)
    clock.now += EVIDENCE_WAIT - 0.1
    client.release_unevidenced()
    assert sent == []
    clock.now += 0.2
    client.release_unevidenced()
    assert sent_obstacles(sent) == [(update.uuid, None)]
    assert sent[0][1]["deadline"] == 54           # the 5.1 s it waited taken off: 54.9 s, rounded down
    assert client.counters()["published_without_evidence"] == 1


def test_a_footprint_too_far_from_the_stamp_releases_nothing(bridge, make_update):
    client, clock, sent = bridge
    update = make_update(stamp=100.0)
    client.publish_obstacle(update)
    client.note_own_footprint(footprint(100.0 + WINDOW + 0.5))
    assert sent == [] and client.counters()["awaiting_evidence"] == 1


def test_the_footprint_nearest_the_stamp_goes_with_a_message_that_waited_offline(bridge, make_update):
    """Updates queued while the broker was away go out later: each with the pose it was made at."""
    client, clock, sent = bridge
    for stamp, x in ((100.0, 1.0), (104.0, 3.0), (108.0, 5.0)):
        client.note_own_footprint(footprint(stamp, x))
    update = make_update(stamp=104.3)
    client.publish_obstacle(update)
    assert sent_obstacles(sent) == [(update.uuid, [104.0, 3.25, 2.25, 0.354, 3.0])]


def test_a_renewal_carries_the_evidence_of_the_update_it_renews(bridge, make_update):
    """Far robots heard neither the area-scoped update nor (now) any separate advert: the renewal brings it."""
    from coaty_bridge import renewals
    client, clock, sent = bridge
    client.note_own_footprint(footprint(100.0))
    update = client._with_evidence(make_update(stamp=100.0))
    ((_chunk, obj),) = renewals.renewals_objects([update], lambda: "00000000-0000-4000-8000-000000000000")
    assert obj["obstacles"][0][7] == [100.0, 1.25, 2.25, 0.354, 3.0]
    (back,) = renewals.decode_renewals(json.loads(renewals.renewals_payload(obj)), OT).obstacles
    assert back.evidence == (100.0, 1.25, 2.25, 0.354, 3.0)


def test_a_footprint_in_another_frame_is_no_evidence(bridge, make_update):
    client, clock, sent = bridge
    client.expect_footprints(False)
    client.note_own_footprint(footprints.RobotFootprint(robot="robot_0", stamp=100.0, frame_id="odom",
                                                        points=((1.0, 2.0), (1.5, 2.0), (1.5, 2.5))))
    client.publish_obstacle(make_update(stamp=100.0))
    assert sent_obstacles(sent)[0][1] is None


def test_a_robot_that_advertises_no_footprint_sends_at_once(bridge, make_update):
    client, clock, sent = bridge
    client.expect_footprints(False)
    update = make_update(stamp=100.0)
    client.publish_obstacle(update)
    assert sent_obstacles(sent) == [(update.uuid, None)]
