"""The rospy node's fleet-robot footprints through a real mosquitto (issue 12, part 5): the own
footprint topic -> Advertise, a peer's Advertise -> fleet_robots, a robot that stops advertising is
forgotten, bad footprints and bad parameters."""
import json
import time
import uuid as uuidlib

import pytest

from coaty_bridge import footprint as fp
from coaty_bridge.topics import Topic

pytestmark = [pytest.mark.ros, pytest.mark.broker]
OT = fp.DEFAULT_FOOTPRINT_OBJECT_TYPE
SQUARE = [[1.0, 2.0], [1.5, 2.0], [1.5, 2.5], [1.0, 2.5]]


def robot_0_adverts(observer):
    """Footprint adverts robot_0's bridge sent (the test's own bad ones left out)."""
    return [a for a in observer.on("ADV::" + OT)
            if isinstance(a[1], dict) and a[1].get("object", {}).get("name") == "RobotFootprint robot_0"]


def latest_fleet(probe, robot):
    """The last fleet_robots list the probe printed for robot, or None."""
    lists = [e["robots"] for e in list(probe.events) if e.get("event") == "fleet_robots" and e["robot"] == robot]
    return lists[-1] if lists else None


def wait_fleet(probe, robot, predicate, wait_for, timeout=10.0, what="fleet_robots"):
    wait_for(lambda: latest_fleet(probe, robot) is not None and predicate(latest_fleet(probe, robot)),
             timeout=timeout, what=what)
    return latest_fleet(probe, robot)


def test_footprints_are_advertised_received_and_forgotten(ros_graph, broker, observer, wait_for):
    params = ["broker_url:=" + broker.url, "footprint_rate:=10.0", "robot_timeout:=1.0"]
    ros_graph.bridge("robot_0", *params)
    ros_graph.bridge("robot_1", *params)
    probe = ros_graph.probe("robot_0", "robot_1")
    wait_for(lambda: len(observer.on("ADV:Identity/")) >= 2, timeout=15, what="bridges online")

    # robot_0's navigation publishes its footprint: robot_1 learns it, robot_0 never lists itself.
    stop_at = time.monotonic() + 2.0
    while time.monotonic() < stop_at:
        probe.send({"cmd": "footprint", "robot": "robot_0", "frame_id": "map", "points": SQUARE, "stamp": 0.0})
        time.sleep(0.1)
    adverts = robot_0_adverts(observer)
    # a rate, not a count: a loaded machine may run the timer late (judge outcomes, not wall clocks)
    assert len(adverts) >= 2, "robot_0 advertised %d times in 2 s at footprint_rate 10" % len(adverts)
    obj = adverts[-1][1]["object"]
    assert (obj["robot"], obj["frameId"], obj["footprint"]) == ("robot_0", "map", SQUARE)
    assert obj["coreType"] == "CoatyObject" and len({a[1]["object"]["objectId"] for a in adverts}) == 1
    heard = wait_fleet(probe, "robot_1", lambda robots: robots, wait_for, what="robot_1 knows robot_0")
    assert [(r["robot"], r["frame_id"], r["points"]) for r in heard] == [("robot_0", "map", SQUARE)]
    assert heard[0]["stamp"] > 0.0, "the stamp is when robot_1's bridge heard it"
    assert latest_fleet(probe, "robot_0") == [], "robot_0 lists itself"

    # robot_0's footprint topic goes quiet: it stops advertising (an old pose is no use), and robot_1
    # forgets it after robot_timeout.
    quiet = time.monotonic()
    wait_fleet(probe, "robot_1", lambda robots: robots == [], wait_for, what="robot_1 forgets robot_0")
    assert time.monotonic() - quiet >= 0.9
    count = len(robot_0_adverts(observer))
    time.sleep(0.5)
    assert len(robot_0_adverts(observer)) == count, "robot_0 kept advertising a stale footprint"

    # Bad footprints of its own are not advertised; bad adverts of peers are counted and dropped.
    for points, frame in (([[float("nan"), 0.0], [1.0, 0.0], [1.0, 1.0]], "map"), ([], "map"),
                          (SQUARE, ""), ([[0.0, 0.0], [80.0, 0.0], [0.0, 1.0]], "map")):
        probe.send({"cmd": "footprint", "robot": "robot_0", "frame_id": frame, "points": points})
    peer = str(uuidlib.uuid4())
    observer.publish(str(Topic("fleet", "ADV", peer, object_type=OT)), b"{broken")
    observer.publish(str(Topic("fleet", "ADV", peer, object_type=OT)),
                     json.dumps({"object": {"objectType": OT, "robot": "robot_9"}}))

    def counters(event, robot):
        for status in event.get("status", []):
            if status["name"] == "coaty_bridge: " + robot:
                return status["values"]
        return None

    def seen(robot, key, value):
        return lambda e: e.get("event") == "diagnostics" and (counters(e, robot) or {}).get(key) == str(value)
    probe.expect(seen("robot_0", "dropped_own_footprint", 4), timeout=10, what="4 own footprints dropped")
    probe.expect(seen("robot_1", "dropped.invalid_json", 1), timeout=10, what="bad payload counted")
    probe.expect(seen("robot_1", "dropped.missing_field", 1), timeout=10, what="bad object counted")
    time.sleep(0.3)
    assert len(robot_0_adverts(observer)) == count, "a bad own footprint was advertised"
    assert latest_fleet(probe, "robot_1") == []
    for node in ros_graph.nodes[:2]:
        assert node.poll() is None, "a bridge died"


@pytest.mark.parametrize("param, shown", [("footprint_rate:=0.0", "footprint_rate = 0.0"),
                                          ("robot_timeout:=-1.0", "robot_timeout = -1.0"),
                                          ("footprint_rate:=2.0 robot_timeout:=0.5", "robot_timeout = 0.5"),
                                          ("advertise_footprint:=maybe", "advertise_footprint = 'maybe'"),
                                          ("footprint_object_type:=coaty.F", "footprint_object_type = 'coaty.F'")])
def test_bad_footprint_parameters_fail_at_start_up(ros_graph, param, shown):
    node = ros_graph.bridge("robot_0", *param.split())
    out, _ = node.communicate(timeout=20)
    assert node.returncode == 2, out
    assert shown in out
