"""The pure core: blocked edges/nodes become schema-valid state errors and go when the obstacle
goes; master-control blocked areas (3.0 zone sets, 2.x fleetBlockArea) come and go."""
import json

import pytest

from vda5050_bridge import core, schemas

MAN, SER = "acme", "robot_0"


def header(version, hid=1):
    return {"headerId": hid, "timestamp": "2026-11-25T10:00:00.000Z", "version": version,
            "manufacturer": MAN, "serialNumber": SER}


def order_doc(version, order_id="order-1"):
    """A corridor A(0,0) -e1-> B(4,0) -e2-> C(4,4)."""
    def node(nid, seq, x, y):
        n = {"nodeId": nid, "sequenceId": seq, "released": True, "actions": [],
             "nodePosition": {"x": x, "y": y, "mapId": "map"}}
        return n

    def edge(eid, seq, a, b):
        return {"edgeId": eid, "sequenceId": seq, "released": True, "startNodeId": a, "endNodeId": b,
                "actions": []}
    doc = header(version)
    doc.update({"orderId": order_id, "orderUpdateId": 0,
                "nodes": [node("A", 0, 0.0, 0.0), node("B", 2, 4.0, 0.0), node("C", 4, 4.0, 4.0)],
                "edges": [edge("e1", 1, "A", "B"), edge("e2", 3, "B", "C")]})
    return doc


def order_or_skip(version):
    doc = order_doc(version)
    problems = schemas.errors(version, "order", doc)
    assert not problems, problems
    return doc


@pytest.fixture(params=["2.0.0", "2.1.0", "3.0.0"])
def version(request):
    if request.param == "2.0.0":
        request.getfixturevalue("schema_2_0_0")
    return request.param


def refs(error):
    return {r["referenceKey"]: r["referenceValue"] for r in error["errorReferences"]}


def test_segment_rect_geometry():
    rect = (1.0, 1.0, 2.0, 2.0)
    assert core.segment_hits_rect((0, 1.5), (3, 1.5), rect)
    assert not core.segment_hits_rect((0, 0.5), (3, 0.5), rect)
    assert core.segment_hits_rect((0, 0.5), (3, 0.5), rect, margin=0.6)   # widened by half-width
    assert not core.segment_hits_rect((0, 0), (0.9, 0.9), rect)
    assert core.segment_hits_rect((1.5, 1.5), (1.5, 1.5), rect)            # a point (node) inside
    assert core.segment_hits_rect((1.5, 5), (1.5, -5), rect)               # vertical, through


def test_blocked_edge_reported_and_withdrawn(version):
    bridge = core.BridgeCore(version, MAN, SER, half_width=0.3)
    assert bridge.on_message("order", json.dumps(order_or_skip(version)).encode()) is None
    state = bridge.state(100.0)
    assert state["errors"] == [] and [e["edgeId"] for e in state["edgeStates"]] == ["e1", "e2"]
    bridge.set_obstacles([core.Obstacle("u-1", "robot_1", (1.5, 0.2, 2.0, 0.8))])  # 0.2 m off e1's line
    state = bridge.state(101.0)
    assert not schemas.errors(version, "state", state)
    assert len(state["errors"]) == 1
    err = state["errors"][0]
    assert err["errorType"] == "fleetObstacleOnPath" and err["errorLevel"] == "WARNING"
    assert refs(err) == {"edgeId": "e1", "orderId": "order-1", "obstacleId": "u-1", "obstacleSource": "robot_1",
                         "obstacleRectangle": "1.500,0.200,2.000,0.800"}
    bridge.set_obstacles([])  # cleared / expired
    assert bridge.state(102.0)["errors"] == []
    assert state["version"] == version


def test_half_width_decides(version):
    bridge = core.BridgeCore(version, MAN, SER, half_width=0.1)
    bridge.on_message("order", json.dumps(order_or_skip(version)).encode())
    bridge.set_obstacles([core.Obstacle("u-1", "robot_1", (1.5, 0.2, 2.0, 0.8))])
    assert bridge.state(1.0)["errors"] == []


def test_node_and_both_edges_blocked_by_one_obstacle(version):
    bridge = core.BridgeCore(version, MAN, SER)
    bridge.on_message("order", json.dumps(order_or_skip(version)).encode())
    bridge.set_obstacles([core.Obstacle("u-2", "robot_2", (3.8, -0.2, 4.2, 0.2)),
                          core.Obstacle("u-m", core.MASTER_SOURCE, (0.5, -0.1, 1.0, 0.1))])  # not echoed
    state = bridge.state(1.0)
    assert not schemas.errors(version, "state", state)
    got = sorted((list(refs(e).items())[0]) for e in state["errors"])
    assert got == [("edgeId", "e1"), ("edgeId", "e2"), ("nodeId", "B")]


def test_state_without_order_is_valid(version):
    state = core.BridgeCore(version, MAN, SER).state(1.0)
    assert not schemas.errors(version, "state", state)
    assert state["headerId"] == 1


def test_topic_prefix():
    assert core.topic_prefix("uagv", "2.1.0", "acme", "robot_0") == "uagv/v2/acme/robot_0"
    assert core.topic_prefix("uagv", "3.0.0", "acme", "robot_0") == "uagv/v3/acme/robot_0"
    with pytest.raises(ValueError):
        core.topic_prefix("uagv", "3.0.0", "ac/me", "robot_0")


def zone_set_doc(set_id="zs-1", zones=None):
    doc = header("3.0.0")
    doc["zoneSet"] = {"mapId": "map", "zoneSetId": set_id, "zones": zones if zones is not None else [
        {"zoneId": "z-blocked", "zoneType": "BLOCKED",
         "vertices": [{"x": 1.0, "y": -1.0}, {"x": 2.0, "y": -1.0}, {"x": 2.0, "y": 1.0}, {"x": 1.0, "y": 1.0}]},
        {"zoneId": "z-speed", "zoneType": "SPEED_LIMIT", "maximumSpeed": 0.5,
         "vertices": [{"x": 5.0, "y": 5.0}, {"x": 6.0, "y": 5.0}, {"x": 6.0, "y": 6.0}]}]}
    return doc


def actions_doc(version, *actions):
    doc = header(version)
    doc["actions"] = [{"actionId": "a%d" % i, "actionType": t, "blockingType": "NONE",
                       "actionParameters": [{"key": k, "value": v} for k, v in params.items()]}
                      for i, (t, params) in enumerate(actions)]
    assert not schemas.errors(version, "instantActions", doc), schemas.errors(version, "instantActions", doc)
    return doc


def test_zone_set_blocked_zone_enabled_then_deleted():
    bridge = core.BridgeCore("3.0.0", MAN, SER)
    assert bridge.on_message("zoneSet", json.dumps(zone_set_doc()).encode()) is None
    assert bridge.areas.areas() == {}          # received zone sets start DISABLED (§7.6)
    assert bridge.on_message("instantActions", json.dumps(actions_doc(
        "3.0.0", ("enableZoneSet", {"zoneSetId": "zs-1"}))).encode()) is None
    areas = list(bridge.areas.areas().values())
    assert len(areas) == 1 and areas[0].key == "zs-1/z-blocked" and areas[0].rect == (1.0, -1.0, 2.0, 1.0)
    assert areas[0].uuid == core.area_uuid("zs-1/z-blocked")
    bridge.on_message("instantActions", json.dumps(actions_doc(
        "3.0.0", ("deleteZoneSet", {"zoneSetId": "zs-1"}))).encode())
    assert bridge.areas.areas() == {}


def test_enabling_another_zone_set_withdraws_the_first():
    bridge = core.BridgeCore("3.0.0", MAN, SER)
    bridge.on_message("zoneSet", json.dumps(zone_set_doc("zs-1")).encode())
    bridge.on_message("zoneSet", json.dumps(zone_set_doc("zs-2", zones=[])).encode())
    bridge.on_message("instantActions", json.dumps(actions_doc("3.0.0", ("enableZoneSet", {"zoneSetId": "zs-1"}))).encode())
    assert len(bridge.areas.areas()) == 1
    bridge.on_message("instantActions", json.dumps(actions_doc("3.0.0", ("enableZoneSet", {"zoneSetId": "zs-2"}))).encode())
    assert bridge.areas.areas() == {}


def test_fleet_block_area_extension(version):
    bridge = core.BridgeCore(version, MAN, SER)
    square = [{"x": 0.0, "y": 0.0}, {"x": 1.0, "y": 0.0}, {"x": 1.0, "y": 1.0}, {"x": 0.0, "y": 1.0}]
    assert bridge.on_message("instantActions", json.dumps(actions_doc(
        version, (core.BLOCK_ACTION, {"areaId": "door-3", "vertices": square}))).encode()) is None
    assert [a.key for a in bridge.areas.areas().values()] == ["area/door-3"]
    bridge.on_message("instantActions", json.dumps(actions_doc(
        version, (core.UNBLOCK_ACTION, {"areaId": "door-3"}))).encode())
    assert bridge.areas.areas() == {}


def test_cells_in_polygon():
    square = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    cells = core.cells_in_polygon(square, 0.5, -1.0, -1.0, 10, 10)
    assert sorted(cells) == sorted([2 * 10 + 2, 2 * 10 + 3, 3 * 10 + 2, 3 * 10 + 3])
    triangle = [(0.0, 0.0), (2.0, 0.0), (0.0, 2.0)]
    assert len(core.cells_in_polygon(triangle, 0.5, 0.0, 0.0, 10, 10)) == 6
