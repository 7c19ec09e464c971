#!/usr/bin/python3
"""Test 3 of the thesis (DESIGN.md §8), node of test3_expiry.test: re-add of a moved block and expiry.

robot_0 shares block_right (on its way to orange; block_middle is taken away first) and
drives on. The block is put back slightly moved (turned by ~11 degrees about the middle of the
monitored rectangle), so that only part of its face lies in the rectangle. robot_1 drives to red,
below the block, and monitors the obstacle. The thesis limited its updates to the rectangle;
since issue 12 face cells that touch the obstacle join it (growing) and the rectangle only
grows, so the test checks that robot_1's updates keep every cell on the old or the moved face,
never shrink the rectangle, and reach robot_0: once robot_1 has reached red (obstacle layer
reset) both robots hold the same cells. robot_1 drives back to its start; nobody sees the block
any more, so its lease is not renewed: within obstacle_duration the obstacle is gone from both
lists and both costmaps, and neither robot sent a message for it meanwhile or received one that is not an
earlier update passed on again (a bridge's renewal of far copies, aged, which extends no lease).
"""
import math

import rospy
import rostest

from fleet_tests.scenario import cell_centre, inside
from fleet_tests.testcase import FleetTestCase

TILT = 0.2  # rad


class Test3Expiry(FleetTestCase):
    NODE = "test3_expiry"
    PICTURE_PREFIX = "test3"
    GOAL_TIMEOUT = 200.0

    @staticmethod
    def costs(robot, msg):
        """Costs (0..100) of the obstacle msg's cells in the robot's latest global costmap."""
        grid = robot.costmap
        res, ox, oy = grid.info.resolution, grid.info.origin.position.x, grid.info.origin.position.y
        out = []
        for i in msg.marked_indexes:
            x, y = cell_centre(msg, i)
            ix, iy = int((x - ox) / res), int((y - oy) / res)
            out.append(grid.data[iy * grid.info.width + ix])
        return out

    def test_partial_readd_and_expiry(self):
        fleet = self.fleet
        r0, r1 = fleet.robots
        block = fleet.facility["blocks"]["block_right"]
        duration = rospy.get_param("~obstacle_duration")
        fleet.remove_block("block_middle")

        r0.send("orange")
        shares = fleet.wait_until(r0.shares, 60.0, "robot_0 to share block_right")
        first = shares[0][1]
        uuid = first.uuid
        rect = tuple(first.rectangle_shape)
        fleet.wait_until(lambda: r0.pose[0] < 8.5, 60.0, "robot_0 to leave the right corridor")
        # robot_0 saw more of the face on its way: the obstacle grew over it (the plan trigger shares
        # the first cells of a block seen on the plan). The monitored rectangle is the one held now.
        rect = r0.obstacles()[uuid][2]

        # Put the block back turned about the middle of the rectangle: its face (the side robot_1
        # will see) crosses the rectangle's band in the middle and leaves it on both sides.
        sx, sy = block["size"]
        mx, my = (rect[0] + rect[2]) / 2.0, (rect[1] + rect[3]) / 2.0
        cx = mx - (sy / 2.0) * math.sin(TILT)
        cy = my + (sy / 2.0) * math.cos(TILT)
        fleet.remove_block("block_right")
        fleet.add_block("block_right", cx, cy, TILT, sx, sy)
        face = [(mx + s * math.cos(TILT), my + s * math.sin(TILT)) for s in [k * 0.05 - sx / 2 for k in range(41)]]
        face = [p for p in face if block["pose"][0] - 0.8 < p[0] < block["pose"][0] + 0.8]
        outside = [p for p in face if not inside(rect, p[0], p[1], margin=0.03)]
        self.assertTrue(outside, "scenario: the moved face %s lies inside the rectangle %s" % (face, rect))

        readded_at = rospy.get_time()
        self.reach(r1, "red")

        def r1_updates():
            with fleet.lock:
                return [m for t, m in r1.to_fleet if t >= readded_at and m.uuid == uuid]
        updates = fleet.wait_until(r1_updates, 20.0, "robot_1's update of %s" % uuid)
        def on_a_face(x, y):
            return inside(rect, x, y, margin=0.03) or min(math.hypot(x - fx, y - fy) for fx, fy in face) < 0.12

        for m in updates:
            self.assertEqual("robot_1", m.source)
            self.assertTrue(inside(tuple(m.rectangle_shape), rect[0], rect[1], margin=1e-3)
                            and inside(tuple(m.rectangle_shape), rect[2], rect[3], margin=1e-3),
                            "the rectangle shrank from %s to %s" % (rect, tuple(m.rectangle_shape)))
            for i in list(m.marked_indexes) + list(m.cleared_indexes):
                x, y = cell_centre(m, i)
                self.assertTrue(on_a_face(x, y), "robot_1 shared cell (%.2f, %.2f), on neither the old face in %s "
                                "nor the moved face" % (x, y, rect))
        self.assertTrue(any(m.marked_indexes for m in updates) or any(m.cleared_indexes for m in updates),
                        "robot_1's updates change nothing")

        def equal_cells():
            a, b = r0.obstacles().get(uuid), r1.obstacles().get(uuid)
            return a is not None and b is not None and a[0] == b[0] and a
        cells, _version, _rect = fleet.wait_until(equal_cells, 20.0, "both robots' cells of %s to be equal" % uuid)
        self.assertTrue(cells, "the moved block left no cell in the obstacle")
        for i in cells:
            x, y = cell_centre(first, i)
            self.assertTrue(on_a_face(x, y), "cell (%.2f, %.2f) on neither face" % (x, y))

        # robot_1 leaves; from now on nothing is sent or received about the obstacle.
        self.reach(r1, "start_1")
        self.reach_r0 = r0.wait(100.0)
        self.assertEqual("SUCCEEDED", self.reach_r0[1], "robot_0 did not reach orange: %s" % (self.reach_r0,))
        quiet = rospy.get_time()
        # What each robot saw itself stays in its obstacle layer (ObstacleLayer keeps a mark until a beam clears it);
        # the shared obstacle is what this test watches expire: reset the obstacle layers, shared obstacles stay.
        for r in (r0, r1):
            r.forget_own_observations()
        obstacle = r1.obstacles()
        self.assertIn(uuid, obstacle, "the obstacle expired before robot_1 was back; obstacle_duration %s too "
                      "short for this machine" % duration)
        msg = [m for _t, m in r1.from_fleet if m.uuid == uuid][-1]
        msg.marked_indexes = list(cells)
        fleet.wait_until(lambda: r0.costmap and r0.costmap.header.stamp.to_sec() > quiet
                         and r1.costmap and r1.costmap.header.stamp.to_sec() > quiet, 10.0, "fresh costmaps")
        for r in (r0, r1):
            self.assertIn(100, self.costs(r, msg), "%s's costmap does not show the obstacle before expiry" % r.name)

        fleet.wait_until(lambda: uuid not in r0.obstacles() and uuid not in r1.obstacles(),
                         duration + 20.0, "the obstacle to expire on both robots")
        expired_at = rospy.get_time()
        def described(messages):
            return ["%s v%d from %s %.1f s after robot_1 was back (%d marked, %d cleared, e.g. %s; robot_0 at %s, "
                    "robot_1 at %s)" % (m.uuid[:8], m.version, m.source, t - quiet, len(m.marked_indexes),
                                        len(m.cleared_indexes), [tuple(round(v, 3) for v in cell_centre(m, i))
                                                                 for i in list(m.marked_indexes)[:3]],
                                        tuple(round(v, 2) for v in r0.pose_at(t)), tuple(round(v, 2) for v in r1.pose_at(t)))
                    for t, m in messages]
        with fleet.lock:
            before = {(m.uuid, m.version) for r in (r0, r1) for t, m in r.to_fleet if t < quiet}
        for r in (r0, r1):
            self.assertIn(uuid, [u for _t, u in r.expired], "%s's handler did not expire %s" % (r.name, uuid))
            with fleet.lock:
                sent = [(t, m) for t, m in r.to_fleet if t >= quiet]
                # A bridge renews far robots' copies with the sender's last update, aged (coaty_bridge, "Obstacle
                # areas"): that is no new observation and carries no longer lease. Anything else is.
                got = [(t, m) for t, m in r.from_fleet if t >= quiet and (m.uuid, m.version) not in before]
            self.assertEqual([], described(sent), "%s sent messages around the expiry" % r.name)
            self.assertEqual([], described(got), "%s received new observations around the expiry" % r.name)
        fleet.wait_until(lambda: r0.costmap.header.stamp.to_sec() > expired_at + 0.5
                         and r1.costmap.header.stamp.to_sec() > expired_at + 0.5, 10.0, "costmaps after expiry")
        for r in (r0, r1):
            self.assertNotIn(100, self.costs(r, msg), "%s's costmap still shows the expired obstacle" % r.name)
        same, lists = fleet.lists_identical()
        self.assertTrue(same, "obstacle lists differ: %s" % lists)


if __name__ == "__main__":
    rostest.rosrun("fleet_tests", "test3_expiry", Test3Expiry)
