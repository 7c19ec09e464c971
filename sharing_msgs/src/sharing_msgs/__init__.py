"""Helpers shared by every package of fleet obstacle sharing (next to the generated msg/srv).

- ``obstacle_rules``: the one validation of a SharedObstacle (bridge and handler both use it).
- ``safe_publisher``: a publisher that one bad message cannot break.
"""
