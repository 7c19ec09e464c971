"""fleet_sim: a Stage-world simulator (stage_ros names) for Debian's ROS 1.

The simulator modules are ROS-free (``world``, ``sim``, ``map_io``,
``snapshot``, ``frames``, ``raycast``); ``sim_node`` and ``map_server_node``
are the thin rospy adapters.
"""

# Tests may put src/ ahead of the workspace on sys.path; the generated srv
# module lives in devel/, so the package spans both folders.
__path__ = __import__("pkgutil").extend_path(__path__, __name__)
