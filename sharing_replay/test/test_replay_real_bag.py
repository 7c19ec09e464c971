"""Replay of the real stage_ros + move_base recording, in the two excerpts in the repository's data/bags
(data/README.md: what the run holds and how the excerpts were cut).

One PR2 in Willow, a 4 m x 0.4 m block closing the corridor at map x ~ 23 (not in the map), no
local-planner failure at the block (navfn replanned), and one move_base/recovery_status at t = 185.7 s
near map (34.1, 19.2).
"""
import glob
import io
import json
import os

import pytest

from sharing_replay import cli

# The reference data: $FLEET_SHARED_DATA, else the repository's data/.
DATA = os.environ.get("FLEET_SHARED_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__)))), "data")
BLOCK_BAG = os.path.join(DATA, "bags", "willow_blocked_corridor_first_30s.bag")
RECOVERY_BAG = os.path.join(DATA, "bags", "willow_recovery_178s_to_192s.bag")
PARAMS = os.path.join(DATA, "move_base_config", "costmap_common_params.yaml")
pytestmark = pytest.mark.skipif(
    not all(os.path.isfile(p) for p in (BLOCK_BAG, RECOVERY_BAG, PARAMS)),
    reason="the recorded Willow bags are not in %s: they are in the repository's data/bags (data/README.md); "
           "point FLEET_SHARED_DATA at that folder" % DATA)


def replay(out, *args, bag=BLOCK_BAG):
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([bag, "--out-dir", str(out), "--progress", "never", "--params", PARAMS] + list(args),
                            stdout, stderr)
    return code, summary, stdout.getvalue() + stderr.getvalue()


def test_recorded_trigger_shares_nothing_at_the_recovery(tmp_path):
    # The recorded triggers alone (no plan-blocked trigger): move_base never failed at the block,
    # and the one recovery (185.7 s, robot at (34.14, 19.21)) had only walls around it, where the
    # map is occupied or unknown: with unknown cells unshareable it proposes nothing (before, it
    # shared wall cells that Stage has and the map leaves grey).
    code, summary, text = replay(tmp_path, "--plan-topics", "none", bag=RECOVERY_BAG)
    assert code == 0, text
    assert summary["robots"] == ["robot"]
    assert summary["scans_processed"] == 141 and summary["scans_dropped"] == 0
    assert summary["map"].startswith("/map")         # taken from the bag
    assert summary["triggers"] == 1
    with open(os.path.join(str(tmp_path), "events.jsonl"), encoding="utf-8") as handle:
        events = [json.loads(line) for line in handle]
    triggers = [e for e in events if e["event"] == "trigger"]
    assert len(triggers) == 1 and 185.6 <= triggers[0]["time"] <= 185.8, triggers
    assert [e for e in events if e["event"] == "proposal"] == []
    assert summary["obstacles_shared"] == 0, summary["obstacles"]


def test_trigger_at_the_block_shares_the_block_and_not_the_walls(tmp_path):
    # 14 s after the start the robot is at map (21.3, 22.1) and the block 1.5 m ahead.
    code, summary, text = replay(tmp_path, "--trigger", "none", "--trigger-at", "14", "--plan-topics", "none")
    assert code == 0, text
    blocks = [o for o in summary["obstacles"]
              if 22.5 <= o["rectangle"][0] and o["rectangle"][2] <= 23.3 and o["cells_ever"] >= 10]
    assert len(blocks) == 1, summary["obstacles"]
    block = blocks[0]
    # Across the corridor (its free width between y ~ 20.4 and 22.0), well clear of the walls.
    assert block["rectangle"][1] >= 20.3 and block["rectangle"][3] <= 22.1
    assert block["cells_near_walls"] <= 0.2 * block["cells_ever"]
    assert summary["bytes_compact"] < summary["bytes_plain"]


@pytest.mark.parametrize("bag", sorted(glob.glob(os.path.join(DATA, "bags", "*.bag"))) or ["(none)"])
def test_every_recorded_bag_replays_without_damage(bag, tmp_path):
    """Any stage_ros-shaped bag dropped into the data's bags folder replays with the defaults."""
    if not os.path.isfile(bag):
        pytest.skip("no bags in %s" % os.path.join(DATA, "bags"))
    import rosbag
    with rosbag.Bag(bag) as b:
        scans = sum(i.message_count for i in b.get_type_and_topic_info().topics.values()
                    if i.msg_type == "sensor_msgs/LaserScan")
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([bag, "--out-dir", str(tmp_path), "--progress", "never", "--no-png"], stdout, stderr)
    assert summary is not None, stderr.getvalue()
    assert not code & 8, stdout.getvalue()
    assert summary["scans_processed"] + summary["scans_dropped"] == scans
    assert summary["scans_processed"] >= 0.95 * scans, stdout.getvalue()


def cell_xy(summary_map_resolution, size_x, index):
    return ((index % size_x + 0.5) * summary_map_resolution, (index // size_x + 0.5) * summary_map_resolution)


def test_plan_trigger_shares_the_block_with_the_defaults_and_no_cell_by_a_wall(tmp_path):
    # No --trigger-at and default parameters: the bag's navfn plans feed the layer's plan-blocked
    # trigger, which shares the block as it comes into view (about t = 10-19 s), before navfn's
    # detour hides it. The bag's map: willow-full.pgm at 0.1 m, 584 x 526, origin (0, 0).
    code, summary, text = replay(tmp_path)
    assert code == 0, text
    assert summary["plans"] > 0 and summary["plan_triggers"] > 0, text
    resolution, size_x = 0.1, 584
    on_block = []
    for obstacle in summary["obstacles"]:
        # Every cell ever held is listed, so the shares can be checked against the map.
        assert len(obstacle["ever_indexes"]) == obstacle["cells_ever"]
        xs = [cell_xy(resolution, size_x, i) for i in obstacle["ever_indexes"]]
        if all(22.5 <= x <= 23.3 and 19.0 <= y <= 23.0 for x, y in xs):
            on_block.append(obstacle)
    assert on_block, "the block at x ~ 23 was not shared: %s" % summary["obstacles"]
    assert min(o["t"] for o in on_block) < 20.0, on_block
    # Over every obstacle, not a subset: no cell within 0.3 m (3 cells, the replay's default
    # --wall-distance; static_tolerance is 3 cells) of an occupied or unknown map cell, counted by
    # the replay's own false-share check.
    assert summary["false_shares"]["cells_near_walls"] == 0, text
    assert summary["false_shares"]["cells_near_occupied"] == 0 and summary["false_shares"]["cells_near_unknown"] == 0, text
