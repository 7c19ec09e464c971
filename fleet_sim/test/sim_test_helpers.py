"""Helpers for fleet_sim's pytest files (unique module name: pytest imports every
package's test folder in one run)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "src"))

DATA = os.path.join(HERE, "data")
SHARED = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(HERE))), "shared", "data")
if not os.path.isdir(SHARED):
    SHARED = "/work/shared/data"
WILLOW = os.path.join(SHARED, "stage_worlds", "willow", "willow-pr2-multi.world")
SIMPLE = os.path.join(SHARED, "stage_worlds", "stage_examples", "simple.world")
WILLOW_PGM = os.path.join(SHARED, "stage_worlds", "maps", "willow-full.pgm")


def raycaster():
    """The C++ core's raycaster (the simulator has no other); fails loudly if it is not built."""
    from fleet_sim.raycast import core_raycaster
    return core_raycaster()
