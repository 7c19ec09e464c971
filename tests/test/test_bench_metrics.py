"""The fleet bench's "robot drove into a blocked corridor" (fleet_tests.bench.entered_blocked) on the
geometry of both layouts' goals files."""
import os

import pytest
import rospkg

from fleet_tests.bench import entered_blocked
from fleet_tests.scenario import load_facility

WORLDS = os.path.join(rospkg.RosPack().get_path("fleet_launch"), "worlds")


def block_and_corridor(goals, name):
    f = load_facility(os.path.join(WORLDS, goals))
    b = f["blocks"][name]
    return b, f["corridors"][b["corridor"]]


@pytest.mark.parametrize("track, expected", [
    ([(0, 13.6, 1.0), (1, 13.6, 8.4)], True),      # drove 5 m up the long corridor, turned 2.5 m before the block
    ([(0, 13.6, 1.0), (1, 13.6, 4.0)], False),     # 0.6 m into the mouth only
    ([(0, 13.6, 1.0), (1, 1.9, 2.0), (2, 1.9, 9.0), (3, 13.3, 13.9)], False),   # the detour, then behind the block
])
def test_deadend(track, expected):
    block, corridor = block_and_corridor("deadend_goals.yaml", "block_far")
    assert entered_blocked(track, block, corridor, 2.4) is expected


@pytest.mark.parametrize("track, expected", [
    ([(0, 12.07, 2.73)], True),                    # stuck below the right corridor's mouth (Test 1's first stuck)
    ([(0, 13.6, 1.0), (1, 15.0, 3.0)], False),     # start slots, right of the corridor
    ([(0, 11.3, 7.3)], False),                     # purple: behind the block, not on the start side
])
def test_facility(track, expected):
    block, corridor = block_and_corridor("goals.yaml", "block_right")
    assert entered_blocked(track, block, corridor, 2.4) is expected
