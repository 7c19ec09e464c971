"""Stage world files: ``parser`` (syntax, includes, macros), ``loader`` (meaning),
``raster`` (occupancy grid for collisions and raycasting)."""
from fleet_sim.world.loader import load_world, require_robots  # noqa: F401
from fleet_sim.world.model import BlockSpec, FloorplanSpec, RangerSpec, RobotSpec, World  # noqa: F401
