"""Bad VDA 5050 input: each one is dropped with one log line and one counter, nothing raises,
and the state built from the good messages before it is unchanged."""
import json
import math

from hypothesis import given, settings, strategies as st

from vda5050_bridge import core
from test_vda_core import MAN, SER, actions_doc, order_doc, zone_set_doc

SQUARE = [{"x": 0.0, "y": 0.0}, {"x": 1.0, "y": 0.0}, {"x": 1.0, "y": 1.0}, {"x": 0.0, "y": 1.0}]


def ready_bridge(version="3.0.0"):
    bridge = core.BridgeCore(version, MAN, SER, limits=core.Limits(max_payload_bytes=65536, max_extent=50.0))
    assert bridge.on_message("order", json.dumps(order_doc(version)).encode()) is None
    assert bridge.on_message("instantActions", json.dumps(actions_doc(
        version, (core.BLOCK_ACTION, {"areaId": "good", "vertices": SQUARE}))).encode()) is None
    bridge.set_obstacles([core.Obstacle("u-1", "robot_1", (1.5, -0.1, 2.0, 0.1))])
    return bridge


def snapshot(bridge):
    state = bridge.state(5.0)
    return json.dumps({k: v for k, v in state.items() if k not in ("headerId",)}, sort_keys=True), \
        sorted(bridge.areas.areas())


def dropped(bridge):
    return sum(v for k, v in bridge.counters.items() if k.startswith("dropped."))


BAD = [
    ("order", b"{not json", "invalid_json"),
    ("order", b"\xff\xfe", "invalid_json"),
    ("order", b"[1, 2]", "schema_violation"),
    ("order", b'{"orderId": NaN}', "invalid_json"),
    ("order", json.dumps(dict(order_doc("3.0.0"), nodes="x")).encode(), "schema_violation"),
    ("order", json.dumps(dict(order_doc("3.0.0"), serialNumber="robot_9")).encode(), "wrong_vehicle"),
    ("order", json.dumps(dict(order_doc("3.0.0"), version="2.1.0")).encode(), "wrong_version"),
    ("order", b"[" * 100000 + b"]" * 100000, "oversized"),
    ("order", b"[" * 5000 + b"]" * 5000, "invalid_json"),
    ("zoneSet", json.dumps(zone_set_doc("bad-1", zones=[{"zoneId": "z", "zoneType": "BLOCKED", "vertices": [
        {"x": 0, "y": 0}, {"x": 1000, "y": 0}, {"x": 0, "y": 1}]}])).encode(), "absurd_zone"),
    ("zoneSet", json.dumps(zone_set_doc("bad-2", zones=[{"zoneId": "z", "zoneType": "BLOCKED", "vertices": [
        {"x": 0, "y": 0}, {"x": 1, "y": 1}, {"x": 2, "y": 2}]}])).encode(), "absurd_zone"),
    ("zoneSet", json.dumps(zone_set_doc("bad-3", zones=[{"zoneId": "z", "zoneType": "BLOCKED", "vertices": [
        {"x": 0, "y": 0}, {"x": 1}]}])).encode(), "schema_violation"),
    ("zoneSet", json.dumps(zone_set_doc("bad-4", zones=[{"zoneId": "z", "zoneType": "BLOCKED", "vertices": [
        {"x": 0, "y": 0}, {"x": 1e300, "y": 0}, {"x": 0, "y": 1}]}])).encode(), "absurd_zone"),
    ("instantActions", json.dumps(actions_doc("3.0.0", (core.BLOCK_ACTION, {"areaId": "x", "vertices": "no"}))).encode(),
     "absurd_zone"),
    ("instantActions", json.dumps(actions_doc("3.0.0", (core.BLOCK_ACTION, {"areaId": 7, "vertices": SQUARE}))).encode(),
     "absurd_zone"),
    ("instantActions", json.dumps(actions_doc("3.0.0", (core.BLOCK_ACTION, {"areaId": "b", "vertices": [
        {"x": True, "y": 0}, {"x": 1, "y": 0}, {"x": 0, "y": 1}]}))).encode(), "absurd_zone"),
    ("instantActions", json.dumps(actions_doc("3.0.0", ("enableZoneSet", {"zoneSetId": "nope"}))).encode(),
     "unknown_zone_set"),
    ("nonsense", b"{}", "unknown_topic"),
]


def test_each_bad_input_is_one_counted_drop_and_loses_nothing():
    bridge = ready_bridge()
    before = snapshot(bridge)
    for topic, payload, reason in BAD:
        n = bridge.counters["dropped." + reason]
        line = bridge.on_message(topic, payload)
        assert line is not None and "\n" not in line and reason in line, (topic, reason, line)
        assert bridge.counters["dropped." + reason] == n + 1, (topic, reason, dict(bridge.counters))
        assert snapshot(bridge) == before, (topic, reason)
    assert dropped(bridge) == len(BAD)


def test_a_bad_action_in_a_batch_changes_nothing():
    bridge = ready_bridge()
    before = snapshot(bridge)
    doc = actions_doc("3.0.0", (core.UNBLOCK_ACTION, {"areaId": "good"}),
                      (core.BLOCK_ACTION, {"areaId": "bad", "vertices": SQUARE[:2]}))
    assert "absurd_zone" in bridge.on_message("instantActions", json.dumps(doc).encode())
    assert snapshot(bridge) == before


json_values = st.recursive(st.none() | st.booleans() | st.floats(allow_nan=False) | st.integers() | st.text(max_size=8),
                           lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
                           max_leaves=20)


def _mutate(doc, path, value):
    target = doc
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return doc


PATHS = [("orderId",), ("nodes",), ("nodes", 0), ("nodes", 0, "nodePosition"), ("nodes", 1, "nodePosition", "x"),
         ("edges", 0, "startNodeId"), ("edges",), ("headerId",), ("version",), ("orderUpdateId",)]
ZPATHS = [("zoneSet",), ("zoneSet", "zones"), ("zoneSet", "zones", 0, "vertices"), ("zoneSet", "zones", 0, "vertices", 0),
          ("zoneSet", "zones", 0, "vertices", 1, "x"), ("zoneSet", "zones", 0, "zoneType"), ("zoneSet", "zoneSetId")]


@settings(max_examples=300, deadline=None)
@given(st.integers(0, len(PATHS) - 1), json_values, st.integers(0, len(ZPATHS) - 1), json_values,
       st.binary(max_size=64))
def test_fuzz_mutated_and_random_payloads_never_raise(i, value, j, zvalue, raw):
    bridge = ready_bridge()
    before = snapshot(bridge)
    total = 0
    for topic, payload in (("order", json.dumps(_mutate(order_doc("3.0.0"), PATHS[i], value))),
                           ("zoneSet", json.dumps(_mutate(zone_set_doc("fz"), ZPATHS[j], zvalue))),
                           ("order", raw), ("instantActions", raw), ("zoneSet", raw)):
        line = bridge.on_message(topic, payload.encode() if isinstance(payload, str) else payload)
        total += 1
        assert "dropped.internal_error" not in bridge.counters, line
        if line is not None:
            assert "\n" not in line
    taken = sum(v for k, v in bridge.counters.items() if k.startswith("received."))
    assert taken + dropped(bridge) == total + 2  # ready_bridge's two good messages
    # a dropped order keeps the old one; a good mutated one replaces it, still a valid state
    state = bridge.state(6.0)
    assert all(math.isfinite(float(v)) for e in state["errors"] for r in e["errorReferences"]
               if r["referenceKey"] == "x" for v in [r["referenceValue"]])
    if bridge.counters["received.order"] == 1:
        assert snapshot(bridge)[0] == before[0]
