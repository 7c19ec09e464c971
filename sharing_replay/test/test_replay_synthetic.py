"""Offline replay on synthetic stage_ros-shaped bags whose truth is known (no roscore).

The corridor world: a 40 x 12 m hall, a corridor y in [4, 8] between x = 10 and 30, and a
0.4 m block that closes it at x = 20 (not in the map). A robot drives along the corridor's
centre line and reports stuck_feedback in front of the block.
"""
import io
import json
import math
import os

import numpy as np
import pytest

from sharing_replay import cli, synth

BLOCK_X = 20.0


def replay(bag, out, *args):
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([bag, "--out-dir", str(out), "--progress", "never"] + list(args), stdout, stderr)
    return code, summary, stdout.getvalue(), stderr.getvalue()


def events(out):
    with open(os.path.join(str(out), "events.jsonl"), encoding="utf-8") as handle:
        return [json.loads(line) for line in handle]


def cell_centres(indexes, world):
    sx = world.occupancy.shape[1]
    idx = np.asarray(indexes)
    return np.column_stack(((idx % sx + 0.5) * world.resolution + world.origin[0],
                            (idx // sx + 0.5) * world.resolution + world.origin[1]))


@pytest.fixture(scope="module")
def one_robot(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("synth")
    world = synth.corridor_world(block_x=BLOCK_X)
    robot = synth.SynthRobot("robot_0", [(2.0, 6.0), (12.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[18.0])
    bag = str(tmp / "one.bag")
    synth.write_bag(bag, world, [robot], 30.0, odom_offset=(1.5, -2.0, 0.7))
    return bag, world


def test_block_is_shared_once_with_cells_on_its_face(one_robot, tmp_path):
    bag, world = one_robot
    code, summary, text, _err = replay(bag, tmp_path)
    assert code == 0, text
    assert summary["scans_processed"] == 300 and summary["scans_dropped"] == 0
    assert summary["triggers"] == 1
    assert summary["obstacles_shared"] >= 1
    # Every shared cell lies on the block's near face (x 19.8), never on the corridor walls.
    for obstacle in summary["obstacles"]:
        assert obstacle["cells_near_walls"] <= 2, obstacle
        rx0, ry0, rx1, ry1 = obstacle["rectangle"]
        assert BLOCK_X - 0.35 <= rx0 and rx1 <= BLOCK_X - 0.1, obstacle
        assert 3.9 <= ry0 and ry1 <= 8.1, obstacle
    total = sum(o["cells_ever"] for o in summary["obstacles"])
    # The face is 4 m = 80 cells long; the laser sees most of it from 0.93 m away, and beams
    # that end exactly on x = 19.8 fall into either of the two cell columns next to it.
    assert 60 <= total <= 160, total
    assert "obstacles shared: %d" % summary["obstacles_shared"] in text


def test_events_agree_with_the_summary(one_robot, tmp_path):
    bag, _world = one_robot
    code, summary, _text, _err = replay(bag, tmp_path)
    assert code == 0
    evs = events(tmp_path)
    kinds = [e["event"] for e in evs]
    assert kinds[0] == "trigger" and evs[0]["source"] == "stuck_feedback"
    authorised = [e for e in evs if e["event"] == "authorised"]
    assert len(authorised) == summary["obstacles_shared"]
    assert {e["uuid"] for e in authorised} == {o["uuid"] for o in summary["obstacles"]}
    sent = [e for e in evs if e["event"] in ("authorised", "update")]
    assert sum(e["bytes_plain"] for e in sent) == summary["bytes_plain"]
    assert sum(e["bytes_compact"] for e in sent) == summary["bytes_compact"]
    assert summary["bytes_compact"] < summary["bytes_plain"]
    for e in evs:
        assert e["time"] >= 100.0 and abs(e["t"] - (e["time"] - 100.0)) < 1e-6
        if e["event"] == "proposal":
            assert e["outcome"] in ("authorised", "merged", "dropped")
            assert e["robot_xy"] == pytest.approx([18.6, 6.0], abs=0.05)
    # Proposals come right after the trigger (the next scan), before any update.
    first_prop = kinds.index("proposal")
    assert evs[first_prop]["time"] == pytest.approx(118.0, abs=0.15)
    # The picture is the map (scaled) plus the time bar.
    from PIL import Image
    with Image.open(summary["png"]) as img:
        scale = math.ceil(1000 / 800)
        assert img.size == (800 * scale, 240 * scale + 40)


def test_trigger_at_gives_the_same_obstacles_as_the_recorded_trigger(one_robot, tmp_path):
    bag, _world = one_robot
    _code, recorded, _t, _e = replay(bag, tmp_path / "a")
    code, timed, _t, _e = replay(bag, tmp_path / "b", "--trigger", "none", "--trigger-at", "18.0")
    assert code == 0
    assert [(o["rectangle"], o["cells_ever"]) for o in timed["obstacles"]] == \
        [(o["rectangle"], o["cells_ever"]) for o in recorded["obstacles"]]
    # Same seed, same uuids: outputs can be diffed between parameter sets.
    assert [o["uuid"] for o in timed["obstacles"]] == [o["uuid"] for o in recorded["obstacles"]]


def test_without_trigger_nothing_is_shared_and_the_missing_topic_is_reported(one_robot, tmp_path):
    bag, _world = one_robot
    code, summary, text, _err = replay(bag, tmp_path, "--trigger", "recovery_status")
    assert code == 32
    assert summary["obstacles_shared"] == 0 and summary["scans_processed"] == 300
    assert summary["missing_topics"] == ["/robot_0/move_base/recovery_status"]
    assert "missing topic: /robot_0/move_base/recovery_status" in text


def test_static_tolerance_and_obstacle_range_change_the_result(one_robot, tmp_path):
    bag, _world = one_robot
    _c, base, _t, _e = replay(bag, tmp_path / "a")
    # With a 0.8 m obstacle_range the block (0.93 m ahead of the laser) is never marked: nothing to share.
    _c, short, _t, _e = replay(bag, tmp_path / "b", "--obstacle-range", "0.8")
    assert base["obstacles_shared"] >= 1 and short["obstacles_shared"] == 0
    assert short["proposals"] == 0
    # A static tolerance wider than the distance to the corridor walls swallows the block's ends.
    _c, wide, _t, _e = replay(bag, tmp_path / "c", "--param", "sharing/static_tolerance=10")
    assert sum(o["cells_ever"] for o in wide["obstacles"]) < sum(o["cells_ever"] for o in base["obstacles"])
    assert wide["parameters"]["layer"]["static_tolerance"] == 10


def test_two_robots_share_through_the_fleet_and_expire(tmp_path):
    world = synth.corridor_world(block_x=BLOCK_X)
    r0 = synth.SynthRobot("robot_0", [(2.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[18.0])
    # robot_1 comes from the other side later, sees the block's far face, and gets stuck there too.
    r1 = synth.SynthRobot("robot_1", [(38.0, 6.5), (21.4, 6.5)], speed=1.0, stuck_at=[25.0], start_delay=6.0)
    bag = str(tmp_path / "two.bag")
    synth.write_bag(bag, world, [r0, r1], 50.0)
    code, summary, text, _err = replay(bag, tmp_path / "out", "--obstacle-duration", "15")
    assert code == 0, text
    assert summary["robots"] == ["robot_0", "robot_1"]
    evs = events(tmp_path / "out")
    by_robot = {}
    for e in evs:
        by_robot.setdefault((e["robot"], e["event"]), []).append(e)
    auth0 = by_robot[("robot_0", "authorised")]
    auth1 = by_robot.get(("robot_1", "authorised"), [])
    # robot_1 receives every obstacle robot_0 authorised, at the same time (lossless fleet).
    received = by_robot[("robot_1", "received")]
    assert {e["uuid"] for e in auth0} <= {e["uuid"] for e in received}
    assert all(e["applied"] for e in received)
    # The far face is 0.4 m behind the near one, within merge_distance (0.5 m), but seen by another robot:
    # robot_1 shares it as its own obstacle (issue 43: its cells are never shown, nor its proposal taken as a
    # renewal, under robot_0's name), and robot_0 receives it.
    assert auth1, "robot_1 did not share the far face"
    merged = [e for e in by_robot.get(("robot_1", "proposal"), []) if e["outcome"] == "merged"]
    uuids = {e["uuid"] for e in auth0}
    assert not {e["uuid"] for e in merged} & uuids, by_robot.get(("robot_1", "proposal"))
    back = [e for e in by_robot.get(("robot_0", "received"), []) if e["uuid"] in {e["uuid"] for e in auth1}]
    assert back and all(e["applied"] for e in back)
    # Leases: robot_0 stays in front of the block to the end of the bag, so it keeps renewing the
    # obstacle (an update marking the cells it sees, every lease_renewal_interval, 5 s) and nobody
    # expires it, although its obstacle_duration (15 s) passed.
    renewed = sorted(e["time"] for e in evs if e["event"] == "update" and e["marked"])
    assert len(renewed) >= 5 and renewed[-1] - renewed[0] > 15.0, renewed
    # either robot's observation resets the interval: the next comes 5 s after the last of anyone's
    assert max(b - a for a, b in zip(renewed, renewed[1:])) <= 5.5, renewed
    assert ("robot_0", "expiry") not in by_robot and ("robot_1", "expiry") not in by_robot
    assert summary["expiries"] == 0
    assert summary["received"] == len(received) + len(by_robot.get(("robot_0", "received"), []))


def test_false_shares_next_to_walls_grow_with_the_wall_distance(one_robot, tmp_path):
    bag, _world = one_robot
    near = {}
    for distance in (0, 3, 10, 200):
        code, summary, _t, _e = replay(bag, tmp_path / str(distance), "--wall-distance", str(distance), "--no-png")
        assert code == 0
        fs = summary["false_shares"]
        assert fs["wall_distance_cells"] == distance and fs["cells"] == summary["cells_shared"]
        near[distance] = fs["cells_near_walls"]
        cells = fs["cells"]
        whole = fs["obstacles_all_near_walls"]
    # The block's face runs from wall to wall (y 4..8): with a 10-cell distance its ends (0.5 m
    # each, within the static tolerance of 2 cells already dropped) count; 200 cells covers all.
    assert near[0] == 0
    assert near[3] <= near[10] < cells
    assert 4 <= near[10] <= 25
    assert near[200] == cells and whole == summary["obstacles_shared"]
