"""C++ navigation-host core (global planner, inflation): the pybind11 module fleet_nav._nav_core."""
from fleet_nav._nav_core import *  # noqa: F401,F403
