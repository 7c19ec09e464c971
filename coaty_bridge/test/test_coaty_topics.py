import pytest

from coaty_bridge.errors import (InvalidNameError, InvalidSourceIdError, InvalidTopicError,
                                 ProtocolVersionError)
from coaty_bridge.topics import Topic, parse_topic, subscription

SRC = "0f8fad5b-d9cb-469f-a165-70867728950e"
COR = "7c9e6679-7425-40de-944b-e07fc1f90ae7"


def test_one_way_and_two_way_topics_round_trip():
    adv = Topic("fleet", "ADV", SRC, object_type="org.fleetsharing.SharedObstacle")
    assert str(adv) == "coaty/3/fleet/ADV::org.fleetsharing.SharedObstacle/" + SRC
    assert parse_topic(str(adv)) == adv
    ident = Topic("fleet", "ADV", SRC, core_type="Identity")
    assert str(ident) == "coaty/3/fleet/ADV:Identity/" + SRC
    assert parse_topic(str(ident)).core_type == "Identity"
    dsc = parse_topic("coaty/3/fleet/DSC/%s/%s" % (SRC, COR))
    assert (dsc.event, dsc.source_id, dsc.correlation_id) == ("DSC", SRC, COR)
    assert str(Topic("-", "DAD", SRC)) == "coaty/3/-/DAD/" + SRC


def test_upper_case_uuid_is_normalised():
    assert parse_topic("coaty/3/fleet/DAD/" + SRC.upper()).source_id == SRC


@pytest.mark.parametrize("topic, error", [
    ("coaty/2/fleet/DAD/" + SRC, ProtocolVersionError),
    ("coaty/4/fleet/DSC/%s/%s" % (SRC, COR), ProtocolVersionError),
    ("coaty/3/fleet/DAD/robot_0", InvalidSourceIdError),
    ("coaty/3/fleet/DSC/%s/not-a-uuid" % SRC, InvalidSourceIdError),
    ("coaty/3/fleet/DSC/" + SRC, InvalidTopicError),
    ("coaty/3/fleet/DAD/%s/%s" % (SRC, COR), InvalidTopicError),
    ("coaty/3/fleet/XYZ/" + SRC, InvalidTopicError),
    ("coaty/3/fleet/ADV/" + SRC, InvalidTopicError),
    ("coaty/3//DAD/" + SRC, InvalidNameError),
    ("coaty/3/fl+eet/DAD/" + SRC, InvalidNameError),
    ("coaty/3/fleet/ADV::a#b/" + SRC, InvalidNameError),
    ("mqtt/3/fleet/DAD/" + SRC, InvalidTopicError),
    ("coaty/3/fleet", InvalidTopicError),
])
def test_bad_topics_raise_the_matching_error(topic, error):
    with pytest.raises(error):
        parse_topic(topic)


@pytest.mark.parametrize("name", ["robot/0", "a+b", "a#", "", "x\u0000y"])
def test_names_with_mqtt_wildcards_or_slashes_are_rejected(name):
    with pytest.raises(InvalidNameError, match="namespace"):
        Topic(name, "DAD", SRC)


def test_subscription_takes_every_protocol_version():
    assert subscription("fleet", "DSC", two_way=True) == "coaty/+/fleet/DSC/+/+"
    assert subscription("fleet", "ADV::x.Y") == "coaty/+/fleet/ADV::x.Y/+"
