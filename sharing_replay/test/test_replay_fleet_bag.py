"""Replay of a recorded five-robot fleet bag: it shares what the live fleet shared, and never a robot.

test/replay/data/fleet5_corridors.bag: the README's fleet (fleet.launch robots:=5 layout:=corridors,
our stand-ins, with 271-beam lasers to keep the bag small), every robot sent at once to the top hall
(record_fleet_bag.py, cut to its first 14 s). The short corridor is closed by a block that is not in
the map; robot_0 shares it (6.2 s), robot_2 adds a cell to it, robot_0 another 17; the robots drive
one behind the other and see each other all the time, and the live layers, which exclude the robots
their bridges hear of, never share one. The bag holds what each live handler sent to the fleet
(to_fleet), the scans, tf, plans, footprints, /map and the simulator's ground truth (in this world
the map frame is Stage's world frame, so ground truth is a map pose).
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import rosbag

from sharing_replay import cli, report
from sharing_replay.bag_reader import BagSource
from sharing_replay.runner import Replay

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(os.path.dirname(HERE), "scripts", "replay")
BAG = os.path.join(HERE, "replay", "data", "fleet5_corridors.bag")
PARAMS = os.path.join(os.path.dirname(HERE), "..", "launch", "config", "move_base", "costmap_common_params.yaml")
ROBOTS = ["robot_%d" % i for i in range(5)]
# A cell is a robot's when its centre lies within this distance of another robot's true centre when it
# was shared: the footprint's farthest point (0.46 m) plus half a cell's diagonal.
ROBOT_REACH = 0.46 + 0.05 * math.sqrt(2) / 2
# Live and replay see the same scans, but a live node may drop one under load (its queue holds 2) and a
# monitoring update may fall either side of a scan: the cell sets may differ by this share of their union.
CELL_TOLERANCE = 0.15


def live_obstacles(bag_path):
    """{uuid: {"source", "cells" (every cell ever marked)}} from the robots' to_fleet in the bag."""
    out = {}
    with rosbag.Bag(bag_path) as bag:
        for _topic, msg, _t in bag.read_messages(topics=["/%s/to_fleet" % r for r in ROBOTS]):
            entry = out.setdefault(msg.uuid, {"source": None, "cells": set()})
            if msg.version == 1:
                entry["source"] = msg.source
            entry["cells"].update(msg.marked_indexes)
    return out


def ground_truth(bag_path):
    """{robot: (times, xy array)} of the simulator's true poses."""
    poses = {r: ([], []) for r in ROBOTS}
    with rosbag.Bag(bag_path) as bag:
        for topic, msg, _t in bag.read_messages(topics=["/%s/base_pose_ground_truth" % r for r in ROBOTS]):
            times, xy = poses[topic.split("/")[1]]
            times.append(msg.header.stamp.to_sec())
            xy.append((msg.pose.pose.position.x, msg.pose.pose.position.y))
    return {r: (np.asarray(t), np.asarray(xy)) for r, (t, xy) in poses.items()}


def run_replay(bag_path, *args):
    """The replay as the command line runs it; returns (exit code, Replay, stderr)."""
    argv = [bag_path, "--params", PARAMS, "--no-png", "--progress", "never"] + list(args)
    settings = cli.settings_from_args(cli.build_parser().parse_args(argv))
    source = BagSource(bag_path)
    try:
        replay = Replay(settings)
        replay.run(source)
    finally:
        source.close()
    return report.exit_code(replay), replay


def cells_on_robots(replay, truth):
    """(obstacle uuid, sharer, robot it lies on, cell) of every shared cell within ROBOT_REACH of another
    robot's true position at the time the cell was first shared."""
    m = replay.map
    found = []
    for uuid, record in replay.obstacles.items():
        for cell, when in record["cell_time"].items():
            x = m.origin_x + (cell % m.size_x + 0.5) * m.resolution
            y = m.origin_y + (cell // m.size_x + 0.5) * m.resolution
            for robot, (times, xy) in truth.items():
                if robot == record["robot"] or not len(times):
                    continue
                k = int(np.argmin(np.abs(times - when)))
                if math.hypot(x - xy[k, 0], y - xy[k, 1]) <= ROBOT_REACH:
                    found.append((uuid, record["robot"], robot, cell))
    return found


def jaccard_distance(a, b):
    return 1.0 - len(a & b) / float(len(a | b)) if a | b else 0.0


def matched(replayed, live):
    """Obstacles paired by shared cells: every replayed one overlaps a live one and every live one a
    replayed one (merging may join or split them), and the cells of both sides agree as a whole."""
    replay_cells = {u: set(r["cell_time"]) for u, r in replayed.items()}
    for uuid, cells in replay_cells.items():
        assert any(cells & o["cells"] for o in live.values()), "replayed %s matches nothing live" % uuid
    for uuid, o in live.items():
        assert any(o["cells"] & c for c in replay_cells.values()), "live %s (from %s) not replayed" % (uuid, o["source"])
    everything_replayed = set().union(*replay_cells.values()) if replay_cells else set()
    everything_live = set().union(*(o["cells"] for o in live.values())) if live else set()
    return jaccard_distance(everything_replayed, everything_live)


@pytest.fixture(scope="module")
def truth():
    return ground_truth(BAG)


def test_the_bag_is_what_the_test_needs(truth):
    with rosbag.Bag(BAG) as bag:
        topics = bag.get_type_and_topic_info().topics
    for robot in ROBOTS:
        for name in ("base_scan", "move_base/NavfnROS/plan", "move_base/global_costmap/footprint",
                     "base_pose_ground_truth"):
            assert "/%s/%s" % (robot, name) in topics, (robot, name)
    live = live_obstacles(BAG)
    assert [o["source"] for o in live.values()] == ["robot_0"], live     # one obstacle, the block
    assert all(len(truth[r][0]) > 100 for r in ROBOTS)


def test_replay_shares_what_the_live_fleet_shared_and_no_robot(truth):
    code, replay = run_replay(BAG)
    assert code == 0, dict(replay.problems)
    assert replay.missing_topics == [] and not replay.notes, dict(replay.notes)
    live = live_obstacles(BAG)
    assert len(replay.obstacles) == len(live) == 1
    assert matched(replay.obstacles, live) <= CELL_TOLERANCE
    assert cells_on_robots(replay, truth) == []
    # Each robot's exclusion knew the four others, with the footprints the bag recorded.
    assert sorted(replay.others.frames) == ROBOTS
    assert sorted(replay.others.shapes) == ROBOTS
    assert {layer.core.fleet_robots.trail for layer in replay.robots.values()} == {1.0}


def test_without_recorded_footprints_the_parameters_place_the_robots(truth, tmp_path):
    """A bag recorded before footprints were recorded: the footprint of --params at tf's poses."""
    stripped = str(tmp_path / "no_footprints.bag")
    with rosbag.Bag(BAG) as src, rosbag.Bag(stripped, "w") as dst:
        for topic, msg, t, header in src.read_messages(raw=True, return_connection_header=True):
            if not topic.endswith("/footprint"):
                dst.write(topic, msg, t, raw=True, connection_header=header)
    code, replay = run_replay(stripped)
    assert code == 0
    assert replay.others.shapes == {}
    assert len(replay.obstacles) == 1 and matched(replay.obstacles, live_obstacles(BAG)) <= CELL_TOLERANCE
    assert cells_on_robots(replay, truth) == []


def test_the_bag_would_show_robots_without_the_exclusion(truth):
    """What the check above guards against: a layer without the exclusion shares the robots it sees
    in front of it (the issue's replay: several obstacles on robots where the fleet shared one)."""
    _code, replay = run_replay(BAG, "--no-robot-exclusion")
    on_robots = cells_on_robots(replay, truth)
    assert len(replay.obstacles) > 1
    assert len({uuid for uuid, _s, _r, _c in on_robots}) >= 2, on_robots


def test_command_line_replays_the_fleet_bag_clean(tmp_path):
    """The user's command, `rosrun sharing_replay replay BAG` at the defaults: exit 0 and nothing on stderr
    (stuck_feedback and recovery_status, which a fleet in its default mode never publishes, are not
    warnings); the summary names the robots excluded."""
    proc = subprocess.run([sys.executable, SCRIPT, BAG, "--out-dir", str(tmp_path), "--progress", "never", "--no-png"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stderr == ""
    assert "obstacles shared: 1 " in proc.stdout
    assert "other robots never shared: robot_0, robot_1, robot_2, robot_3, robot_4 (placed from tf; footprint " \
           "recorded: robot_0, robot_1, robot_2, robot_3, robot_4; margin 0.2 m, trail 1 s)" in proc.stdout, proc.stdout
    with open(os.path.join(str(tmp_path), "summary.json"), encoding="utf-8") as handle:
        summary = json.load(handle)
    assert summary["robot_exclusion"]["robots"] == {r: "recorded footprint" for r in ROBOTS}
