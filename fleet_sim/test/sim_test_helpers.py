"""Helpers for fleet_sim's pytest files (unique module name: pytest imports every
package's test folder in one run)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
try:
    import fleet_sim.errors  # noqa: F401  (the devel space's package, with the generated srv)
except ImportError:          # not built/sourced: the pure modules from the source tree still work
    for _name in [m for m in sys.modules if m == "fleet_sim" or m.startswith("fleet_sim.")]:
        del sys.modules[_name]       # e.g. the repo folder picked up as a namespace package
    sys.path.insert(0, os.path.join(os.path.dirname(HERE), "src"))

DATA = os.path.join(HERE, "data")
# The project's reference data: $FLEET_SHARED_DATA, else the repository's data/ (data/README.md).
SHARED = os.environ.get("FLEET_SHARED_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__)))), "data")
WILLOW = os.path.join(SHARED, "stage_worlds", "willow", "willow-pr2-multi.world")
SIMPLE = os.path.join(SHARED, "stage_worlds", "stage_examples", "simple.world")
WILLOW_PGM = os.path.join(SHARED, "stage_worlds", "maps", "willow-full.pgm")


def raycaster():
    """The C++ core's raycaster (the simulator has no other); fails loudly if it is not built."""
    from fleet_sim.raycast import core_raycaster
    return core_raycaster()


def room_sim(**kwargs):
    """A Simulation of test/data/room.world (10 m x 8 m, two robots) with the core's raycaster."""
    from fleet_sim.sim import Simulation
    from fleet_sim.world import load_world
    return Simulation(load_world(os.path.join(DATA, "room.world"), log=lambda *a: None), raycast=raycaster(), **kwargs)
