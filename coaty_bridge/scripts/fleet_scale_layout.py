"""Where bench_fleet_scale's robots stand, drive and see obstacles (no ROS, no MQTT).

The robots stand in rows of ROBOTS_PER_ROW, 2.4 m apart, rows ROW_SPACING m apart (the map grows with the fleet);
a driving robot goes back and forth along its aisle, AISLE_OFFSET m past its row unless told otherwise. A standing
robot's obstacles lie around it, within its sensor reach (obstacle_rectangle), as the evidence rule requires of what a
robot shares.
"""
import math

from sharing_handler_py.validation import Geometry, Rectangle

ROBOTS_PER_ROW, ROW_SPACING = 40, 30.0
#: m from a row to its drivers' aisle by default: halfway to the next row, the farthest from every obstacle
AISLE_OFFSET = ROW_SPACING / 2


def position(index):
    """Where robot ``index`` stands: rows of 40 robots 30 m apart, 2.4 m apart along a row."""
    return 1.0 + (index % ROBOTS_PER_ROW) * 2.4, 20.0 + (index // ROBOTS_PER_ROW) * ROW_SPACING


#: a standing robot's obstacles (0.5 m squares) in 2 columns x 5 rows around where it stands (left and bottom
#: edges, m from its position): all within its sensor reach, so that their evidence holds, and 0.6 m from each
#: other and from the neighbours' (2.4 m away), more than the handlers' merge distance (0.5 m)
OBSTACLE_SIZE = 0.5
OBSTACLE_COLUMNS = (-0.85, 0.35)
OBSTACLE_ROWS = (0.6, -1.1, 1.7, -2.2, 2.8)
MAX_OBSTACLES_PER_ROBOT = len(OBSTACLE_COLUMNS) * len(OBSTACLE_ROWS)
#: half the width of the tutorials' footprint (footprint_points), m
ROBOT_HALF_WIDTH = 0.325


def aisle_offset_range():
    """(lowest, highest) m past its row an aisle may lie: a driver's footprint clears the obstacles of its own row
    (up to max(OBSTACLE_ROWS) + OBSTACLE_SIZE above it) and of the next row (down to min(OBSTACLE_ROWS) below it)."""
    return (max(OBSTACLE_ROWS) + OBSTACLE_SIZE + ROBOT_HALF_WIDTH,
            ROW_SPACING + min(OBSTACLE_ROWS) - ROBOT_HALF_WIDTH)


def obstacle_rectangle(index, k):
    """The k-th obstacle of the robot standing at position(index)."""
    x, y = position(index)
    left, bottom = x + OBSTACLE_COLUMNS[k % 2], y + OBSTACLE_ROWS[k // 2]
    return Rectangle(left, bottom, left + OBSTACLE_SIZE, bottom + OBSTACLE_SIZE)


def grid_for(n_robots):
    """The map: 100 m wide, as many 30 m rows as the robots need (at least 100 m)."""
    rows = -(-n_robots // ROBOTS_PER_ROW)
    return Geometry(0.05, 0.0, 0.0, 2000, max(2000, int(math.ceil((rows * ROW_SPACING + 10.0) / 0.05))))


def footprint_points(index, at=None):
    """The tutorials' robot footprint (0.65 m x 0.65 m, nose 0.46 m) where robot ``index`` stands (or at ``at``)."""
    x, y = at or position(index)
    return ((x - 0.325, y - 0.325), (x - 0.325, y + 0.325), (x + 0.325, y + 0.325), (x + 0.46, y),
            (x + 0.325, y - 0.325))


def aisle_position(start_x, aisle_y, speed, t, x_min=1.0, x_max=95.0):
    """Where a robot that left ``start_x`` at t = 0 is after ``t`` s, driving back and forth between
    x_min and x_max at ``speed`` along y = aisle_y (first towards x_max)."""
    span = x_max - x_min
    travelled = (start_x - x_min + speed * t) % (2 * span)
    return (x_min + travelled if travelled <= span else x_max - (travelled - span)), aisle_y


def is_driving(index, fraction):
    """Whether robot ``index`` drives: ``fraction`` of the robots, spread evenly over the indexes."""
    return int((index + 1) * fraction) > int(index * fraction)
