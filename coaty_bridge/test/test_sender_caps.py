"""What a bridge remembers per sender is bounded (incoming.py): each cap tested just inside and just
outside. A client that is not connected, its handle() called directly: no broker, no sleeps."""
import uuid as uuidlib

import pytest

from coaty_bridge import areas, footprint as fp, incoming
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.topics import Topic

OT = fp.DEFAULT_FOOTPRINT_OBJECT_TYPE
# at 5 m squares (12.0..12.5, 3.0..3.5) lies in square (2, 0); a 10 m bridge puts it under (1, 0)
POINTS = ((12.0, 3.0), (12.5, 3.0), (12.5, 3.5), (12.0, 3.5))


@pytest.fixture
def client():
    c = CoatyBridgeClient(BridgeConfig("robot_0", footprint_area_size=5.0), lambda u, t: None,
                          on_footprint=lambda f, t: None)
    yield c


def _advert(client, robot, area, sender=None):
    """robot's footprint advert under ``area``, from ``sender`` (default: a new sourceId)."""
    sender = sender or str(uuidlib.uuid4())
    object_type = areas.area_object_type(OT, area)
    footprint = fp.RobotFootprint(robot=robot, stamp=1700000000.5, frame_id="map", points=POINTS)
    client.handle(str(Topic("fleet", "ADV", sender, object_type=object_type)),
                  fp.footprint_payload(footprint, str(uuidlib.uuid4()), object_type))
    return sender


def _warnings(caplog):
    return [r.getMessage() for r in caplog.records if "another area size" in r.getMessage()]


def test_robots_warned_about_another_area_size_are_capped_and_still_counted(client, caplog):
    caplog.set_level("WARNING", logger="coaty_bridge.client")
    client._area_mismatch_warned.update("old_%d" % i for i in range(incoming.MAX_AREA_MISMATCH_WARNED - 1))
    _advert(client, "robot_7", (1, 0))             # just inside: the last one warned about
    assert len(_warnings(caplog)) == 1 and "'robot_7'" in _warnings(caplog)[0]
    _advert(client, "robot_8", (1, 0))             # just outside: counted, not warned
    assert len(_warnings(caplog)) == 1
    assert len(client._area_mismatch_warned) == incoming.MAX_AREA_MISMATCH_WARNED
    assert client.counters()["footprint_area_mismatches"] == 2


def test_footprint_senders_remembered_are_capped_and_a_known_one_is_still_updated(client):
    for i in range(incoming.MAX_FOOTPRINT_SENDERS - 1):
        client._footprint_senders[str(uuidlib.uuid4())] = ("old_%d" % i, str(uuidlib.uuid4()))
    inside = _advert(client, "robot_7", (2, 0))     # just inside
    assert client._footprint_senders[inside][0] == "robot_7"
    outside = _advert(client, "robot_8", (2, 0))    # just outside
    assert outside not in client._footprint_senders
    _advert(client, "robot_7b", (2, 0), sender=inside)    # a known sender is updated at the cap
    assert client._footprint_senders[inside][0] == "robot_7b"
    assert len(client._footprint_senders) == incoming.MAX_FOOTPRINT_SENDERS


def test_topics_admitted_are_forgotten_all_at_once_beyond_the_cap(client):
    topics = [str(Topic("fleet", "ADV", str(uuidlib.uuid4()), object_type=areas.area_object_type(OT, (i, 0))))
              for i in range(incoming.MAX_ADMIT_CACHE + 1)]
    for topic in topics[:-1]:
        assert client.admit(topic) is not None
    assert len(client._admit_cache) == incoming.MAX_ADMIT_CACHE      # just inside: all remembered
    client.admit(topics[-1])                                          # just outside: a fresh start
    assert list(client._admit_cache) == [topics[-1]]


def test_agents_known_by_name_are_capped_and_a_known_one_is_still_updated(client):
    for i in range(incoming._MAX_KNOWN_AGENTS - 1):
        client._note_robot_of("agent-%d" % i, "robot_%d" % i)
    client._note_robot_of("inside", "robot_a")       # just inside
    client._note_robot_of("outside", "robot_b")      # just outside
    assert client._robot_of["inside"] == "robot_a" and "outside" not in client._robot_of
    client._note_robot_of("inside", "robot_c")
    assert client._robot_of["inside"] == "robot_c"
