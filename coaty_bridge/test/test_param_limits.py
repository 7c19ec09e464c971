"""Every numeric range of the bridge's parameters and of a received heartbeat, just inside and just outside: a
limit moved by one step (``<=`` for ``<``, a bound off by one) turns one of these red. Pure: no broker, no ROS
master."""
import json

import pytest

from coaty_bridge import footprint as footprints
from coaty_bridge import liveness
from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
from coaty_bridge.security import robot_names


def refusal(**fields):
    """The ValueError text a BridgeConfig of robot_0 with these fields is refused with; "" when it is taken."""
    try:
        BridgeConfig("robot_0", **fields)
    except ValueError as err:
        return str(err)
    return ""


def check(name, value, accepted, why, **others):
    """``name`` = ``value`` (with ``others``) is taken, or refused naming it, its value and ``why``."""
    text = refusal(**dict(others, **{name: value}))
    if accepted:
        assert text == "", text
    else:
        assert text.startswith("parameter %s = %r: %s" % (name, value, why)), text


# ------------------------------------------------------------------------------- BridgeConfig: integers

@pytest.mark.parametrize("name,value,accepted", [
    ("max_payload_bytes", 64, True), ("max_payload_bytes", 63, False),
    ("max_indexes", 1, True), ("max_indexes", 0, False),
    ("offline_queue_size", 0, True), ("offline_queue_size", -1, False),
    ("keepalive", 1, True), ("keepalive", 0, False),
])
def test_integer_parameters_at_their_lower_limit(name, value, accepted):
    """Each least value is taken and one below it refused naming the parameter (a keepalive of 0 would switch
    MQTT's keepalive off, and with it the broker's last will of a lost robot)."""
    check(name, value, accepted, "must be an integer >=")


@pytest.mark.parametrize("value,accepted", [(1, True), (0, False), (1000, True), (1001, False)])
def test_discover_answer_burst_is_1_to_1000(value, accepted):
    """Each Discover answered costs a Resolve per obstacle held: the burst is bounded (issue 27, attack 4)."""
    check("discover_answer_burst", value, accepted, "must be an integer 1..1000")


@pytest.mark.parametrize("name", ["source_message_burst", "source_queue_size"])
@pytest.mark.parametrize("value,accepted", [(1, True), (0, False), (10 ** 7, True), (10 ** 7 + 1, False)])
def test_per_sender_burst_and_queue_are_1_to_10_million(name, value, accepted):
    """A sender's bucket and queue are bounded, so one flooding sender cannot take the bridge's memory."""
    check(name, value, accepted, "must be an integer 1..10000000")


# --------------------------------------------------------------------------------- BridgeConfig: numbers

EVIDENCE_CAPS = (("sensor_reach", 1000.0), ("evidence_window", 3600.0), ("max_robot_speed", 100.0),
                 ("localisation_tolerance", 100.0))


@pytest.mark.parametrize("name,value,accepted", [
    case for name, high in EVIDENCE_CAPS
    for case in ((name, 0.0, True), (name, -0.001, False), (name, high, True), (name, high + 0.001, False))])
def test_evidence_slack_is_0_to_its_cap(name, value, accepted):
    """The slack of plausible evidence (issue 43): 0 and the cap are taken, a hair beyond either is refused
    naming this parameter (not the EvidenceRule it is passed to)."""
    check(name, value, accepted, "must be a number 0..")


@pytest.mark.parametrize("value,accepted", [(0.001, True), (0, False), (1e9 - 0.001, True), (1e9, False)])
def test_source_message_rate_is_above_0_and_below_1e9(value, accepted):
    check("source_message_rate", value, accepted, "must be a positive number of messages per second")


# the other durations a value near a limit needs so that no other rule refuses it
SECONDS_OTHERS = {("reconnect_min_delay", "high"): {"reconnect_max_delay": 1e6 - 0.001},
                  ("reconnect_max_delay", "low"): {"reconnect_min_delay": 0.001},
                  ("liveness_timeout", "low"): {"heartbeat_interval": 0.0005}}


DURATIONS = ("reconnect_min_delay", "reconnect_max_delay", "discover_window", "broker_warn_interval",
             "discover_answer_rate", "heartbeat_interval", "liveness_timeout")


@pytest.mark.parametrize("name,value,accepted", [
    case for name in DURATIONS
    for case in ((name, 0.001, True), (name, 0, False), (name, 1e6 - 0.001, True), (name, 1e6, False))
    if case[:2] != ("heartbeat_interval", 1e6 - 0.001)])   # see the next test
def test_durations_are_above_0_and_below_1e6_s(name, value, accepted):
    """A duration of 0 would spin; 1e6 s is beyond any use."""
    others = SECONDS_OTHERS.get((name, "low" if value < 1 else "high"), {})
    check(name, value, accepted, "must be a positive number of seconds", **others)


def test_a_heartbeat_interval_just_below_1e6_s_passes_its_own_range_and_fails_on_liveness_timeout():
    """Its own range takes it; it cannot be taken, as no liveness_timeout below 1e6 s is twice it."""
    assert refusal(heartbeat_interval=1e6 - 0.001).startswith("parameter liveness_timeout = 3.0: must be at "
                                                              "least twice heartbeat_interval")


@pytest.mark.parametrize("value,accepted", [(2.0, True), (1.999, False)])
def test_liveness_timeout_is_at_least_twice_the_heartbeat_interval(value, accepted):
    """A timeout shorter than two intervals would call one late heartbeat a stall (issue 27, attack 6)."""
    check("liveness_timeout", value, accepted, "must be at least twice heartbeat_interval", heartbeat_interval=1.0)


@pytest.mark.parametrize("value,accepted", [
    (0, True), (-0.001, False), (0.001, False),           # 0: automatic
    (1.0, True), (0.999, False),                          # at least heartbeat_interval
    (liveness.MAX_ANNOUNCED_INTERVAL, True), (liveness.MAX_ANNOUNCED_INTERVAL + 0.001, False),
])
def test_peer_heartbeat_interval_is_0_or_heartbeat_interval_to_the_most_a_peer_takes(value, accepted):
    """Peers drop a heartbeat announcing more than MAX_ANNOUNCED_INTERVAL: a bridge must not send one."""
    check("peer_heartbeat_interval", value, accepted, "must be 0 (automatic", heartbeat_interval=1.0)


@pytest.mark.parametrize("value,accepted", [(0.5, True), (0.499, False)])
def test_reconnect_max_delay_is_at_least_the_min_delay(value, accepted):
    check("reconnect_max_delay", value, accepted, "smaller than reconnect_min_delay", reconnect_min_delay=0.5)


@pytest.mark.parametrize("name", ["footprint_area_size", "obstacle_area_size"])
@pytest.mark.parametrize("value,accepted", [
    (0, True), (-0.001, False), (0.001, False),           # 0: one area
    (footprints.MIN_AREA_SIZE, True), (footprints.MIN_AREA_SIZE - 0.001, False),
    (footprints.MAX_AREA_SIZE, True), (footprints.MAX_AREA_SIZE + 0.001, False),
])
def test_area_sizes_are_0_or_within_the_area_bounds(name, value, accepted):
    """0 is one area for the fleet; otherwise squares of MIN_AREA_SIZE..MAX_AREA_SIZE m (a smaller one would make
    a robot subscribe to many topics for a few metres)."""
    check(name, value, accepted, "must be 0 (one area) or")


@pytest.mark.parametrize("value,accepted", [(0.1, True), (0.099, False),
                                            (footprints.MAX_EXTENT, True), (footprints.MAX_EXTENT + 0.001, False)])
def test_max_footprint_extent_is_a_tenth_of_a_metre_to_the_largest_footprint(value, accepted):
    """A footprint beyond MAX_EXTENT is refused by every decoder: a cap above it would mean nothing."""
    check("max_footprint_extent", value, accepted, "must be 0.1..")


@pytest.mark.parametrize("name,value,accepted", [
    ("max_obstacle_extent", 0.001, True), ("max_obstacle_extent", 0, False),
    ("max_obstacle_extent", 1e6 - 0.001, True), ("max_obstacle_extent", 1e6, False),
    ("max_obstacle_cells", 0, True), ("max_obstacle_cells", -1, False),
    ("max_sensor_reach", 0, True), ("max_sensor_reach", -0.001, False),
    ("max_sensor_reach", 1000.0, True), ("max_sensor_reach", 1000.001, False),
])
def test_obstacle_caps_are_the_handlers_and_refused_naming_them(name, value, accepted):
    """The caps are checked by sharing_msgs' PeerPolicy (its own limits are tested there); the bridge names the
    parameter its error is about."""
    check(name, value, accepted, "")


# ---------------------------------------------------------------------------------- robot counts

ROBOT_COUNTS = [(1, True), (0, False), (10000, True), (10001, False),
                ("1", True), ("0", False), ("10000", True), ("10001", False)]   # robots:=N on a command line


@pytest.mark.parametrize("count,accepted", ROBOT_COUNTS, ids=["%r-%s" % case for case in ROBOT_COUNTS])
def test_a_robot_count_is_1_to_10000(count, accepted):
    """A robot count makes one set of credentials per robot: 0 is no fleet, beyond 10000 is refused."""
    if accepted:
        names = robot_names(count)
        assert len(names) == int(count) and names[-1] == "robot_%d" % (int(count) - 1)
    else:
        with pytest.raises(ValueError, match="a count must be 1..10000"):
            robot_names(count)


# ----------------------------------------------------------------------------- received heartbeats

SENDER = "5f0e1c4e-8a57-4f6e-9a8e-0a1b2c3d4e5f"


def _heartbeat(**fields):
    obj = {"objectType": liveness.OBJECT_TYPE, "coreType": "CoatyObject", "objectId": SENDER, "name": "robot_1",
           "robot": "robot_1", "seq": 1, "interval": 5.0, "heard": 1}
    obj.update(fields)
    return json.dumps({"object": obj}).encode()


def _taken(payload):
    """True when robot_0's client takes this heartbeat of robot_1, False when it drops it as out of range."""
    client = CoatyBridgeClient(BridgeConfig("robot_0"), lambda u, t: None, clock=lambda: 100.0, heartbeats=False)
    client.handle("coaty/3/fleet/CHN:%s/%s" % (liveness.CHANNEL, SENDER), payload)
    counters = client.counters()
    taken, dropped = counters.get("heartbeats_received", 0), counters.get("dropped.out_of_range", 0)
    assert taken + dropped == 1, counters
    return taken == 1


@pytest.mark.parametrize("interval,accepted", [
    (liveness.MIN_ANNOUNCED_INTERVAL, True), (liveness.MIN_ANNOUNCED_INTERVAL - 0.001, False),
    (liveness.MAX_ANNOUNCED_INTERVAL, True), (liveness.MAX_ANNOUNCED_INTERVAL + 0.001, False),
])
def test_a_heartbeats_announced_interval_is_within_the_announced_bounds(interval, accepted):
    """A peer's announced interval sets when it counts as missed: a tiny one would call it missing at once, a
    huge one never."""
    assert _taken(_heartbeat(interval=interval)) is accepted


@pytest.mark.parametrize("heard,accepted", [(0, True), (-1, False), (10 ** 6, True), (10 ** 6 + 1, False)])
def test_a_heartbeats_heard_count_is_0_to_a_million(heard, accepted):
    """``heard`` sizes a joining robot's first interval: a count no fleet reaches is refused, not believed."""
    assert _taken(_heartbeat(heard=heard)) is accepted


@pytest.mark.parametrize("value,accepted", [(0, True), (-0.001, False), (3600, True), (3600.001, False),
                                            (True, False), ("10", False)])
def test_the_bridge_node_waits_0_to_3600_s_for_its_subscribers(value, accepted):
    """How long the node waits for the handler to subscribe before it connects (node.main's ~subscriber_wait)."""
    from coaty_bridge.node import checked_subscriber_wait
    if accepted:
        assert checked_subscriber_wait(value) == float(value)
    else:
        with pytest.raises(ValueError, match=r"parameter subscriber_wait = .*: must be 0\.\.3600 seconds"):
            checked_subscriber_wait(value)
