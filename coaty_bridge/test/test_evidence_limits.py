"""Each numeric limit on evidence (issues 43 and 46; coaty_bridge/evidence.py, codec.check_evidence and
sharing_msgs.authority.EvidenceRule) just inside and just outside, where test_evidence_in.py, test_evidence_out.py
and test_param_limits.py leave a side unchecked. Pure: no broker, no ROS master."""
import logging
import math
import uuid as uuidlib

import pytest

from coaty_bridge import codec
from coaty_bridge.topics import Topic
from sharing_msgs.authority import EvidenceRule

from test_evidence_in import OT, REACH, STAMP, cell_at, receiver  # noqa: F401 - the fixture
from test_evidence_out import WINDOW, bridge, footprint  # noqa: F401 - the fixture

STEP = 0.01
#: evidence.EVIDENCE_WAIT and a uint32's largest value, stated here so that changing a bound fails a test
EVIDENCE_WAIT = 5.0
MAX_UINT32 = 4294967295.0


# ------------------------------------------------------------------ codec.check_evidence: the field's ranges

EVIDENCE_RANGES = [
    # (index in [stamp, x, y, radius, reach], value, accepted); radius and reach above are in test_evidence_in.py
    (0, 0.0, True), (0, -STEP, False),
    (0, MAX_UINT32, True), (0, MAX_UINT32 + STEP, False),
    (1, -1.0e6, True), (1, -1.0e6 - STEP, False), (1, 1.0e6, True), (1, 1.0e6 + STEP, False),
    (2, -1.0e6, True), (2, -1.0e6 - STEP, False), (2, 1.0e6, True), (2, 1.0e6 + STEP, False),
    (3, 0.0, True), (3, -STEP, False),
    (4, 0.0, True), (4, -STEP, False),
]


@pytest.mark.parametrize("index,value,accepted", EVIDENCE_RANGES,
                         ids=["%s=%r" % (("stamp", "x", "y", "radius", "reach")[i], v) for i, v, _ in EVIDENCE_RANGES])
def test_each_evidence_value_is_within_its_range(index, value, accepted):
    """A stamp is a uint32 time, a pose lies within the 1e6 m any grid may span, a radius and a reach are not
    negative: evidence beyond them is no pose of a robot and is a bad payload, named by its field."""
    evidence = [STAMP, 1.0, 3.0, 0.3, REACH]
    evidence[index] = value
    if accepted:
        assert codec.check_evidence(evidence)[index] == value
    else:
        name = ("stamp", "x", "y", "radius", "reach")[index]
        with pytest.raises(codec.OutOfRangeError, match="evidence " + name):
            codec.check_evidence(evidence)


# ------------------------------------------------------------------ EvidenceRule: the receiver's slack

RULE_RANGES = [(name, value, accepted)
               for name, high in (("max_sensor_reach", 1000.0), ("window", 3600.0), ("max_speed", 100.0),
                                  ("localisation_tolerance", 100.0))
               for value, accepted in ((0.0, True), (-0.001, False), (high, True), (high + 0.001, False))]


@pytest.mark.parametrize("name,value,accepted", RULE_RANGES, ids=["%s=%r" % c[:2] for c in RULE_RANGES])
def test_evidence_rule_slack_is_0_to_its_cap(name, value, accepted):
    """The slack widens what evidence vouches for: negative slack means nothing, and a cap keeps one rule from
    vouching for the whole map. (BridgeConfig checks the same caps first; this is the rule's own guard.)"""
    if accepted:
        assert getattr(EvidenceRule(**{name: value}), name) == value
    else:
        with pytest.raises(ValueError, match=name):
            EvidenceRule(**{name: value})


# ------------------------------------------------------------------ evidence.py: radius cap on received evidence

@pytest.mark.parametrize("radius,kept", [(5.0 * math.sqrt(0.5), True), (5.0 * math.sqrt(0.5) + 1e-9, False)])
def test_evidence_radius_may_equal_the_max_footprint_extent_squares_and_not_exceed_it(receiver, make_update,
                                                                                       radius, kept):
    """A footprint advert wider than a max_footprint_extent (default 5 m) square is refused; evidence claiming
    such a footprint would vouch for cells farther away than any accepted advert could, so it is refused too.
    Exactly the square's circumradius is a footprint an advert may have."""
    client, got = receiver
    update = make_update(stamp=STAMP, rectangle=(0.95, 2.95, 1.05, 3.05), marked=(cell_at(1.0, 3.0),), cleared=())
    obj = codec.obstacle_to_object(update)
    obj["evidence"] = [STAMP, 1.0, 3.0, radius, REACH]
    client.handle(str(Topic("fleet", "ADV", str(uuidlib.uuid4()), object_type=OT)), codec.advertise_payload(obj))
    assert (len(got) == 1) == kept, client.counters()
    assert (client.counters().get("dropped.implausible_evidence") == 1) == (not kept), client.counters()


# ------------------------------------------------------------------ evidence.py: what this robot sends

@pytest.mark.parametrize("offset,evidence", [
    (-WINDOW, True), (-(WINDOW + STEP), False), (-(WINDOW - STEP), True), (WINDOW, True)])
def test_a_footprint_within_the_window_before_or_after_the_stamp_is_evidence(bridge, make_update, offset, evidence):
    """Evidence is where the robot stood when it saw the cells: a footprint taken up to evidence_window before or
    after the stamp (the window itself included), no farther, or the pose says little about what it saw.
    (The after side just inside/outside is in test_evidence_out.py.)"""
    client, clock, sent = bridge
    client.note_own_footprint(footprint(100.0 + offset))
    update = make_update(stamp=100.0)
    client.publish_obstacle(update)
    if evidence:
        assert [(obj["uuid"], obj.get("evidence")) for _t, obj in sent] == [
            (update.uuid, [100.0 + offset, 1.25, 2.25, 0.354, 3.0])]
    else:
        assert sent == [] and client.counters()["awaiting_evidence"] == 1


@pytest.mark.parametrize("waited,released", [(EVIDENCE_WAIT, True), (EVIDENCE_WAIT - 0.001, False)])
def test_a_message_goes_out_without_evidence_once_it_waited_evidence_wait(bridge, make_update, waited, released):
    """A message waits for a footprint at most EVIDENCE_WAIT s (the footprint topic may lag or never come): at
    EVIDENCE_WAIT it goes, once, so that it is not held back for good nor sent twice."""
    client, clock, sent = bridge
    update = make_update(stamp=100.0)
    client.publish_obstacle(update)
    clock.now += waited
    client.release_unevidenced()
    assert [obj["uuid"] for _t, obj in sent] == ([update.uuid] if released else [])
    clock.now += 1.0                   # later rounds of the broker watch: it went once, or it goes now
    client.release_unevidenced()
    assert [obj["uuid"] for _t, obj in sent] == [update.uuid]


@pytest.mark.parametrize("after,warnings", [(30.0, 2), (30.0 - 0.001, 1)])
def test_a_message_without_evidence_warns_at_most_every_30_seconds(bridge, make_update, caplog, after, warnings):
    """Each message without evidence is counted, but the WARN naming the missing footprint repeats only every
    30 s, so a robot whose footprint topic is broken does not flood its log."""
    client, clock, sent = bridge
    with caplog.at_level(logging.WARNING, logger="coaty_bridge.client"):
        client._with_evidence(make_update(stamp=100.0))
        clock.now += after
        client._with_evidence(make_update(stamp=100.0))
    warned = [r for r in caplog.records if "published without evidence" in r.getMessage()]
    assert len(warned) == warnings
    assert client.counters()["published_without_evidence"] == 2
