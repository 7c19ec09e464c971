"""Bad input to the offline replay: each case is reported with counts, the replay goes on where
it can, and the exit code says what failed (README: 2 usage, 3 bag unreadable, 4 no scan topic;
bits 8 bag damaged, 16 scans dropped for tf, 32 missing topic / bad content)."""
import io
import json
import os
import shutil

import pytest
import rosbag

from sharing_replay import cli, synth

BLOCK_X = 20.0


def replay(bag, out, *args):
    stdout, stderr = io.StringIO(), io.StringIO()
    code, summary = cli.run([str(bag), "--out-dir", str(out), "--progress", "never"] + list(args), stdout, stderr)
    return code, summary, stdout.getvalue() + stderr.getvalue()


def corridor_robot(ns="robot_0", stuck=18.0):
    return synth.SynthRobot(ns, [(2.0, 6.0), (12.0, 6.0), (18.6, 6.0)], speed=1.0, stuck_at=[stuck])


@pytest.fixture(scope="module")
def good_lz4(tmp_path_factory):
    """30 s, one robot, lz4-compressed: three chunks (100-112 s, 112-128 s, 128-130 s)."""
    path = str(tmp_path_factory.mktemp("bad") / "good.bag")
    synth.write_bag(path, synth.corridor_world(block_x=BLOCK_X), [corridor_robot()], 30.0, compression="lz4")
    return path


def chunks(path):
    with rosbag.Bag(path) as bag:
        return [(c.pos, c.start_time.to_sec(), c.end_time.to_sec()) for c in bag._chunks]


def test_the_good_bag_replays_cleanly(good_lz4, tmp_path):
    assert len(chunks(good_lz4)) >= 3
    code, summary, text = replay(good_lz4, tmp_path)
    assert code == 0, text
    assert summary["scans_processed"] == 300 and summary["obstacles_shared"] >= 1
    assert summary["problems"] == {}


def test_missing_scan_topic_exits_4_and_lists_what_is_there(good_lz4, tmp_path):
    code, summary, text = replay(good_lz4, tmp_path, "--scan-topic", "front_scan")
    assert code == 4 and summary is None
    assert "missing topic" in text and "/robot_0/base_scan" in text
    code, _s, text = replay(good_lz4, tmp_path, "--robots", "robot_0,robot_7")
    assert code == 4 and "robot_7" in text


def test_missing_trigger_topic_is_reported_and_the_scans_still_run(good_lz4, tmp_path):
    code, summary, text = replay(good_lz4, tmp_path, "--trigger", "both")
    assert code == 32
    assert summary["missing_topics"] == ["/robot_0/move_base/recovery_status"]
    # stuck_feedback is there, so the block is still shared.
    assert summary["obstacles_shared"] >= 1 and summary["scans_processed"] == 300


def test_tf_gap_drops_only_the_scans_inside_it(tmp_path):
    bag = tmp_path / "gap.bag"
    synth.write_bag(str(bag), synth.corridor_world(block_x=BLOCK_X), [corridor_robot()], 30.0,
                    tf_gaps=[("robot_0", 5.0, 8.0)])
    code, summary, text = replay(bag, tmp_path / "out")
    assert code == 16, text
    dropped = summary["problems"]["scans_tf_gap"]
    # 30 scans lie in the 3 s gap; the ones within tf_tolerance (0.2 s) of either side are kept.
    assert 24 <= dropped <= 28
    assert summary["scans_dropped"] == dropped
    assert summary["scans_processed"] == 300 - dropped
    assert summary["frames_failed"]["tf_gap"] == {"robot_0/base_laser_link": dropped}
    assert summary["obstacles_shared"] >= 1       # the rest of the bag is replayed
    assert "scans_tf_gap=%d" % dropped in text
    # Interpolating across it needs a longer max gap, and scans that wait long enough for the
    # sample after the gap: then nothing is dropped.
    code, summary, _t = replay(bag, tmp_path / "out2", "--tf-max-gap", "5")
    assert code == 16 and 0 < summary["scans_dropped"] < dropped
    code, summary, _t = replay(bag, tmp_path / "out3", "--tf-max-gap", "5", "--tf-wait", "5")
    assert code == 0 and summary["scans_dropped"] == 0


def test_untransformable_frame_is_counted_per_frame_and_other_robots_go_on(tmp_path):
    bag = tmp_path / "frame.bag"
    r1 = synth.SynthRobot("robot_1", [(38.0, 6.5), (30.0, 6.5)], speed=1.0, stuck_at=[20.0])
    synth.write_bag(str(bag), synth.corridor_world(block_x=BLOCK_X), [corridor_robot(), r1], 30.0,
                    laser_frame_override={"robot_1": "robot_1/laser_without_tf"})
    code, summary, text = replay(bag, tmp_path / "out")
    assert code == 16, text
    assert summary["problems"]["scans_tf_unconnected"] == 300
    assert summary["frames_failed"]["tf_unconnected"] == {"robot_1/laser_without_tf": 300}
    assert summary["scans_processed"] == 300       # robot_0's
    assert summary["obstacles_shared"] >= 1
    assert "robot_1/laser_without_tf x300" in text


def test_truncated_bag_is_reindexed_in_a_copy_and_replayed_up_to_the_cut(good_lz4, tmp_path):
    bag = tmp_path / "truncated.bag"
    shutil.copyfile(good_lz4, bag)
    last_chunk = chunks(good_lz4)[-1]
    with open(bag, "r+b") as handle:
        handle.truncate(last_chunk[0] + 2000)      # inside the last chunk; the index is gone
    size = os.path.getsize(bag)
    code, summary, text = replay(bag, tmp_path / "out")
    assert code & 8, text
    assert summary["problems"]["bag_unindexed"] == 1
    # Everything before the last chunk is there: the block is shared as in the good bag.
    assert 250 <= summary["scans_processed"] < 300
    assert summary["obstacles_shared"] >= 1
    assert os.path.getsize(bag) == size            # the original was not touched
    assert "reindexed copy" in text


def test_damaged_index_is_rebuilt_and_a_bag_cut_before_its_first_chunk_exits_3(good_lz4, tmp_path):
    bag = tmp_path / "index.bag"
    shutil.copyfile(good_lz4, bag)
    size = os.path.getsize(bag)
    with open(bag, "r+b") as handle:          # the index records sit at the end of the file
        handle.seek(size - 300)
        handle.write(b"\x13" * 200)
    code, summary, text = replay(bag, tmp_path / "out")
    assert code & 8, text
    # Reindexing keeps every chunk it can read whole (here all but, at most, the last one).
    assert summary["problems"]["bag_unindexed"] == 1 and 250 <= summary["scans_processed"] <= 300
    first_chunk = chunks(good_lz4)[0][0]
    cut = tmp_path / "cut.bag"
    shutil.copyfile(good_lz4, cut)
    with open(cut, "r+b") as handle:
        handle.truncate(first_chunk + 100)
    code, summary, text = replay(cut, tmp_path / "out2")
    assert code == 3 and summary is None
    assert "holds no message" in text and "no index" in text


def test_corrupted_chunk_is_skipped_with_its_messages_counted(good_lz4, tmp_path):
    bag = tmp_path / "corrupt.bag"
    shutil.copyfile(good_lz4, bag)
    (_p1, _s1, _e1), (pos2, start2, end2), (pos3, _s3, _e3) = chunks(good_lz4)[:3]
    with open(bag, "r+b") as handle:
        handle.seek((pos2 + pos3) // 2)            # the middle of the second chunk's compressed data
        handle.write(b"\xff" * 64)
    # The stuck_feedback (118 s) is in the damaged chunk; trigger by time in the last one instead.
    code, summary, text = replay(bag, tmp_path / "out", "--trigger-at", "29.0")
    assert code == 8, text
    assert summary["problems"]["damaged_chunks"] == 1
    with rosbag.Bag(good_lz4) as good:
        scans = [t.to_sec() for _tp, _m, t in good.read_messages(topics=["/robot_0/base_scan"])]
        lost = [t for t in scans if start2 <= t <= end2]
        lost_all = sum(1 for _tp, _m, t in good.read_messages(topics=["/robot_0/base_scan", "/tf",
                                                                          "/robot_0/stuck_feedback"])
                       if start2 <= t.to_sec() <= end2)
    assert len(lost) > 100
    # Exactly the damaged chunk's messages are lost; the chunk after it is replayed.
    assert summary["scans_processed"] == 300 - len(lost)
    assert summary["problems"]["lost_messages"] == lost_all
    assert summary["obstacles_shared"] >= 1
    assert "unreadable chunk" in text


def test_not_a_bag_and_missing_file_exit_3(tmp_path):
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"#ROSBAG V2.0\n" + os.urandom(5000))
    code, summary, text = replay(junk, tmp_path / "out")
    assert code == 3 and summary is None and "junk.bag" in text
    text_file = tmp_path / "notes.bag"
    text_file.write_text("not a bag at all\n")
    assert replay(text_file, tmp_path / "out")[0] == 3
    code, _s, text = replay(tmp_path / "nope.bag", tmp_path / "out")
    assert code == 3 and "does not exist" in text


def test_bad_parameters_and_maps_exit_2_before_reading(good_lz4, tmp_path):
    cases = [
        (["--obstacle-range", "-1"], "obstacle_range"),
        (["--param", "sharing/proposal_strategy=diagonal"], "proposal_strategy"),
        (["--tf-max-gap", "0"], "tf_max_gap"),
        (["--obstacle-duration", "nan"], "obstacle_duration"),
        (["--map", str(tmp_path / "missing.yaml")], "missing.yaml"),
        (["--map-image", str(tmp_path / "missing.pgm")], "--resolution"),
        (["--params", str(tmp_path / "none.yaml")], "none.yaml"),
        (["--trigger-at", "robot_9@3"], "robot_9"),
    ]
    for args, words in cases:
        code, summary, text = replay(good_lz4, tmp_path / "out", *args)
        assert code == 2, (args, text)
        assert summary is None and words in text, (args, text)


def test_tf_with_bad_values_is_counted(tmp_path):
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    import rospy
    bag = tmp_path / "nan.bag"
    synth.write_bag(str(bag), synth.corridor_world(block_x=BLOCK_X), [corridor_robot()], 10.0)
    with rosbag.Bag(str(bag), "a") as out:
        bad = TransformStamped()
        bad.header.stamp = rospy.Time.from_sec(105.0)
        bad.header.frame_id, bad.child_frame_id = "map", "robot_0/odom"
        bad.transform.translation.x = float("nan")
        bad.transform.rotation.w = 1.0
        out.write("/tf", TFMessage([bad]), bad.header.stamp)
    code, summary, _text = replay(bag, tmp_path / "out")
    assert code == 32
    assert summary["problems"]["tf_rejected"] == 1 and summary["scans_processed"] == 100


def test_plans_in_another_frame_or_with_bad_poses_are_handled_and_a_good_plan_triggers(tmp_path):
    # The plan-blocked trigger reads <ns>/move_base/NavfnROS/plan: a plan in another frame is
    # counted and ignored, non-finite poses are dropped, and the rest of the plan still works.
    import math
    import rospy
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path

    def path(frame, points, t):
        msg = Path()
        msg.header.frame_id, msg.header.stamp = frame, rospy.Time.from_sec(t)
        for x, y in points:
            pose = PoseStamped()
            pose.pose.position.x, pose.pose.position.y, pose.pose.orientation.w = x, y, 1.0
            msg.poses.append(pose)
        return msg

    bag = tmp_path / "plans.bag"
    synth.write_bag(str(bag), synth.corridor_world(block_x=BLOCK_X), [corridor_robot(stuck=1000.0)], 30.0)
    line = [(2.0 + 0.05 * k, 6.0) for k in range(460)]
    topic = "/robot_0/move_base/NavfnROS/plan"
    with rosbag.Bag(str(bag), "a") as out:
        out.write(topic, path("robot_0/odom", line, 100.5), rospy.Time.from_sec(100.5))
        out.write(topic, path("map", [(math.nan, 6.0), (3.0, math.inf)] + line, 101.0), rospy.Time.from_sec(101.0))
    code, summary, text = replay(bag, tmp_path / "out", "--trigger", "none")
    assert code == 0, text
    assert summary["problems"] == {"plans_other_frame": 1}, summary["problems"]
    assert summary["plans"] == 1 and summary["plan_triggers"] >= 1, text
    with open(os.path.join(str(tmp_path / "out"), "events.jsonl"), encoding="utf-8") as handle:
        plans = [json.loads(line) for line in handle if '"plan"' in line]
    assert [(p["poses"], p["dropped"]) for p in plans if p["event"] == "plan"] == [(460, 2)]
    # The block across the corridor at x = 20 is shared from the plan trigger alone.
    assert any(BLOCK_X - 0.3 <= o["rectangle"][0] <= BLOCK_X + 0.3 for o in summary["obstacles"]), summary["obstacles"]
    # Switched off, the same bag shares nothing.
    _code, off, _text = replay(bag, tmp_path / "off", "--trigger", "none", "--plan-topics", "none")
    assert off["obstacles_shared"] == 0 and off["plans"] == 0
