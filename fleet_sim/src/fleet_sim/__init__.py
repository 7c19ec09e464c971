"""fleet_sim: a Stage-world simulator (stage_ros names) for Debian's ROS 1.

The simulator modules are ROS-free (``world``, ``sim``, ``map_io``,
``snapshot``, ``frames``, ``raycast``); ``sim_node`` and ``map_server_node``
are the thin rospy adapters.
"""
