"""fleet_nav: the navigation host that stands in for move_base on Debian's ROS.

Pure modules (no rospy): ``params`` (move_base/costmap_2d parameters, validated),
``costmap`` (static + sharing + inflation layers), ``navigator`` (global planning,
path following, stuck detection, goal state), ``snapshot`` (PNG of one robot's view).
``node`` is the thin rospy adapter behind ``rosrun fleet_nav fleet_nav``.
"""
