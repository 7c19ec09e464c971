"""Interop with the real Coaty JS library (@coaty/core 2.4.1 from the npm registry).

The library is installed once into a cache outside the repo
(``$FLEET_COATY_CACHE`` or ~/.cache/fleet-coaty-interop) and reused. If npm cannot
reach the registry the test is skipped with the npm error as the reason.
"""
import json
import os
import shutil
import signal
import subprocess
import time
import uuid as uuidlib

import pytest

from coaty_bridge.broker import Broker

pytestmark = [pytest.mark.npm, pytest.mark.broker, pytest.mark.ros]

HERE = os.path.dirname(os.path.abspath(__file__))
CACHE = os.environ.get("FLEET_COATY_CACHE", os.path.expanduser("~/.cache/fleet-coaty-interop"))
PACKAGES = ["@coaty/core@2.4.1", "rxjs@^6.6.7"]
OT = "org.fleetsharing.SharedObstacle"
FOOTPRINT_OT = "org.fleetsharing.RobotFootprint"
# robot_0's advert below stands at (1.25, 2.25): the 10 m area (0, 0), footprint_area_size's default
FOOTPRINT_AREA_OT = FOOTPRINT_OT + ".area_0_0"
NETWORK_ERRORS = ("ENOTFOUND", "EAI_AGAIN", "ECONNREFUSED", "ECONNRESET", "ETIMEDOUT", "ENETUNREACH",
                  "network", "proxy")


def installed_version():
    try:
        with open(os.path.join(CACHE, "node_modules", "@coaty", "core", "package.json")) as meta:
            return json.load(meta).get("version")
    except (OSError, ValueError):
        return None


@pytest.fixture(scope="module")
def coaty_js():
    """The cache directory holding node_modules/@coaty/core 2.4.1."""
    if not shutil.which("node") or not shutil.which("npm"):
        pytest.skip("node/npm not installed")
    if installed_version() != "2.4.1":
        os.makedirs(CACHE, exist_ok=True)
        proc = subprocess.run(["npm", "install", "--prefix", CACHE, "--legacy-peer-deps", "--no-audit",
                               "--no-fund"] + PACKAGES, capture_output=True, text=True, timeout=240)
        if proc.returncode != 0:
            text = proc.stdout + proc.stderr
            if any(marker in text for marker in NETWORK_ERRORS):
                pytest.skip("npm registry unreachable, Coaty JS interop not tested: %s" % text.strip()[-300:])
            raise AssertionError("npm install failed: %s" % text[-1000:])
        assert installed_version() == "2.4.1", "npm did not install @coaty/core 2.4.1"
    return CACHE


def ros_obstacle(source, **fields):
    # 64 cells in a row, so the compact form is the deflated one; 3 scattered cleared cells.
    # (all inside the rectangle: x 255..284, y 5..34 on this grid)
    msg = dict(uuid=str(uuidlib.uuid4()), marked_indexes=[y * 2000 + x for y in (5, 6, 7) for x in range(255, 277)][:64]
               + [30 * 2000 + 260, 34 * 2000 + 284], cleared_indexes=[8 * 2000 + 255, 20 * 2000 + 270, 34 * 2000 + 255],
               deadline=90, rectangle_shape=[0.25, 7.5, 1.75, 9.0], source=source,
               resolution=0.05000000074505806, origin_x=-12.5, origin_y=7.25, size_x=2000, size_y=2000,
               version=1, stamp=1700000123.5, frame_id="map")
    msg.update(fields)
    return msg


def js_obstacle():
    oid = str(uuidlib.uuid4())
    # Written as a JS program would: 1 rather than 1.0, plain index arrays.
    return {"objectType": OT, "coreType": "CoatyObject", "objectId": oid, "name": "js obstacle",
            "uuid": oid, "source": "js_peer", "version": 2, "stamp": 1700000200, "frameId": "map",
            "deadline": 30, "rectangle": [3, -5, 5, -3], "resolution": 1, "origin": [0, -5], "size": [20, 10],
            "markedIndexes": [3, 4, 23], "clearedIndexes": []}          # each cell inside the rectangle


def test_coaty_js_peer_and_bridges_interoperate(coaty_js, ros_graph, json_lines_process):
    with Broker() as broker:
        params = ["broker_url:=" + broker.url, "namespace:=fleet"]
        robot_0 = ros_graph.bridge("robot_0", *params)
        probe = ros_graph.probe("robot_0", "robot_1")
        peer = json_lines_process(
            "coaty_js_peer", ["node", os.path.join(HERE, "coaty_js_peer.js"), broker.url, "fleet", OT, FOOTPRINT_AREA_OT],
            env=dict(os.environ, NODE_PATH=os.path.join(coaty_js, "node_modules")), cwd=coaty_js)
        try:
            peer.expect(lambda e: e.get("event") == "ready", what="Coaty JS agent online")

            # (c) the peer discovers our Identity
            identity = None
            for _ in range(20):
                peer.send({"cmd": "discoverIdentities"})
                try:
                    identity = peer.expect(lambda e: e.get("event") == "identity" and
                                           e["object"]["name"] == "robot_0", timeout=1.0, what="robot_0")["object"]
                    break
                except AssertionError:
                    continue  # the bridge is still starting
            assert identity, "(c) Coaty JS never discovered robot_0's Identity"
            assert identity["coreType"] == "Identity" and identity["objectType"] == "coaty.Identity"

            # (a) an obstacle our bridge publishes reaches the peer with every field intact
            mine = ros_obstacle("robot_0")
            # robot_0's footprint taken at the obstacle's stamp: the evidence it goes out with (else it would wait up
            # to 5 s for one and go out with its deadline aged)
            square = [[1.0, 2.0], [1.5, 2.0], [1.5, 2.5], [1.0, 2.5]]
            for _ in range(30):        # the bridge has it once it advertised it: the peer sees that
                probe.send({"cmd": "footprint", "robot": "robot_0", "frame_id": "map", "points": square,
                            "stamp": mine["stamp"]})
                if [e for e in peer.events if e.get("event") == "footprint"]:
                    break
                time.sleep(0.1)
            probe.send({"cmd": "to_fleet", "robot": "robot_0", "msg": mine})
            seen = peer.expect(lambda e: e.get("event") == "advertise" and e["object"]["uuid"] == mine["uuid"],
                               what="(a) robot_0's obstacle at the Coaty JS peer")
            obj = seen["object"]
            assert obj["objectId"] == mine["uuid"] and obj["source"] == "robot_0" and obj["version"] == 1
            assert obj["markedIndexes"].startswith("z:") and not obj["clearedIndexes"].startswith("z:")
            assert seen["marked"] == mine["marked_indexes"] and seen["cleared"] == mine["cleared_indexes"]
            assert obj["rectangle"] == mine["rectangle_shape"] and obj["deadline"] == 90
            assert obj["origin"] == [-12.5, 7.25] and obj["size"] == [2000, 2000]
            assert obj["resolution"] == pytest.approx(0.05) and obj["stamp"] == 1700000123.5
            assert obj["frameId"] == "map" and "parentObjectId" not in obj

            # (b) an obstacle the peer publishes reaches ROS on from_fleet, numbers cast
            theirs = js_obstacle()
            peer.send({"cmd": "publish", "object": theirs})
            got = probe.expect(lambda e: e.get("event") == "from_fleet" and e["robot"] == "robot_0" and
                               e["msg"]["uuid"] == theirs["uuid"], what="(b) the JS obstacle on robot_0/from_fleet")
            msg = got["msg"]
            assert msg["marked_indexes"] == [3, 4, 23] and msg["cleared_indexes"] == []
            assert msg["resolution"] == 1.0 and msg["types"]["resolution"] == "float"
            assert (msg["origin_x"], msg["origin_y"]) == (0.0, -5.0) and msg["types"]["origin_x"] == "float"
            assert (msg["size_x"], msg["size_y"], msg["version"], msg["deadline"]) == (20, 10, 2, 30)
            assert msg["source"] == "js_peer" and msg["stamp"] == 1700000200.0
            assert not [e for e in probe.events if e.get("event") == "from_fleet" and e["msg"]["uuid"] == mine["uuid"]], \
                "robot_0's own obstacle came back to it"

            # (e) robot footprints: robot_0's advert reaches the Coaty JS peer as a valid CoatyObject, and
            # a footprint the peer advertises (integers as JS writes them) is listed on robot_0/fleet_robots
            for _ in range(30):
                probe.send({"cmd": "footprint", "robot": "robot_0", "frame_id": "map", "points": square})
                if [e for e in peer.events if e.get("event") == "footprint"]:
                    break
                time.sleep(0.1)
            seen = peer.expect(lambda e: e.get("event") == "footprint", what="(e) robot_0's footprint at the peer")
            assert seen["object"]["robot"] == "robot_0" and seen["object"]["footprint"] == square
            assert seen["object"]["coreType"] == "CoatyObject" and seen["object"]["frameId"] == "map"
            assert seen["object"]["objectType"] == FOOTPRINT_AREA_OT
            # the peer advertises under the plain objectType (it knows no areas): every bridge hears that
            peer.send({"cmd": "publishFootprint", "object": {
                "objectType": FOOTPRINT_OT, "coreType": "CoatyObject", "objectId": str(uuidlib.uuid4()),
                "name": "RobotFootprint js_peer", "robot": "js_peer", "stamp": 1700000300, "frameId": "map",
                "footprint": [[4, 4], [5, 4], [5, 5]]}})
            listed = probe.expect(lambda e: e.get("event") == "fleet_robots" and e["robot"] == "robot_0" and
                                  e["robots"], what="(e) the JS peer's footprint on robot_0/fleet_robots")
            assert [(r["robot"], r["points"]) for r in listed["robots"]] == [
                ("js_peer", [[4.0, 4.0], [5.0, 4.0], [5.0, 5.0]])]

            # (d) a bridge started late gets the obstacles already in the fleet: robot_0's
            # (from its shared_obstacle_list) and the JS peer's (the peer answers Discover too). The Resolves
            # answering its Discover restore state, so they come on robot_1/fleet_state, not from_fleet (issue 43:
            # the handler never takes them as an observation or a renewal)
            probe.send({"cmd": "list", "robot": "robot_0", "msgs": [mine]})
            probe.expect(lambda e: e.get("event") == "sent", what="list sent")
            sent = len([e for e in probe.events if e.get("event") == "sent"])
            probe.send({"cmd": "watch_state", "robot": "robot_1"})
            probe.expect(lambda e: len([s for s in probe.events if s.get("event") == "sent"]) > sent,
                         what="robot_1/fleet_state subscribed")
            ros_graph.bridge("robot_1", *params)
            for uuid in (mine["uuid"], theirs["uuid"]):
                probe.expect(lambda e: e.get("event") == "fleet_state" and e["robot"] == "robot_1" and
                             e["msg"]["uuid"] == uuid, timeout=20, what="(d) obstacle %s at late robot_1" % uuid)
            late = {e["msg"]["uuid"]: e["msg"] for e in probe.events if e.get("event") == "fleet_state"
                    and e["robot"] == "robot_1"}
            assert late[mine["uuid"]]["marked_indexes"] == mine["marked_indexes"]
            assert late[mine["uuid"]]["source"] == "robot_0"
            assert late[theirs["uuid"]]["marked_indexes"] == [3, 4, 23] and late[theirs["uuid"]]["source"] == "js_peer"
            # theirs is in no list of robot_0's: the JS peer's own answer brought it
            peer.expect(lambda e: e.get("event") == "discoverAnswered" and e["count"] >= 1,
                        what="(d) the Coaty JS peer answered robot_1's Discover")
            assert not [e for e in probe.events if e.get("event") == "from_fleet" and e["robot"] == "robot_1"
                        and e["msg"]["uuid"] in late], "a Resolve restoring state came on from_fleet as an observation"

            # (c) the peer sees the Deadvertise of a killed bridge (the last will)
            robot_0.send_signal(signal.SIGKILL)
            robot_0.wait(5)
            peer.expect(lambda e: e.get("event") == "deadvertise" and identity["objectId"] in e["objectIds"],
                        what="(c) robot_0's last-will Deadvertise at the Coaty JS peer")
        finally:
            peer.send({"cmd": "exit"}) if peer.proc.poll() is None else None
            peer.stop()


def test_renewals_events_pass_between_a_bridge_and_coaty_js(coaty_js, json_lines_process, make_update):
    """A bridge's renewals event (issue 29) is a Channel event Coaty JS takes as valid and reads whole,
    and one a JS program writes (integers for floats, plain index arrays) renews at a bridge."""
    from coaty_bridge.client import BridgeConfig, CoatyBridgeClient
    with Broker() as broker:
        peer = json_lines_process(
            "coaty_js_peer", ["node", os.path.join(HERE, "coaty_js_peer.js"), broker.url, "fleet", OT],
            env=dict(os.environ, NODE_PATH=os.path.join(coaty_js, "node_modules")), cwd=coaty_js)
        now = [1000.0]
        source = CoatyBridgeClient(BridgeConfig("robot_0", broker_url=broker.url), lambda u, t: None,
                                   clock=lambda: now[0])
        got = []
        receiver = CoatyBridgeClient(BridgeConfig("robot_1", broker_url=broker.url), lambda u, t: got.append(u))
        try:
            source.start()
            receiver.start()
            peer.expect(lambda e: e.get("event") == "ready", what="Coaty JS agent online")
            deadline = time.monotonic() + 10
            while not (source.subscribed and receiver.subscribed) and time.monotonic() < deadline:
                time.sleep(0.05)
            source.note_own_position((5.0, 5.0))
            first = make_update(version=1, deadline=100)
            # shared until the peer has it: then its subscriptions are in place (the renewals channel is
            # observed before the Advertise); 'ready' comes before they are
            for _ in range(30):
                assert source.publish_obstacle(first)
                try:
                    peer.expect(lambda e: e.get("event") == "advertise" and e["object"]["objectId"] == first.uuid,
                                timeout=1.0, what="the first share at Coaty JS")
                    break
                except AssertionError:
                    continue
            now[0] = 1010.0
            assert source.publish_obstacle(make_update(uuid=first.uuid, version=2, marked=(880250,), cleared=(),
                                                       deadline=100))
            now[0] = 1090.0
            assert source.renew_due() == 1
            seen = peer.expect(lambda e: e.get("event") == "renewals", what="the renewals event at Coaty JS")
            obj = seen["object"]
            assert seen["sourceId"] == source.identity_id and obj["coreType"] == "CoatyObject"
            assert obj["source"] == "robot_0" and obj["size"] == [2000, 2000]
            assert [(e[0], e[1], e[3]) for e in obj["obstacles"]] == [(first.uuid, 2, 20)]

            # written as a JS program would: 1 for 1.0, plain arrays of indexes
            theirs = str(uuidlib.uuid4())
            peer.send({"cmd": "publishRenewals", "object": {
                "objectType": "org.fleetsharing.ObstacleRenewals", "coreType": "CoatyObject",
                "objectId": str(uuidlib.uuid4()), "name": "js_peer", "source": "js_peer", "frameId": "map",
                "resolution": 1, "origin": [0, -5], "size": [20, 10],
                "obstacles": [[theirs, 3, 1700000200, 30, [3, -5, 5, -4], [3, 4], []]]}})   # cells in the rectangle
            deadline = time.monotonic() + 10
            while not [u for u in got if u.uuid == theirs] and time.monotonic() < deadline:
                time.sleep(0.05)
            renewed = [u for u in got if u.uuid == theirs]
            assert renewed, "the JS renewal never reached robot_1: %s" % receiver.counters()
            assert (renewed[0].version, renewed[0].deadline, renewed[0].marked) == (3, 30, (3, 4))
            assert renewed[0].resolution == 1.0 and renewed[0].origin_y == -5.0
        finally:
            source.stop(timeout=0.5)
            receiver.stop(timeout=0.5)
            peer.send({"cmd": "exit"}) if peer.proc.poll() is None else None
            peer.stop()
