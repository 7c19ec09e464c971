"""Fleet robots' footprints (issue 12, part 5): the Coaty object, its validation, the table of
heard robots with its timeout (pure), and two bridges advertising over a real mosquitto."""
import dataclasses
import json
import math
import uuid as uuidlib

import pytest

from coaty_bridge import areas, footprint as fp
from coaty_bridge.client import BridgeConfig
from coaty_bridge.errors import CoatyError
from coaty_bridge.topics import Topic

OT = fp.DEFAULT_FOOTPRINT_OBJECT_TYPE
SQUARE = ((1.0, 2.0), (1.65, 2.0), (1.65, 2.65), (1.0, 2.65))


def make(**fields):
    values = dict(robot="robot_1", stamp=1700000000.5, frame_id="map", points=SQUARE)
    values.update(fields)
    return fp.RobotFootprint(**values)


def good_object(**fields):
    obj = fp.footprint_to_object(make(), str(uuidlib.uuid4()))
    obj.update(fields)
    return obj


# ------------------------------------------------------------------------------------- pure codec

def test_object_round_trip_and_shape():
    value = make()
    object_id = str(uuidlib.uuid4())
    obj = fp.footprint_to_object(value, object_id)
    assert obj == {"objectType": OT, "coreType": "CoatyObject", "objectId": object_id,
                   "name": "robot_1", "robot": "robot_1", "stamp": 1700000000.5,
                   "frameId": "map", "footprint": [list(p) for p in SQUARE]}
    assert fp.footprint_from_object(json.loads(json.dumps(obj))) == value
    payload = json.loads(fp.footprint_payload(value, object_id))
    assert fp.decode_footprint_advertise(payload) == value
    # coordinates travel in millimetres (the layers' cells are centimetres)
    assert fp.footprint_to_object(make(points=((1.23456789, -0.0004),)), object_id)["footprint"] == [[1.235, -0.0]]
    # JS writes 2.0 as 2: integers are numbers too
    assert fp.footprint_from_object(good_object(footprint=[[1, 2], [2, 2], [2, 3]], stamp=5)).points == \
        ((1.0, 2.0), (2.0, 2.0), (2.0, 3.0))


BAD_OBJECTS = [
    ("missing robot", lambda o: o.pop("robot"), "missing_field"),
    ("missing footprint", lambda o: o.pop("footprint"), "missing_field"),
    ("missing objectId", lambda o: o.pop("objectId"), "missing_field"),
    ("robot with slash", lambda o: o.update(robot="robot/1"), "invalid_name"),
    ("robot empty", lambda o: o.update(robot=""), "invalid_name"),
    ("robot too long", lambda o: o.update(robot="r" * 300), "invalid_name"),
    ("robot a number", lambda o: o.update(robot=7), "wrong_type"),
    ("objectType other", lambda o: o.update(objectType="org.other.Thing"), "wrong_type"),
    ("coreType other", lambda o: o.update(coreType="Identity"), "wrong_type"),
    ("objectId not a uuid", lambda o: o.update(objectId="x"), "wrong_type"),
    ("name not a string", lambda o: o.update(name=3), "wrong_type"),
    ("stamp a string", lambda o: o.update(stamp="now"), "wrong_type"),
    ("stamp bool", lambda o: o.update(stamp=True), "wrong_type"),
    ("stamp negative", lambda o: o.update(stamp=-1.0), "out_of_range"),
    ("stamp past ROS time", lambda o: o.update(stamp=2.0 ** 32), "out_of_range"),
    ("frameId empty", lambda o: o.update(frameId=""), "out_of_range"),
    ("frameId a list", lambda o: o.update(frameId=["map"]), "wrong_type"),
    ("footprint empty", lambda o: o.update(footprint=[]), "out_of_range"),
    ("footprint a dict", lambda o: o.update(footprint={"x": 1}), "wrong_type"),
    ("vertex of three", lambda o: o.update(footprint=[[1, 2, 3], [1, 2, 3], [1, 2, 3]]), "wrong_type"),
    ("vertex a string", lambda o: o.update(footprint=[[1, "2"], [2, 2], [2, 3]]), "wrong_type"),
    ("vertex huge", lambda o: o.update(footprint=[[1e7, 0], [1e7, 1], [1e7 + 1, 1]]), "out_of_range"),
    ("footprint a building", lambda o: o.update(footprint=[[0, 0], [60, 0], [60, 1]]), "out_of_range"),
    ("too many vertices", lambda o: o.update(footprint=[[0.0, 0.0]] * (fp.MAX_POINTS + 1)), "out_of_range"),
]


@pytest.mark.parametrize("what, spoil, reason", BAD_OBJECTS, ids=[b[0] for b in BAD_OBJECTS])
def test_bad_objects_raise_the_named_error(what, spoil, reason):
    obj = good_object()
    spoil(obj)
    with pytest.raises(CoatyError) as err:
        fp.footprint_from_object(obj)
    assert err.value.reason == reason, (what, err.value)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_values_in_values(bad):
    with pytest.raises(CoatyError) as err:
        make(points=((bad, 0.0), (1.0, 0.0), (1.0, 1.0)))
    assert err.value.reason == "non_finite_number"
    with pytest.raises(CoatyError):
        make(stamp=bad)


def test_advertise_payload_shape_errors():
    with pytest.raises(CoatyError) as err:
        fp.decode_footprint_advertise({"objects": []})
    assert err.value.reason == "missing_field"
    with pytest.raises(CoatyError) as err:
        fp.decode_footprint_advertise({"object": good_object(), "privateData": 3})
    assert err.value.reason == "wrong_type"
    with pytest.raises(CoatyError) as err:
        fp.decode_footprint_advertise({"object": [1, 2]})
    assert err.value.reason == "wrong_type"


def test_config_refuses_bad_footprint_object_types():
    for bad in ("coaty.Footprint", "a/b", "", BridgeConfig("robot_0").object_type):
        with pytest.raises(ValueError, match="footprint_object_type"):
            BridgeConfig("robot_0", footprint_object_type=bad)


# ------------------------------------------------------------------------------- table and timeout

class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_table_keeps_the_latest_forgets_after_the_timeout_and_never_holds_itself():
    clock = FakeClock()
    table = fp.FleetRobotTable("robot_0", 3.0, clock)
    assert not table.heard(make(robot="robot_0"))
    assert table.robots() == []
    assert table.heard(make(robot="robot_2"))
    clock.now = 101.0
    moved = make(robot="robot_1", points=((5.0, 5.0),))
    assert table.heard(make(robot="robot_1")) and table.heard(moved)
    assert [r.footprint for r in table.robots()] == [moved, make(robot="robot_2")]
    assert [r.heard_at for r in table.robots()] == [101.0, 100.0]
    clock.now = 103.0
    assert table.expire() == []
    clock.now = 103.01
    assert table.expire() == ["robot_2"]          # not heard for more than 3 s
    assert [r.footprint.robot for r in table.robots()] == ["robot_1"]
    clock.now = 50.0                              # the clock went back (simulation restarted)
    assert table.expire() == ["robot_1"]
    for bad in (0, -1.0, float("nan"), True, "3"):
        with pytest.raises(ValueError, match="robot_timeout"):
            fp.FleetRobotTable("robot_0", bad, clock)


# ------------------------------------------------------------------------------- over a broker

@pytest.fixture
def make_fleet_client(broker):
    """Clients that record the footprints they receive."""
    from coaty_bridge.client import CoatyBridgeClient
    clients = []

    def create(robot_name, **config):
        config.setdefault("broker_url", broker.url)
        got = []
        client = CoatyBridgeClient(BridgeConfig(robot_name, **config), lambda u, t: None,
                                   on_footprint=lambda f, t: got.append((f, t.source_id)))
        client.footprints = got
        clients.append(client)
        client.start()
        return client
    yield create
    for client in clients:
        client.stop(timeout=0.5)


@pytest.mark.broker
def test_footprint_advert_reaches_the_peer_not_itself(make_fleet_client, observer, wait_for):
    a = make_fleet_client("robot_0")
    b = make_fleet_client("robot_1")
    wait_for(lambda: a.subscribed and b.subscribed, what="both connected")
    wait_for(lambda: len(observer.on("/DSC/")) == 2, what="both subscribed")
    b.note_own_position((4.0, 6.0))   # robot_1 stands in the same 10 m area as robot_0's SQUARE
    mine = make(robot="robot_0")
    wait_for(lambda: a.publish_footprint(mine) and b.footprints, what="robot_1 hears robot_0")
    # the advert carries robot_0's sensor reach (issue 43: the evidence its obstacles are judged by)
    assert b.footprints[0] == (dataclasses.replace(mine, reach=a.config.sensor_reach), a.identity_id)
    # The observer's copy and robot_0's own echo may come after robot_1's copy on a loaded machine.
    wait_for(lambda: observer.on("ADV::" + OT), what="the observer's copy of the advert")
    wait_for(lambda: a.counters()["echoes_suppressed"] >= 1, what="robot_0's own echo, suppressed")
    (topic, data) = observer.on("ADV::" + OT)[0]
    assert topic == "coaty/3/fleet/ADV::%s.area_0_0/%s" % (OT, a.identity_id)
    assert data["object"]["objectType"] == OT + ".area_0_0"
    assert data["object"]["objectId"] == a.footprint_object_id
    assert data["object"]["footprint"] == [list(p) for p in SQUARE] and data["object"]["reach"] == 4.0
    assert a.footprints == [] and a.counters()["echoes_suppressed"] >= 1
    published = a.counters()["footprints_published"]
    assert a.counters()["footprint_bytes_published"] == published * len(
        fp.footprint_payload(dataclasses.replace(mine, reach=4.0), a.footprint_object_id, OT + ".area_0_0"))
    assert "bytes_published" not in a.counters()      # obstacle traffic is counted apart


@pytest.mark.broker
def test_bad_footprint_payloads_are_counted_and_dropped_good_ones_pass(make_fleet_client, observer, wait_for):
    b = make_fleet_client("robot_1")
    wait_for(lambda: b.subscribed and observer.on("/DSC/"), what="robot_1 subscribed")
    sender = str(uuidlib.uuid4())
    topic = str(Topic("fleet", "ADV", sender, object_type=OT))
    bad = [b"not json", b"[1, 2]", b'{"object": {"robot": "robot_2"}}', b'{"object": 3}',
           json.dumps({"object": good_object(robot="a/b")}).encode(),
           json.dumps({"object": good_object(footprint=[[0, 0], [100, 0], [0, 1]])}).encode(),
           b'{"object": {"objectType": "%s", "stamp": NaN}}' % OT.encode()]
    for payload in bad:
        observer.publish(topic, payload)
    # a robot advertising under this robot's own name is not a fleet robot to it
    observer.publish(topic, fp.footprint_payload(make(robot="robot_1"), str(uuidlib.uuid4())))
    observer.publish(topic, fp.footprint_payload(make(robot="robot_2"), str(uuidlib.uuid4())))
    wait_for(lambda: b.footprints, what="the good footprint")
    assert [f.robot for f, _ in b.footprints] == ["robot_2"]
    counters = b.counters()
    dropped = sum(v for k, v in counters.items() if k.startswith("dropped."))
    assert dropped == len(bad), counters
    for reason in ("invalid_json", "wrong_type", "missing_field", "invalid_name", "out_of_range",
                   "non_finite_number"):
        assert counters.get("dropped." + reason), (reason, counters)
    assert counters["footprints_own_name"] == 1 and counters["footprints_received"] == 1


@pytest.mark.broker
def test_forged_footprint_is_dropped_with_authenticated_sources(make_fleet_client, observer, wait_for):
    b = make_fleet_client("robot_1", authenticate_sources=True)
    wait_for(lambda: b.subscribed and observer.on("/DSC/"), what="robot_1 subscribed")
    from coaty_bridge.identity import identity_for
    for sender in (str(uuidlib.uuid4()), identity_for("fleet", "robot_2")):
        observer.publish(str(Topic("fleet", "ADV", sender, object_type=OT)),
                         fp.footprint_payload(make(robot="robot_2"), str(uuidlib.uuid4())))
    wait_for(lambda: b.footprints, what="the authentic footprint")
    assert [src for _f, src in b.footprints] == [identity_for("fleet", "robot_2")]
    assert b.counters()["dropped.forged_source"] == 1


def test_offline_footprints_are_not_queued():
    from coaty_bridge.client import CoatyBridgeClient
    client = CoatyBridgeClient(BridgeConfig("robot_0", broker_url="mqtt://127.0.0.1:1"), lambda u, t: None)
    assert not client.publish_footprint(make(robot="robot_0"))
    assert client.counters()["footprints_not_sent_offline"] == 1 and client.counters()["queue_length"] == 0
    assert math.isclose(make().stamp, 1700000000.5)


def test_a_late_older_advert_does_not_move_a_robot_back_but_a_restarted_clock_does():
    clock = FakeClock()
    table = fp.FleetRobotTable("robot_0", 3.0, clock)
    new, old = make(stamp=50.0, points=((5.0, 5.0),)), make(stamp=49.5, points=((1.0, 1.0),))
    assert table.heard(new) and not table.heard(old)
    assert table.robots()[0].footprint == new
    restarted = make(stamp=1.0, points=((2.0, 2.0),))   # 49 s older: a new simulation, not a late advert
    assert table.heard(restarted) and table.robots()[0].footprint == restarted


# ----------------------------------------------------- convergence of the exclusion (hypothesis)

from hypothesis import given, settings, strategies as st  # noqa: E402


@st.composite
def deliveries(draw):
    """Adverts of up to 3 robots (0.5 s apart in their stamps), each delivered 0-3 times (loss and
    duplicates), in any order, over a short window (one broker bridge's worth of reordering)."""
    adverts = []
    for robot in ("robot_1", "robot_2", "robot_3")[:draw(st.integers(1, 3))]:
        for k in range(draw(st.integers(1, 6))):
            adverts.append(make(robot=robot, stamp=100.0 + 0.5 * k, points=((float(k), float(len(robot))),)))
    copies = [a for a in adverts for _ in range(draw(st.integers(0, 3)))]
    return draw(st.permutations(copies))


@settings(max_examples=600, deadline=None)
@given(deliveries())
def test_every_order_of_adverts_keeps_the_newest_footprint_per_robot(delivered):
    """Whatever the order, duplication and loss, a bridge lists for each robot the newest footprint
    that reached it, so every layer excludes the cells where that robot stands now (and two bridges
    that got the same adverts in different orders list the same robots)."""
    clock = FakeClock()
    one, other = fp.FleetRobotTable("robot_0", 3.0, clock), fp.FleetRobotTable("robot_9", 3.0, clock)
    for advert in delivered:
        one.heard(advert)
    for advert in reversed(delivered):
        other.heard(advert)
    newest = {}
    for advert in delivered:
        if advert.robot not in newest or advert.stamp > newest[advert.robot].stamp:
            newest[advert.robot] = advert
    expected = [newest[name] for name in sorted(newest)]
    assert [r.footprint for r in one.robots()] == expected
    assert [r.footprint for r in other.robots()] == expected


# ------------------------------------------------------------------------------------------ areas

def test_areas_are_floor_squares_and_their_object_types_parse_back():
    assert areas.area_of((0.0, 0.0), 10.0) == (0, 0)
    assert areas.area_of((9.999, -0.001), 10.0) == (0, -1)
    assert areas.area_of((-10.0, 25.0), 10.0) == (-1, 2)
    assert areas.area_object_type(OT, (-1, 2)) == OT + ".area_-1_2"
    assert areas.areas_around((5.0, 5.0), 10.0) == {(x, y) for x in (-1, 0, 1) for y in (-1, 0, 1)}
    for good in (OT, OT + ".area_0_0", OT + ".area_-12_7"):
        assert areas.is_scoped_object_type(good, OT), good
    for bad in ("org.other", OT + ".area_", OT + ".area_1", OT + ".area_1_2_3", OT + ".area_a_1",
                OT + ".area_01_1", OT + ".area_+1_1", OT + ".area_1_ 1", OT + "X", OT + ".areax_1_1"):
        assert not areas.is_scoped_object_type(bad, OT), bad


@pytest.mark.parametrize("bad", [-1.0, 0.5, 1e5, float("nan"), float("inf"), True, "10"])
def test_config_refuses_a_bad_area_size(bad):
    with pytest.raises(ValueError, match="footprint_area_size"):
        BridgeConfig("robot_0", footprint_area_size=bad)


@pytest.mark.broker
def test_a_robot_hears_the_areas_around_it_and_follows_its_own_moves(make_fleet_client, observer, wait_for):
    """Adverts go out per 10 m area; each bridge hears the 3 x 3 areas around its own robot, so a
    robot 25 m away is not heard until one of the two comes near; plain-objectType adverts (a peer
    without areas) are heard anywhere."""
    listener = make_fleet_client("robot_0", footprint_area_size=10.0)   # the positions below are for 10 m areas
    near, far = make_fleet_client("robot_1", footprint_area_size=10.0), make_fleet_client("robot_2", footprint_area_size=10.0)
    wait_for(lambda: listener.subscribed and near.subscribed and far.subscribed and len(observer.on("/DSC/")) == 3,
             what="all subscribed")
    listener.note_own_position((5.0, 5.0))            # area (0, 0): hears x, y in [-10, 20)

    def square(robot, x, y, stamp=1700000000.0):
        return make(robot=robot, stamp=stamp, points=((x, y), (x + 0.6, y), (x + 0.6, y + 0.6), (x, y + 0.6)))

    def heard():
        return {f.robot for f, _ in listener.footprints}
    # robot_1 at (14, 3) in area (1, 0): heard. robot_2 at (30, 5), area (3, 0): not heard.
    wait_for(lambda: near.publish_footprint(square("robot_1", 14.0, 3.0)) and "robot_1" in heard(),
             what="robot_0 hears robot_1 one area over")
    for _ in range(20):
        far.publish_footprint(square("robot_2", 30.0, 5.0))
    near.publish_footprint(square("robot_1", 14.0, 3.0, stamp=1700000001.0))
    wait_for(lambda: [f for f, _ in listener.footprints if f.stamp == 1700000001.0], what="the later robot_1 advert")
    # the observer hears robot_2's connection on its own: MQTT orders per sender only, so robot_1's later
    # advert reaching the listener says nothing about robot_2's 20 having reached the observer yet
    wait_for(lambda: len(observer.on(OT + ".area_3_0/")) >= 20, what="robot_2's 20 adverts under its own area")
    assert len(observer.on(OT + ".area_3_0/")) == 20, "robot_2's adverts went out under its own area"
    assert "robot_2" not in heard(), "an advert from 25 m away, three areas over, was heard"

    # robot_0 drives to (26, 5), area (2, 0): it now hears area 3, where robot_2 stands, and no
    # longer area 0 (robot_1's area 1 stays in range)
    listener.note_own_position((26.0, 5.0))
    wait_for(lambda: far.publish_footprint(square("robot_2", 30.0, 5.0)) and "robot_2" in heard(),
             what="robot_0 hears robot_2 after moving next to it")
    # ... and no longer area 0: robot_1, gone back to (3, 3), is not heard; robot_2's later advert is
    for _ in range(20):
        near.publish_footprint(square("robot_1", 3.0, 3.0, stamp=1700000002.0))
    far.publish_footprint(square("robot_2", 30.0, 5.0, stamp=1700000003.0))
    wait_for(lambda: [f for f, _ in listener.footprints if f.stamp == 1700000003.0], what="robot_2's later advert")
    assert not [f for f, _ in listener.footprints if f.stamp == 1700000002.0], "area (0, 0) still heard"
    # a peer that knows no areas (plain objectType) is heard wherever it stands
    observer.publish(str(Topic("fleet", "ADV", str(uuidlib.uuid4()), object_type=OT)),
                     fp.footprint_payload(square("js_peer", 90.0, 90.0), str(uuidlib.uuid4())))
    wait_for(lambda: "js_peer" in heard(), what="the plain-objectType advert")
    assert listener.counters()["footprint_area_changes"] == 2
    assert not any(k.startswith("dropped.") for k in listener.counters()), listener.counters()


@pytest.mark.broker
def test_without_areas_every_advert_is_heard_under_the_plain_object_type(make_fleet_client, observer, wait_for):
    a = make_fleet_client("robot_0", footprint_area_size=0)
    b = make_fleet_client("robot_1", footprint_area_size=0)
    wait_for(lambda: a.subscribed and b.subscribed and len(observer.on("/DSC/")) == 2, what="both subscribed")
    far = make(robot="robot_0", points=((500.0, 500.0), (500.5, 500.0), (500.5, 500.5)))
    wait_for(lambda: a.publish_footprint(far) and b.footprints, what="robot_1 hears robot_0 500 m away")
    assert observer.on("ADV::" + OT + "/"), "not under the plain objectType"
    assert "footprint_area_changes" not in b.counters()


def test_an_area_change_while_offline_is_subscribed_on_connect(broker, observer, wait_for):
    """The areas follow the robot while the broker is away: the (re)connect subscribes the current ones."""
    from coaty_bridge.client import CoatyBridgeClient
    got = []
    listener = CoatyBridgeClient(BridgeConfig("robot_0", broker_url=broker.url), lambda u, t: None,
                                 on_footprint=lambda f, t: got.append(f))
    listener.note_own_position((105.0, 5.0))     # before it ever connected
    listener.start()
    try:
        wait_for(lambda: listener.subscribed and observer.on("/DSC/"), what="robot_0 subscribed")
        sender = str(uuidlib.uuid4())
        # the square east of robot_0's, at the default footprint_area_size
        size = BridgeConfig("robot_0").footprint_area_size
        ix, iy = areas.area_of((105.0, 5.0), size)
        east = areas.area_object_type(OT, (ix + 1, iy))
        cx, cy = (ix + 1.5) * size, (iy + 0.5) * size
        topic = str(Topic("fleet", "ADV", sender, object_type=east))
        wait_for(lambda: observer.publish(topic, fp.footprint_payload(
            make(robot="robot_5", points=((cx, cy), (cx + 0.5, cy), (cx + 0.5, cy + 0.5))), str(uuidlib.uuid4()),
            east)) or got,
            what="robot_0 hears the square east of its own, %s" % east)
    finally:
        listener.stop(timeout=0.5)


@pytest.mark.parametrize("x, inside", [(9.991, True), (9.989, False), (14.999, True), (15.009, True), (15.011, False)])
def test_a_point_lies_in_a_square_give_or_take_a_centimetre(x, inside):
    # square (2, 0) at 5 m spans x 10..15; the rounding of the wire (millimetres) stays within 0.01 m of it
    assert areas.lies_in((x, 2.0), (2, 0), 5.0) is inside


@pytest.mark.broker
def test_a_peer_advertising_at_another_area_size_is_named_once_and_still_heard(make_fleet_client, observer, wait_for,
                                                                                caplog):
    """A bridge with the old 10 m squares puts a robot at (12.2, 3.2) under area_1_0; at 5 m that point is in square
    (2, 0). Robots of the two sizes miss each other's adverts, so the one that notices says what to set."""
    listener = make_fleet_client("robot_0", footprint_area_size=5.0)
    wait_for(lambda: listener.subscribed, what="robot_0 subscribed")
    listener.note_own_position((7.0, 2.0))     # hears the 5 m squares (0..2, -1..1)
    points = ((12.0, 3.0), (12.5, 3.0), (12.5, 3.5), (12.0, 3.5))
    sender = str(uuidlib.uuid4())

    def advertise(area, robot):
        object_type = areas.area_object_type(OT, area)
        observer.publish(str(Topic("fleet", "ADV", sender, object_type=object_type)),
                         fp.footprint_payload(make(robot=robot, points=points), str(uuidlib.uuid4()), object_type))

    caplog.set_level("WARNING", logger="coaty_bridge.client")
    wait_for(lambda: advertise((2, 0), "robot_5") or any(f.robot == "robot_5" for f, _ in listener.footprints),
             what="robot_5's advert in the right square")
    assert listener.counters().get("footprint_area_mismatches", 0) == 0
    for _ in range(2):
        advertise((1, 0), "robot_7")
    wait_for(lambda: sum(f.robot == "robot_7" for f, _ in listener.footprints) == 2,
             what="robot_7's two adverts, still taken")
    assert listener.counters()["footprint_area_mismatches"] == 2
    warnings = [r.getMessage() for r in caplog.records if "another area size" in r.getMessage()]
    assert len(warnings) == 1, warnings
    assert "'robot_7'" in warnings[0] and "(2, 0)" in warnings[0] and "footprint_area_size 5 m" in warnings[0]
