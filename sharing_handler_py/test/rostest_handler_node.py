#!/usr/bin/python3
"""rostest: the sharing_handler node in robot_0, driven through fake layer and bridge topics.

Every flow of DESIGN.md §5.5-§5.11 as the layer and the bridge see it, the bad-input drops on
/diagnostics and /rosout, the services, the latched list, the YAML snapshot and a start-up
failure on a bad parameter. The tests run in name order and build on each other's state.
"""
import os
import re
import subprocess
import sys
import threading
import time
import unittest

import rospy
from visualization_msgs.msg import MarkerArray
import rostest
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import OccupancyGrid
from rosgraph_msgs.msg import Log
from sharing_msgs.msg import SharedObstacle, SharedObstacleArray
from sharing_msgs.srv import AddObstacle, ListObstacles, RemoveObstacle
from std_msgs.msg import String

NS = "/robot_0/"
RES, OX, OY, SX, SY = 0.05, -5.0, -2.5, 200, 100
UUID4 = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}$")
HERE = os.path.dirname(os.path.abspath(__file__))
# Fleet messages carry UUIDs (sharing_msgs.obstacle_rules); fixed ones keep the test readable.
EXT1 = "00000000-0000-4000-8000-00000000e001"
SHORT1 = "00000000-0000-4000-8000-00000000e002"


def at(x, y):
    """The cell whose centre is nearest (x, y) on the test map: every cell of a message lies inside its
    rectangle (issue 43)."""
    return int(round((y - OY) / RES - 0.5)) * SX + int(round((x - OX) / RES - 0.5))


P = at(0.025, 0.025)     # the first cell of the own obstacle's rectangle (0, 0, 0.5, 0.5); P + k along x
Q = at(0.525, 0.275)     # inside (0.25, 0.25, 1.0, 1.0), outside (0, 0, 0.5, 0.5)
E = at(2.025, 0.025)     # the first cell of ext-1's rectangle (2.0, 0.0, 2.5, 0.5)
S = at(3.225, 0.025)     # the first cell of short-1's rectangle (3.2, 0.0, 3.7, 0.5)


def obstacle(uuid="", marked=(), cleared=(), deadline=30, rect=(0.0, 0.0, 0.5, 0.5), source="robot_1",
             version=1, grid=(RES, OX, OY, SX, SY)):
    msg = SharedObstacle()
    msg.header.frame_id = "map"
    msg.header.stamp = rospy.Time.now()
    msg.uuid = uuid
    msg.marked_indexes = list(marked)
    msg.cleared_indexes = list(cleared)
    msg.deadline = deadline
    msg.rectangle_shape = list(rect)
    msg.source = source
    msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y = grid
    msg.version = version
    return msg


def wait_for(predicate, timeout=5.0, what="condition"):
    end = time.time() + timeout
    while time.time() < end:
        if predicate():
            return
        time.sleep(0.02)
    raise AssertionError("timed out after %.1f s waiting for %s" % (timeout, what))


class Bus:
    """Fake layer and bridge: publishers into the node and recorders of what it sends."""

    def __init__(self):
        self.lock = threading.Lock()
        self.shared, self.fleet, self.expired, self.rosout = [], [], [], []
        self.list = None
        self.diag = None
        sub = rospy.Subscriber
        sub(NS + "shared_obstacles", SharedObstacle, self._rec(self.shared), queue_size=1000)
        sub(NS + "to_fleet", SharedObstacle, self._rec(self.fleet), queue_size=1000)
        sub(NS + "expired_obstacles", String, lambda m: self._rec(self.expired)(m.data), queue_size=100)
        sub(NS + "shared_obstacle_list", SharedObstacleArray, self._on_list, queue_size=10)
        # fleet_obstacle_markers is subscribed late, in test_06b (the first array a late subscriber gets)
        self.first_markers = None
        self.markers = None
        sub("/diagnostics", DiagnosticArray, self._on_diag, queue_size=100)
        sub("/rosout", Log, self._on_rosout, queue_size=1000)
        self.proposals = rospy.Publisher(NS + "obstacle_proposals", SharedObstacle, queue_size=100)
        self.updates = rospy.Publisher(NS + "obstacle_updates", SharedObstacle, queue_size=100)
        self.from_fleet = rospy.Publisher(NS + "from_fleet", SharedObstacle, queue_size=100)
        self.map = rospy.Publisher("/map", OccupancyGrid, queue_size=1, latch=True)
        grid = OccupancyGrid()
        grid.header.frame_id = "map"
        grid.info.resolution, grid.info.width, grid.info.height = RES, SX, SY
        grid.info.origin.position.x, grid.info.origin.position.y = OX, OY
        grid.info.origin.orientation.w = 1.0
        grid.data = [0] * (SX * SY)
        self.map.publish(grid)

    def _rec(self, sink):
        def record(msg):
            with self.lock:
                sink.append(msg)
        return record

    def _on_list(self, msg):
        self.list = msg

    def _on_markers(self, msg):
        with self.lock:
            if self.first_markers is None:
                self.first_markers = msg
        self.markers = msg

    def subscribe_markers(self):
        self.first_markers = None
        rospy.Subscriber(NS + "fleet_obstacle_markers", MarkerArray, self._on_markers, queue_size=10)

    def labels(self, array=None):
        array = array or self.markers
        return [m.text for m in array.markers if m.ns == "fleet_obstacles/labels"] if array else []

    def _on_diag(self, msg):
        for status in msg.status:
            if status.name == "sharing_handler (robot_0)":
                self.diag = {kv.key: kv.value for kv in status.values}

    def _on_rosout(self, msg):
        if msg.name == NS + "sharing_handler":
            with self.lock:
                self.rosout.append(msg.msg)

    def counter(self, name):
        return int(self.diag[name]) if self.diag and name in self.diag else None

    def listed(self):
        return {o.uuid: o for o in self.list.obstacles} if self.list else {}


class TestHandlerNode(unittest.TestCase):
    bus = None
    own = None  # the obstacle robot_0 authorised

    @classmethod
    def setUpClass(cls):
        rospy.init_node("rostest_handler_node")
        cls.bus = Bus()
        for pub in (cls.bus.proposals, cls.bus.updates, cls.bus.from_fleet, cls.bus.map):
            wait_for(lambda: pub.get_num_connections() > 0, 15, "the node to subscribe %s" % pub.name)
        rospy.wait_for_service(NS + "list_obstacles", 15)
        wait_for(lambda: cls.bus.diag is not None and cls.bus.diag.get("grid") != "unknown", 10,
                 "the node to learn the grid from /map")
        cls.list_srv = rospy.ServiceProxy(NS + "list_obstacles", ListObstacles)
        cls.add_srv = rospy.ServiceProxy(NS + "add_obstacle", AddObstacle)

    def test_01_proposal_is_authorised_back_to_the_layer_and_out_to_the_fleet(self):
        bus = self.bus
        bus.proposals.publish(obstacle(marked=(P + 5, P + 3, P + 4), rect=(0.0, 0.0, 0.5, 0.5),
                                       source="robot_0", version=0, deadline=0))
        wait_for(lambda: bus.shared and bus.fleet, what="the authorised obstacle")
        shared = bus.shared[0]
        self.assertRegex(shared.uuid, UUID4)
        self.assertEqual((shared.version, shared.source, shared.deadline), (1, "robot_0", 60))
        self.assertEqual(list(shared.marked_indexes), [P + 5, P + 3, P + 4])
        self.assertEqual(bus.fleet[0].uuid, shared.uuid)
        wait_for(lambda: shared.uuid in bus.listed(), what="the latched list")
        listed = bus.listed()[shared.uuid]
        self.assertEqual(list(listed.marked_indexes), [P + 3, P + 4, P + 5])
        self.assertEqual(list(listed.cleared_indexes), [])
        self.assertEqual((listed.version, listed.source), (1, "robot_0"))
        self.assertTrue(55 <= listed.deadline <= 60, listed.deadline)
        type(self).own = shared

    def test_02_overlapping_proposal_is_an_update_of_the_live_obstacle(self):
        bus = self.bus
        bus.proposals.publish(obstacle(marked=(Q,), rect=(0.25, 0.25, 1.0, 1.0), source="robot_0",
                                       version=0, deadline=0))
        wait_for(lambda: bus.counter("merged_proposals") == 1, what="merged_proposals = 1 on /diagnostics")
        self.assertEqual(bus.counter("proposals"), 2)
        wait_for(lambda: (len(bus.shared), len(bus.fleet)) == (2, 2), what="the update to the layer and fleet")
        for m in (bus.shared[1], bus.fleet[1]):
            self.assertEqual((m.uuid, m.version, list(m.marked_indexes)), (self.own.uuid, 2, [Q]))
            self.assertEqual(list(m.rectangle_shape), [0.0, 0.0, 1.0, 1.0])
        wait_for(lambda: list(bus.listed()[self.own.uuid].marked_indexes) == [P + 3, P + 4, P + 5, Q],
                 what="the merged cells in the list")

    def test_03_internal_update_goes_to_the_fleet_and_is_applied_not_echoed(self):
        bus = self.bus
        bus.updates.publish(obstacle(uuid=self.own.uuid, marked=(P + 6,), cleared=(P + 3,), version=2,
                                     source="robot_0", deadline=60, rect=(0.0, 0.0, 0.5, 0.5)))
        wait_for(lambda: len(bus.fleet) == 3, what="the update on to_fleet")
        # version 2 is taken (the merged proposal): re-stamped 3
        self.assertEqual((bus.fleet[2].uuid, bus.fleet[2].version), (self.own.uuid, 3))
        wait_for(lambda: list(bus.listed()[self.own.uuid].marked_indexes) == [P + 4, P + 5, P + 6, Q],
                 what="the update applied in the list")
        self.assertEqual(bus.listed()[self.own.uuid].version, 3)
        self.assertEqual(len(bus.shared), 2, "internal updates are not sent back to the layer")

    def test_04_external_add_and_update_go_to_the_layer_and_never_back_out(self):
        bus = self.bus
        before = time.time()
        bus.from_fleet.publish(obstacle(uuid=EXT1, marked=(E, E + 1, E + 2), version=1, deadline=30,
                                        rect=(2.0, 0.0, 2.5, 0.5), source="robot_1"))
        wait_for(lambda: EXT1 in bus.listed(), what="ext-1 in the list")
        bus.from_fleet.publish(obstacle(uuid=EXT1, marked=(E + 2, E + 3), cleared=(E,), version=2,
                                        deadline=30, rect=(2.0, 0.0, 2.5, 0.5), source="robot_2"))
        wait_for(lambda: list(bus.listed()[EXT1].marked_indexes) == [E + 1, E + 2, E + 3],
                 what="ext-1 updated")
        self.assertEqual([m.uuid for m in bus.shared[2:]], [EXT1, EXT1])
        self.assertEqual([m.version for m in bus.shared[2:]], [1, 2])
        self.assertEqual(len(bus.fleet), 3, "external messages are never sent back out")
        listed = bus.listed()[EXT1]
        self.assertEqual((listed.source, listed.version), ("robot_1", 2))
        reply = self.list_srv()
        index = [o.uuid for o in reply.obstacles].index(EXT1)
        self.assertAlmostEqual(reply.arrival_times[index], before, delta=2.0)
        self.assertTrue(27 < reply.remaining_seconds[index] <= 30, reply.remaining_seconds[index])
        self.assertEqual(list(reply.obstacles[index].marked_indexes), [E + 1, E + 2, E + 3])
        self.assertEqual(sorted(o.uuid for o in reply.obstacles), sorted([self.own.uuid, EXT1]))

    def test_05_bad_fleet_messages_are_dropped_logged_and_counted(self):
        bus = self.bus
        good = dict(uuid=EXT1, marked=(E + 5,), version=5, source="robot_9", deadline=30,
                    rect=(2.0, 0.0, 2.5, 0.5))
        bad = {
            "empty_uuid": dict(uuid=""),
            "index_out_of_range": dict(marked=(SX * SY,)),
            "too_many_cells": dict(marked=range(5001)),
            "geometry_mismatch": dict(grid=(0.1, OX, OY, SX, SY)),
            "bad_geometry": dict(grid=(0.0, OX, OY, SX, SY)),
            "zero_deadline": dict(deadline=0),
            "non_finite_rectangle": dict(rect=(float("nan"), 0.0, 1.0, 1.0)),
            "malformed": dict(rect=(0.0, 0.0, 1.0)),
            "own_source": dict(source="robot_0"),
            "bad_version": dict(version=0),
            "empty_update": dict(marked=()),
            "rectangle_outside_grid": dict(rect=(-1e38, -1e38, 1e38, 1e38)),
        }
        listed_before = {u: list(o.marked_indexes) for u, o in bus.listed().items()}
        for reason, change in bad.items():
            fields = dict(good)
            fields.update(change)
            bus.from_fleet.publish(obstacle(**fields))
        for reason in bad:
            wait_for(lambda: bus.counter("dropped_" + reason) == 1, what="dropped_%s = 1" % reason)
        self.assertEqual(bus.counter("dropped"), len(bad))
        self.assertEqual({u: list(o.marked_indexes) for u, o in bus.listed().items()}, listed_before)
        self.assertEqual(len(bus.fleet), 3)
        for reason in bad:
            lines = [line for line in bus.rosout if "dropped" in line and reason in line]
            if reason == "own_source":
                self.assertTrue(lines and "robot_0" in lines[0], lines)
            else:
                self.assertTrue(lines and "robot_9" in lines[0], (reason, bus.rosout[-12:]))
        # the node is still alive and applies the next good message
        bus.from_fleet.publish(obstacle(**good))
        wait_for(lambda: E + 5 in bus.listed()[EXT1].marked_indexes, what="the good message")

    def test_06_manual_add_is_shared_like_a_detection(self):
        bus = self.bus
        reply = self.add_srv(rectangle_shape=[-5.0, -2.5, -4.9, -2.45], marked_indexes=[], deadline=0)
        self.assertTrue(reply.success, reply.message)
        self.assertRegex(reply.uuid, UUID4)
        wait_for(lambda: bus.fleet[-1].uuid == reply.uuid and bus.shared[-1].uuid == reply.uuid,
                 what="the manual obstacle on to_fleet and shared_obstacles")
        self.assertEqual((list(bus.fleet[-1].marked_indexes), bus.fleet[-1].deadline), ([0, 1], 60))
        # the same rectangle again: an observation of that obstacle, sent as an update of it
        again = self.add_srv(rectangle_shape=[-5.0, -2.5, -4.9, -2.45], marked_indexes=[], deadline=0)
        self.assertTrue(again.success, again.message)
        self.assertEqual(again.uuid, reply.uuid)
        wait_for(lambda: bus.fleet[-1].uuid == reply.uuid and bus.fleet[-1].version == 2,
                 what="the update of the manual obstacle on to_fleet")

    def test_06b_the_fleets_obstacles_are_drawn_for_rviz_with_source_age_time_left_and_cells(self):
        bus = self.bus
        # Nobody has looked at the markers so far: a late subscriber (RViz started now) gets the obstacles
        # held now as its first array, not an empty one from before the first share.
        held = len(self.list_srv().obstacles)
        self.assertGreater(held, 0)
        bus.subscribe_markers()
        wait_for(lambda: bus.first_markers is not None, what="the first fleet_obstacle_markers a late subscriber gets")
        self.assertEqual(len(bus.labels(bus.first_markers)), held, bus.labels(bus.first_markers))
        wait_for(lambda: bus.list and bus.list.obstacles and len(bus.labels()) == len(bus.list.obstacles),
                 what="one label per listed obstacle on fleet_obstacle_markers")
        labels = bus.labels()
        for o in bus.list.obstacles:
            self.assertTrue(any(text.startswith(o.source + " · ") and text.endswith(
                " · %d cells" % len(o.marked_indexes)) for text in labels), (o.uuid, labels))
        self.assertEqual(bus.markers.markers[0].action, 3)   # DELETEALL first: gone obstacles vanish

    def test_06bb_fleet_obstacles_list_counts_ages_on_the_handlers_clock(self):
        # The tool on simulated time before any /clock (a fleet launch's /use_sim_time, the tool started
        # before the simulator runs): its own clock reads 0, and ages from it came out negative.
        rospy.set_param("/use_sim_time", True)
        try:
            proc = subprocess.run([sys.executable, os.path.join(os.path.dirname(HERE), "scripts", "fleet_obstacles"),
                                   "list", "--robot", "robot_0"], capture_output=True, text=True, timeout=60)
        finally:
            rospy.delete_param("/use_sim_time")
        self.assertEqual(proc.returncode, 0, proc.stderr)
        rows = [line.split() for line in proc.stdout.splitlines()[1:]]
        self.assertTrue(rows, proc.stdout)
        for row in rows:
            age = float(row[2])
            self.assertTrue(0 <= age <= 120, "age %r in %s" % (age, proc.stdout))

    def test_06c_remove_obstacle_clears_it_fleet_wide_and_refuses_without_a_requester(self):
        bus = self.bus
        remove = rospy.ServiceProxy(NS + "remove_obstacle", RemoveObstacle)
        reply = self.add_srv(rectangle_shape=[4.0, 2.0, 4.1, 2.05], marked_indexes=[], deadline=0)
        self.assertTrue(reply.success, reply.message)
        wait_for(lambda: reply.uuid in bus.listed(), what="the obstacle to remove in the list")
        refused = remove(uuid=reply.uuid, rectangle_shape=[], requested_by="")
        self.assertFalse(refused.success)
        self.assertIn("requested_by", refused.message)
        done = remove(uuid=reply.uuid, rectangle_shape=[], requested_by="rostest")
        self.assertTrue(done.success, done.message)
        self.assertEqual(list(done.removed), [reply.uuid])
        wait_for(lambda: reply.uuid not in bus.listed(), what="the removed obstacle gone from the list")
        out = [m for m in bus.fleet if m.uuid == reply.uuid][-1]
        self.assertEqual((list(out.marked_indexes), out.source), ([], "robot_0"))
        self.assertTrue(out.cleared_indexes)

    def test_07_expiry_tells_the_layer_and_sends_nothing_to_the_fleet(self):
        bus = self.bus
        fleet_before = len(bus.fleet)
        first = obstacle(uuid=SHORT1, marked=(S,), version=1, deadline=1, rect=(3.2, 0.0, 3.7, 0.5),
                         source="robot_3")   # beyond merge_distance of ext-1
        bus.from_fleet.publish(first)
        wait_for(lambda: SHORT1 in bus.listed(), what="short-1 in the list")
        wait_for(lambda: SHORT1 in bus.expired, timeout=4, what="short-1 on expired_obstacles")
        wait_for(lambda: SHORT1 not in bus.listed(), what="short-1 gone from the list")
        self.assertEqual(len(bus.fleet), fleet_before)
        # a late message for it (made before it expired here) does not bring it back (one made after it would:
        # the robot that sees it again shares it again, issue 43)
        late = obstacle(uuid=SHORT1, marked=(S + 1,), version=2, deadline=1, rect=(3.2, 0.0, 3.7, 0.5),
                        source="robot_4")
        late.header.stamp = first.header.stamp
        bus.from_fleet.publish(late)
        wait_for(lambda: bus.counter("dropped_expired") == 1, what="dropped_expired = 1")
        self.assertNotIn(SHORT1, bus.listed())
        self.assertEqual(bus.counter("expired"), 1)

    def test_08_snapshot_file_is_yaml_of_the_current_list(self):
        path = rospy.get_param("~snapshot_file")
        wanted = set(self.bus.listed())

        def current():
            try:
                with open(path) as f:
                    doc = yaml.safe_load(f)
            except (OSError, yaml.YAMLError):
                return False
            return {o["uuid"] for o in doc["obstacles"]} == wanted
        wait_for(current, what="the snapshot %s to list %s" % (path, sorted(wanted)))
        with open(path) as f:
            doc = yaml.safe_load(f)
        ext = [o for o in doc["obstacles"] if o["uuid"] == EXT1][0]
        self.assertEqual(doc["robot"], "robot_0")
        self.assertEqual(ext["source"], "robot_1")
        self.assertEqual(ext["cells"], [E + 1, E + 2, E + 3, E + 5])
        os.unlink(path)

    def test_10_a_flooding_sources_excess_is_dropped_counted_per_source_and_named(self):
        """Issue 27, item 3 (max_obstacles_per_source 3 in handler_node.test): robot_7's new obstacles beyond
        3 are dropped, counted on /diagnostics with robot_7 named, and logged once; robot_6's still go."""
        bus = self.bus

        def far(k, source, row):   # one cell, 1 m apart along x: nothing merges
            col = 10 + 20 * k
            x, y = OX + col * RES, OY + row * RES
            return obstacle(uuid="00000000-0000-4000-8000-%012d" % (7000 + 100 * row + k), marked=(row * SX + col,),
                            rect=(x, y, x + RES, y + RES), source=source, deadline=30)
        for k in range(5):
            bus.from_fleet.publish(far(k, "robot_7", 10))
        wait_for(lambda: bus.counter("dropped_source_quota.robot_7") == 2,
                 what="dropped_source_quota.robot_7 = 2 on /diagnostics")
        self.assertEqual(bus.counter("dropped_source_quota"), 2)
        floods = [far(k, "robot_7", 10).uuid for k in range(5)]
        # the list is rebuilt on a throttle, so it may come after the counters: wait for the three kept
        wait_for(lambda: all(u in bus.listed() for u in floods[:3]), what="robot_7's first three on the list")
        self.assertEqual([u in bus.listed() for u in floods], [True] * 3 + [False] * 2)
        good = far(0, "robot_6", 30)
        bus.from_fleet.publish(good)
        wait_for(lambda: good.uuid in bus.listed(), what="robot_6's obstacle")
        lines = [line for line in bus.rosout if "source_quota" in line]
        self.assertEqual(len(lines), 1, lines)   # one line, not one per message
        self.assertIn("robot_7", lines[0])
        self.assertIn("max_obstacles_per_source 3", lines[0])

    def test_09_bad_parameter_fails_at_startup_naming_it(self):
        proc = subprocess.run([sys.executable, os.path.join(HERE, "..", "scripts", "sharing_handler"),
                               "__ns:=robot_5", "__name:=sharing_handler", "_obstacle_duration:=-5"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=20)
        self.assertEqual(proc.returncode, 2)
        self.assertIn("~obstacle_duration = -5", proc.stderr.decode())


if __name__ == "__main__":
    rostest.rosrun("sharing_handler_py", "handler_node", TestHandlerNode, sys.argv)
