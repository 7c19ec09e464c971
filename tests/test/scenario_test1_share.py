#!/usr/bin/python3
"""Test 1 of the thesis (DESIGN.md §8), node of test1_share.test: share and react.

robot_0 drives to the orange goal behind both blocks. It runs move_base's defaults, so nothing
publishes stuck_feedback: each block is shared once, from the sharing layer's plan-blocked
trigger as the block appears on its plan (and grown over the rest of the face as robot_0 sees
it), and robot_0 reaches the goal through the open (left) corridor without passing a block.
robot_1, sent afterwards to the purple goal behind the same blocks, plans the open route from the
start: no plan or pose of it inside a blocked corridor. robot_1, which robot_0 sees at the start,
is never shared. At the end both robots hold the same obstacle list.
"""
import math

import rostest

from fleet_tests.scenario import cell_centre, entered, inside
from fleet_tests.testcase import FleetTestCase


class Test1Share(FleetTestCase):
    NODE = "test1_share"
    PICTURE_PREFIX = "test1"

    def test_share_and_react(self):
        fleet = self.fleet
        r0, r1 = fleet.robots
        blocks = fleet.facility["blocks"]
        blocked = {name: fleet.corridor(b["corridor"]) for name, b in blocks.items()}
        r1_start = r1.pose

        self.assert_succeeded(r0, "orange", r0.go("orange", 300.0))

        # Each block shared once (and nothing else shared), without a stuck signal.
        self.assertEqual([], r0.stuck, "stuck_feedback in move_base's default mode")
        shares = r0.shares()
        rects = [tuple(m.rectangle_shape) for _t, m in shares]
        self.assertEqual(len(blocks), len(shares), "robot_0 shared %d obstacles %s, expected one per block"
                         % (len(shares), rects))
        for name, b in blocks.items():
            bx, by = b["pose"][0], b["pose"][1]
            sx, sy = b["size"]
            box = (bx - sx / 2, by - sy / 2, bx + sx / 2, by + sy / 2)
            near = [m for _t, m in shares
                    if all(inside(box, *cell_centre(m, i), margin=0.15) for i in m.marked_indexes)]
            self.assertEqual(1, len(near), "block %s: %d shares lie on it (rectangles %s)" % (name, len(near), rects))
        # robot_1 is never shared: no shared cell near where it stands.
        for _t, m in shares:
            for i in m.marked_indexes:
                x, y = cell_centre(m, i)
                self.assertGreater(math.hypot(x - r1_start[0], y - r1_start[1]), 0.6,
                                   "robot_0 shared robot_1 (cell (%.2f, %.2f) of %s)" % (x, y, m.uuid))
        # The open route: robot_0 went through the left corridor and never past a block.
        self.assertTrue(entered(r0.track, fleet.corridor("left")), "robot_0 never drove the left corridor")
        for name, b in blocks.items():
            beyond = [p for p in entered(r0.track, blocked[name]) if p[2] > b["pose"][1]]
            self.assertEqual([], beyond[:3], "robot_0 passed %s" % name)

        # robot_1 has both obstacles (through MQTT) before it is sent.
        fleet.wait_until(lambda: len(r1.obstacles()) == len(blocks), 20.0, "robot_1 to hold both obstacles")
        sent = r1.send("purple")
        self.assert_succeeded(r1, "purple", r1.wait(300.0))
        self.assertEqual([], r1.stuck, "robot_1 got stuck")
        plans = [p for t, p in r1.plans if t >= sent]
        self.assertTrue(plans, "robot_1 published no plan")
        self.assertTrue(entered(plans[0], fleet.corridor("left")), "robot_1's first plan is not the open route")
        for name, rect in blocked.items():
            for k, plan in enumerate(plans):
                self.assertEqual([], entered(plan, rect)[:3], "robot_1's plan %d enters the blocked %s corridor"
                                 % (k, name))
            self.assertEqual([], entered([p for p in r1.track if p[0] >= sent], rect)[:3],
                             "robot_1 drove into the blocked corridor of %s" % name)
        # robot_1 shared nothing, and both lists are the same.
        self.assertEqual([], r1.shares(), "robot_1 shared an obstacle")
        same, lists = fleet.lists_identical()
        self.assertTrue(same, "obstacle lists differ: %s" % lists)
        self.assertEqual(len(blocks), len(lists[0]))


if __name__ == "__main__":
    rostest.rosrun("fleet_tests", "test1_share", Test1Share)
