#!/usr/bin/python3
"""Test 2 of the thesis (DESIGN.md §8), node of test2_clear.test: clear and share the update.

block_middle is taken away first so that robot_0 shares block_right alone. robot_0 drives to
orange (sharing block_right as it appears on its plan), then to purple, where it looks down the right
corridor at the block. The block is removed while in its view: robot_0 sends an update of that
obstacle with the cleared cells, and both robots then hold the same cells for it (or, when every cell
was seen free, neither lists it any more: issue 26). robot_1, sent to
purple, plans and drives straight up the right corridor with no stuck event. Both robots' obstacle
lists are identical at the end.
"""

import rospy
import rostest

from fleet_tests.scenario import entered
from fleet_tests.testcase import FleetTestCase


class Test2Clear(FleetTestCase):
    NODE = "test2_clear"
    PICTURE_PREFIX = "test2"

    def test_clear_and_share_update(self):
        fleet = self.fleet
        r0, r1 = fleet.robots
        right = fleet.corridor("right")
        block_y = fleet.facility["blocks"]["block_right"]["pose"][1]
        fleet.remove_block("block_middle")

        self.reach(r0, "orange")
        shares = r0.shares()
        self.assertEqual(1, len(shares), "robot_0 shared %d obstacles, expected block_right only" % len(shares))
        uuid = shares[0][1].uuid
        self.reach(r0, "purple")
        fleet.wait_until(lambda: uuid in r1.obstacles(), 20.0, "robot_1 to hold %s" % uuid)
        before = set(r1.obstacles()[uuid][0])
        self.assertTrue(before, "robot_1 holds %s without cells" % uuid)

        removed_at = rospy.get_time()
        fleet.remove_block("block_right")

        def cleared_update():
            with fleet.lock:
                return [m for t, m in r0.to_fleet if t >= removed_at and m.uuid == uuid and m.cleared_indexes]
        updates = fleet.wait_until(cleared_update, 30.0, "robot_0's update of %s with cleared cells" % uuid)
        self.assertEqual("robot_0", updates[0].source)
        self.assertGreater(updates[0].version, 1)
        self.assertTrue(set(updates[0].cleared_indexes) & before, "the update clears none of the shared cells")

        def equal_cells():
            # the same cells on both, or (every cell seen free, issue 26) listed on neither
            a, b = r0.obstacles().get(uuid), r1.obstacles().get(uuid)
            if a is None and b is None:
                return ((),)
            return a is not None and b is not None and a[0] == b[0] and a
        cells = fleet.wait_until(equal_cells, 30.0, "both robots' cells of %s to be equal" % uuid)[0]
        self.assertLess(len(cells), len(before), "the update cleared nothing on robot_1")

        # robot_0 makes way at the top of the corridor; robot_1 drives straight through it.
        self.reach(r0, "orange")
        sent = r1.send("purple")
        self.assert_succeeded(r1, "purple", r1.wait(300.0))
        self.assertEqual([], r1.stuck, "robot_1 got stuck in the cleared corridor")
        plans = [p for t, p in r1.plans if t >= sent]
        self.assertTrue(plans, "robot_1 published no plan")
        crossing = [p for p in entered(plans[0], right) if abs(p[1] - block_y) < 0.2]
        self.assertTrue(crossing, "robot_1's first plan does not run through the cleared corridor")
        driven = [p for p in entered([p for p in r1.track if p[0] >= sent], right) if abs(p[2] - block_y) < 0.3]
        self.assertTrue(driven, "robot_1 did not drive through the cleared corridor")
        self.assertFalse(entered([p for p in r1.track if p[0] >= sent], fleet.corridor("middle")),
                         "robot_1 took the middle corridor")

        # robot_1, driving up the cleared corridor, may see the rest of the place free and end the obstacle (on
        # both robots at once), or leave what it did not see: either way both robots hold the same.
        same, lists = fleet.lists_identical()
        self.assertTrue(same, "obstacle lists differ: %s" % lists)


if __name__ == "__main__":
    rostest.rosrun("fleet_tests", "test2_clear", Test2Clear)
