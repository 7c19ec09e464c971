"""The evidence an obstacle message carries (issue 46: evidence inside the message instead of a footprint advert to
every robot before it), judged by a receiving bridge that requires evidence: a message's own evidence vouches for
cells within reach of where it says its sender stood, no farther; evidence claiming a footprint larger than a
max_footprint_extent square is refused, as such a footprint advert is; bad evidence is a bad payload, named.
Pure: the client's receive path (handle) with its deliveries recorded; no broker."""
import json
import math
import uuid as uuidlib

import pytest

from coaty_bridge import codec, renewals
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.topics import Topic

OT = codec.DEFAULT_OBJECT_TYPE
REACH = 4.0
STAMP = 1700000000.5


@pytest.fixture
def receiver():
    got = []
    client = CoatyBridgeClient(BridgeConfig("robot_1", require_evidence=True, sensor_reach=REACH,
                                            max_sensor_reach=REACH), lambda update, topic: got.append(update),
                               heartbeats=False)
    return client, got


def cell_at(x, y, resolution=0.05, origin=(-10.0, -20.0), size_x=2000):
    return int((y - origin[1]) / resolution) * size_x + int((x - origin[0]) / resolution)


def message(make_update, cell_x, evidence):
    """robot_0's first share of one cell at (cell_x, 3.0), carrying ``evidence``."""
    cell = cell_at(cell_x, 3.0)
    update = make_update(stamp=STAMP, rectangle=(cell_x - 0.05, 2.95, cell_x + 0.05, 3.05), marked=(cell,), cleared=())
    obj = codec.obstacle_to_object(update)
    if evidence is not None:
        obj["evidence"] = evidence
    return codec.advertise_payload(obj)


def deliver(client, payload):
    client.handle(str(Topic("fleet", "ADV", str(uuidlib.uuid4()), object_type=OT)), payload)


def allowance(radius=0.3):
    """The evidence rule's reach at the advert's own stamp (sharing_msgs README, "Plausible evidence")."""
    return REACH + radius + 0.05 / math.sqrt(2.0) + 0.25


@pytest.mark.parametrize("beyond, kept", [(-0.05, True), (0.05, False)])
def test_a_messages_own_evidence_vouches_for_cells_within_reach_and_no_farther(receiver, make_update, beyond, kept):
    client, got = receiver
    # the cell's centre just inside / just outside the allowance from the pose the message says its sender had
    centre = 0.0 + 0.05 * (int((allowance() + beyond + 10.0) / 0.05)) - 10.0 + 0.025
    deliver(client, message(make_update, centre, [STAMP, 0.0, 3.025, 0.3, REACH]))
    if kept:
        assert len(got) == 1, client.counters()
    else:
        assert got == [] and client.counters().get("dropped.implausible_evidence") == 1, client.counters()


def test_without_evidence_or_a_sighting_a_message_is_refused(receiver, make_update):
    client, got = receiver
    deliver(client, message(make_update, 1.0, None))
    assert got == [] and client.counters().get("dropped.implausible_evidence") == 1


@pytest.mark.parametrize("radius, kept", [(5.0 * math.sqrt(0.5) - 0.01, True), (5.0 * math.sqrt(0.5) + 0.01, False)])
def test_evidence_of_a_footprint_larger_than_max_footprint_extent_is_refused(receiver, make_update, radius, kept):
    """The default max_footprint_extent is 5 m: a 5 m square's circumradius is 3.54 m."""
    client, got = receiver
    deliver(client, message(make_update, 1.0, [STAMP, 1.0, 3.0, radius, REACH]))
    assert (len(got) == 1) == kept, client.counters()


@pytest.mark.parametrize("evidence, error", [
    ("here", "wrong_type"), ([STAMP, 1.0, 3.0, 0.3], "wrong_type"), ([STAMP, 1.0, 3.0, 0.3, "far"], "wrong_type"),
    ([STAMP, float("nan"), 3.0, 0.3, REACH], "non_finite_number"), ([STAMP, 1.0, 3.0, -0.01, REACH], "out_of_range"),
    ([STAMP, 1.0, 3.0, 0.3, 1000.01], "out_of_range"), ([-1.0, 1.0, 3.0, 0.3, REACH], "out_of_range"),
    ([STAMP, 1.0e6 + 1, 3.0, 0.3, REACH], "out_of_range"), ([STAMP, 1.0, 3.0, 0.3, True], "wrong_type"),
])
def test_bad_evidence_is_a_bad_payload_named_by_its_field(receiver, make_update, evidence, error):
    client, got = receiver
    nan = isinstance(evidence, list) and any(isinstance(v, float) and math.isnan(v) for v in evidence)
    if nan:   # JSON has no NaN: what a peer may send anyway
        evidence = [999.125 if isinstance(v, float) and math.isnan(v) else v for v in evidence]
    payload = message(make_update, 1.0, evidence)
    deliver(client, payload.replace(b"999.125", b"NaN") if nan else payload)
    assert got == [] and client.counters().get("dropped." + error) == 1, client.counters()
    # the bad one cost nothing else: the same sender's next, good message is taken
    deliver(client, message(make_update, 1.0, [STAMP, 1.0, 3.0, 0.3, REACH]))
    assert len(got) == 1, client.counters()


def test_the_largest_values_evidence_may_state_pass_the_codec():
    assert codec.check_evidence([float(2 ** 32 - 1), -1.0e6, 1.0e6, codec.MAX_EVIDENCE_RADIUS, 1000.0])
    with pytest.raises(codec.OutOfRangeError, match="radius"):
        codec.check_evidence([STAMP, 0.0, 0.0, codec.MAX_EVIDENCE_RADIUS + 0.01, REACH])


def test_a_renewal_is_judged_by_the_evidence_it_carries(receiver, make_update):
    """Far robots never heard the area-scoped update (nor, now, an advert): the renewal's own evidence counts."""
    client, got = receiver
    cell = cell_at(1.0, 3.0)
    near = make_update(stamp=STAMP, version=4, rectangle=(0.95, 2.95, 1.05, 3.05), marked=(cell,), cleared=(),
                       evidence=(STAMP, 1.0, 3.0, 0.3, REACH))
    far = make_update(stamp=STAMP, version=4, rectangle=(0.95, 2.95, 1.05, 3.05), marked=(cell,), cleared=(),
                      evidence=(STAMP, 30.0, 3.0, 0.3, REACH))
    for update in (far, near):   # the far one first: once noted, the near pose would vouch for it too
        ((_chunk, obj),) = renewals.renewals_objects([update], lambda: str(uuidlib.uuid4()))
        client.handle(str(Topic("fleet", "CHN", str(uuidlib.uuid4()), filter=renewals.CHANNEL)),
                      renewals.renewals_payload(obj))
    assert [u.uuid for u in got] == [near.uuid], client.counters()


def test_a_message_without_evidence_round_trips_without_the_field(make_update):
    obj = codec.obstacle_to_object(make_update())
    assert "evidence" not in obj
    assert codec.obstacle_from_object(json.loads(json.dumps(obj))).evidence is None
