"""C++ navigation-host core (global planner, inflation) used by fleet_sim's fleet_nav."""
from sharing_layer_cpp._nav_core import *  # noqa: F401,F403
