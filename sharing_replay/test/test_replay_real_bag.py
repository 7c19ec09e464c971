"""Replay of the real stage_ros + move_base bag in ../shared/data/bags (skipped when absent).

What the bag holds (its README): one PR2 in Willow, a 4 m x 0.4 m block closing the corridor
at map x ~ 23 (not in the map), no local-planner failure at the block (navfn replanned), and
one move_base/recovery_status at t = 185.7 s near map (34.1, 19.2).
"""
import glob
import io
import json
import os

import pytest

from sharing_replay import cli

# The shared data: $FLEET_SHARED_DATA, else ../shared/data beside the repository.
DATA = os.environ.get("FLEET_SHARED_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__)))), "shared", "data")
BAG = os.path.join(DATA, "bags", "willow_blocked_corridor_stage.bag")
PARAMS = os.path.join(DATA, "move_base_config", "costmap_common_params.yaml")
pytestmark = pytest.mark.skipif(not (os.path.isfile(BAG) and os.path.isfile(PARAMS)),
                                reason="the recorded bag %s is not here" % BAG)


def replay(out, *args):
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([BAG, "--out-dir", str(out), "--progress", "never", "--params", PARAMS] + list(args),
                            stdout, stderr)
    return code, summary, stdout.getvalue() + stderr.getvalue()


def test_recorded_trigger_shares_only_at_the_recovery(tmp_path):
    code, summary, text = replay(tmp_path)
    assert code == 0, text
    assert summary["robots"] == ["robot"]
    assert summary["scans_processed"] == 2452 and summary["scans_dropped"] == 0
    assert summary["map"].startswith("/map")         # taken from the bag
    assert summary["triggers"] == 1
    with open(os.path.join(str(tmp_path), "events.jsonl"), encoding="utf-8") as handle:
        events = [json.loads(line) for line in handle]
    proposals = [e for e in events if e["event"] == "proposal"]
    assert proposals, "the recovery at 185.7 s proposed nothing"
    for e in proposals:
        assert 185.7 <= e["time"] <= 185.9
        assert e["robot_xy"] == pytest.approx([34.14, 19.21], abs=0.1)
    # Nothing is shared at the block: move_base never reported a failure there.
    for obstacle in summary["obstacles"]:
        assert obstacle["rectangle"][0] > 30.0, obstacle


def test_trigger_at_the_block_shares_the_block_and_not_the_walls(tmp_path):
    # 14 s after the start the robot is at map (21.3, 22.1) and the block 1.5 m ahead.
    code, summary, text = replay(tmp_path, "--trigger", "none", "--trigger-at", "14")
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
    """Any stage_ros-shaped bag dropped into the shared bags folder replays with the defaults."""
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
