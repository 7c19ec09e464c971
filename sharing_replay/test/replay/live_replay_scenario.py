#!/usr/bin/python3
"""Test node of live_replay.test: record a live share with record_bag.launch, replay it offline,
compare with what the live sharing_handler holds."""
import io
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import unittest

import actionlib
import rospy
import rostest
from move_base_msgs.msg import MoveBaseAction
from sharing_msgs.msg import SharedObstacleArray
from sharing_msgs.srv import ListObstacles

from sharing_replay import cli
from fleet_nav.goals import move_base_goal

# A replayed obstacle matches a live one when their cell sets differ by at most this share
# of the larger set (the live layer and the replay see the same scans; the live handler's
# answer arrives a few ms later, so one scan's monitoring update may fall on either side).
CELL_TOLERANCE = 0.15


def jaccard_distance(a, b):
    a, b = set(a), set(b)
    if not a and not b:
        return 0.0
    return 1.0 - len(a & b) / float(len(a | b))


class LiveReplay(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("live_replay_scenario")
        cls.tmp = tempfile.mkdtemp(prefix="live_replay_")
        cls.bag = os.path.join(cls.tmp, "live.bag")
        cls.lists = []
        rospy.Subscriber("/robot_0/shared_obstacle_list", SharedObstacleArray, cls.lists.append)
        cls.client = actionlib.SimpleActionClient("/robot_0/move_base", MoveBaseAction)
        assert cls.client.wait_for_server(rospy.Duration(60.0)), "robot_0/move_base never came up"
        rospy.wait_for_service("/robot_0/list_obstacles", 60.0)
        # The recorder: the simulator's own launch file, as a user would start it.
        cls.recorder = subprocess.Popen(["roslaunch", "fleet_sim", "record_bag.launch", "bag:=" + cls.bag],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                        start_new_session=True)
        give_up = time.monotonic() + 30.0
        while not os.path.exists(cls.bag + ".active") and time.monotonic() < give_up:
            time.sleep(0.1)
        assert os.path.exists(cls.bag + ".active"), "rosbag record did not start"
        time.sleep(2.0)   # let it subscribe to every topic (the latched /map included)

    @classmethod
    def tearDownClass(cls):
        if cls.recorder.poll() is None:
            os.killpg(cls.recorder.pid, signal.SIGKILL)
        if os.environ.get("LIVE_REPLAY_KEEP"):
            rospy.loginfo("live_replay: kept %s", cls.tmp)
        else:
            shutil.rmtree(cls.tmp, ignore_errors=True)

    def stop_recording(self):
        os.killpg(self.recorder.pid, signal.SIGINT)
        try:
            self.recorder.wait(30.0)
        except subprocess.TimeoutExpired:
            os.killpg(self.recorder.pid, signal.SIGKILL)
            self.fail("roslaunch record_bag.launch did not stop on SIGINT")
        give_up = time.monotonic() + 10.0
        while os.path.exists(self.bag + ".active") and time.monotonic() < give_up:
            time.sleep(0.1)
        self.assertTrue(os.path.isfile(self.bag), "no bag written")

    def test_replay_shares_what_the_live_run_shared(self):
        gx, gy, gyaw = rospy.get_param("~goal")
        self.client.send_goal(move_base_goal(gx, gy, gyaw))
        # Wait for the share, then a few simulated seconds of monitoring while the robot turns away.
        give_up = time.monotonic() + 100.0
        while not (self.lists and self.lists[-1].obstacles) and time.monotonic() < give_up:
            time.sleep(0.2)
        self.assertTrue(self.lists and self.lists[-1].obstacles, "the live run shared nothing within 100 s")
        shared_at = rospy.get_time()
        while rospy.get_time() < shared_at + 6.0 and time.monotonic() < give_up + 20.0:
            time.sleep(0.1)
        live = list(rospy.ServiceProxy("/robot_0/list_obstacles", ListObstacles)().obstacles)
        time.sleep(0.5)
        self.client.cancel_all_goals()
        self.stop_recording()

        # record_bag.launch recorded the stage_ros shape and what the sharing nodes said.
        import rosbag
        with rosbag.Bag(self.bag) as bag:
            topics = set(bag.get_type_and_topic_info().topics)
        for topic in ("/map", "/tf", "/clock", "/robot_0/base_scan", "/robot_0/odom", "/robot_0/stuck_feedback",
                      "/robot_0/obstacle_proposals", "/robot_0/shared_obstacle_list", "/robot_0/to_fleet"):
            self.assertIn(topic, topics)
        self.assertNotIn("/rosout", topics)

        stdout, stderr = io.StringIO(), io.StringIO()
        # The live run has the plan trigger off (live_replay.test), so the replay has too.
        code, summary = cli.run([self.bag, "--out-dir", os.path.join(self.tmp, "replay"), "--progress", "never",
                                 "--plan-topics", "none",
                                 "--params", rospy.get_param("~params_file"),
                                 "--obstacle-duration", str(rospy.get_param("~obstacle_duration"))], stdout, stderr)
        report = "live: %s\nreplay:\n%s\n%s" % (
            [(o.uuid[:8], [round(v, 2) for v in o.rectangle_shape], len(o.marked_indexes)) for o in live],
            stdout.getvalue(), stderr.getvalue())
        rospy.loginfo(report)
        self.assertEqual(0, code, report)
        self.assertEqual(["robot_0"], summary["robots"])
        self.assertGreater(summary["triggers"], 0, "no stuck_feedback in the bag\n" + report)
        # Same count.
        self.assertEqual(len(live), summary["obstacles_shared"], report)
        # Each live obstacle has a replayed one with the same rectangle (within a cell) and cells.
        replayed = list(summary["obstacles"])
        resolution = 0.05
        for obstacle in live:
            rect = list(obstacle.rectangle_shape)
            best = min(replayed, key=lambda r: max(abs(a - b) for a, b in zip(r["rectangle"], rect)))
            self.assertLessEqual(max(abs(a - b) for a, b in zip(best["rectangle"], rect)), resolution + 1e-3, report)
            distance = jaccard_distance(obstacle.marked_indexes, best["final_indexes"])
            self.assertLessEqual(distance, CELL_TOLERANCE, "cells differ by %.2f\n%s" % (distance, report))
            replayed.remove(best)
        # And it is the block that was shared: cells on its face, not on the corridor walls.
        fx, fy0, fy1 = rospy.get_param("~block_face")
        all_cells = [c for o in live for c in o.marked_indexes]
        size_x = 600
        xs = [(c % size_x + 0.5) * resolution for c in all_cells]
        ys = [(c // size_x + 0.5) * resolution for c in all_cells]
        self.assertTrue(all(abs(x - fx) <= 0.15 for x in xs), report)
        self.assertTrue(all(fy0 - 0.1 <= y <= fy1 + 0.1 for y in ys), report)
        with open(os.path.join(self.tmp, "replay", "events.jsonl"), encoding="utf-8") as handle:
            kinds = [json.loads(line)["event"] for line in handle]
        self.assertIn("authorised", kinds)


if __name__ == "__main__":
    rostest.rosrun("sharing_replay", "live_replay", LiveReplay)
