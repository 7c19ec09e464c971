"""Moving the worlds' blocks in a running Stage, as a test or benchmark needs to (take a block away,
put it back turned, move it out of a corridor at a set time).

Stage 4.3 and stageros 1.8 offer no service to move a model. The worlds' blocks are therefore Stage
``position`` models with an omnidirectional drive and ``obstacle_return 0`` (fleet_launch's
make_facility_world): stageros -u gives each one ``/<name>/cmd_vel`` and
``/<name>/base_pose_ground_truth``, and ``BlockDriver`` steers it there on its ground truth.
Taking a block away drives it sideways into the nearest wall that holds it whole: no laser reaches
it there (lasers stop at the wall's face), so for every robot the block is gone, as with
fleet_sim's remove_block. Putting it back drives it out to the pose asked for.

The pure parts (``parking_shift``, ``velocity_towards``) are tested without a master
(tests/test/test_stage_blocks.py); ``BlockDriver`` needs stageros.
"""
import math
import threading

import rospy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry

MAX_SPEED = 1.0        # m/s; Stage moves a block by speed x 0.1 s per step
MAX_TURN = 1.0         # rad/s
GAIN = 2.0             # 1/s: the speed asked for per metre (radian) still to go
TOLERANCE = 0.005      # m and rad: close enough to the goal pose
WALL_MARGIN = 0.1      # m of wall kept around a parked block on every side


def yaw_of(q):
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def wrap(angle):
    return math.atan2(math.sin(angle), math.cos(angle))


def velocity_towards(pose, goal, max_speed=MAX_SPEED, max_turn=MAX_TURN, gain=GAIN):
    """(vx, vy, wz) in the block's own frame that brings pose (x, y, yaw) towards goal (x, y, yaw):
    proportional to what is left, at most max_speed and max_turn."""
    dx, dy = goal[0] - pose[0], goal[1] - pose[1]
    distance = math.hypot(dx, dy)
    speed = min(max_speed, gain * distance)
    vx_world, vy_world = (dx / distance * speed, dy / distance * speed) if distance > 0 else (0.0, 0.0)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    turn = max(-max_turn, min(max_turn, gain * wrap(goal[2] - pose[2])))
    return c * vx_world + s * vy_world, -s * vx_world + c * vy_world, turn


def block_points(pose, size, margin, step=0.05):
    """Points every `step` m over the block's rectangle grown by margin on every side."""
    (x, y, yaw), (sx, sy) = pose, size
    c, s = math.cos(yaw), math.sin(yaw)
    half_x, half_y = sx / 2.0 + margin, sy / 2.0 + margin
    nx, ny = max(1, int(math.ceil(2 * half_x / step))), max(1, int(math.ceil(2 * half_y / step)))
    points = []
    for i in range(nx + 1):
        for j in range(ny + 1):
            u, v = -half_x + 2 * half_x * i / nx, -half_y + 2 * half_y * j / ny
            points.append((x + c * u - s * v, y + s * u + c * v))
    return points


def parking_shift(pose, size, occupied, limit=20.0, step=0.05, margin=WALL_MARGIN):
    """The smallest shift d (metres, either sign) along the block's own x axis after which the block,
    grown by margin, lies wholly on occupied map cells (occupied(x, y) -> bool); None within limit."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for k in range(1, int(limit / step) + 1):
        for d in (k * step, -k * step):
            moved = (pose[0] + c * d, pose[1] + s * d, pose[2])
            if all(occupied(px, py) for px, py in block_points(moved, size, margin)):
                return d
    return None


def map_occupancy(grid):
    """occupied(x, y) of a nav_msgs/OccupancyGrid: True on a cell >= 65 or outside the map."""
    info = grid.info
    ox, oy, res = info.origin.position.x, info.origin.position.y, info.resolution

    def occupied(x, y):
        ix, iy = int(math.floor((x - ox) / res)), int(math.floor((y - oy) / res))
        if not (0 <= ix < info.width and 0 <= iy < info.height):
            return True
        return grid.data[iy * info.width + ix] >= 65
    return occupied


class BlockError(Exception):
    """A block could not be moved (no such model, no ground truth, no wall to park it in, too slow)."""


class BlockDriver:
    """Drives the blocks of a running stageros (``names``) on their ground truth."""

    def __init__(self, names):
        self.lock = threading.Lock()
        self.poses = {}
        self.parked = {}        # name -> the pose it had before it was parked
        self.pubs = {}
        for name in names:
            self.pubs[name] = rospy.Publisher("/%s/cmd_vel" % name, Twist, queue_size=1)
            rospy.Subscriber("/%s/base_pose_ground_truth" % name, Odometry, self._on_pose(name), queue_size=1)

    def _on_pose(self, name):
        def cb(msg):
            p = msg.pose.pose
            with self.lock:
                self.poses[name] = (p.position.x, p.position.y, yaw_of(p.orientation))
        return cb

    def pose(self, name, timeout=10.0):
        """The block's ground-truth pose (x, y, yaw) in the world (= map) frame."""
        if name not in self.pubs:
            raise BlockError("no block named %r (blocks: %s)" % (name, ", ".join(sorted(self.pubs))))
        end = rospy.get_time() + timeout
        while not rospy.is_shutdown():
            with self.lock:
                if name in self.poses:
                    return self.poses[name]
            if rospy.get_time() > end:
                raise BlockError("no /%s/base_pose_ground_truth from stageros in %.0f s: is %s a position "
                                 "model of the world, and stageros started with -u?" % (name, timeout, name))
            rospy.sleep(0.05)
        raise BlockError("shut down")

    def move(self, name, goal, timeout=60.0):
        """Drives the block to goal (x, y, yaw); returns when within TOLERANCE."""
        self.pose(name)
        end = rospy.get_time() + timeout
        rate = rospy.Rate(20)
        pub = self.pubs[name]
        while not rospy.is_shutdown():
            pose = self.pose(name)
            if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) < TOLERANCE and \
                    abs(wrap(goal[2] - pose[2])) < TOLERANCE:
                break
            if rospy.get_time() > end:
                pub.publish(Twist())
                raise BlockError("block %s did not reach (%.2f, %.2f, %.2f rad) in %.0f s; it is at (%.2f, %.2f, "
                                 "%.2f rad)" % ((name,) + tuple(goal) + (timeout,) + tuple(pose)))
            vx, vy, wz = velocity_towards(pose, goal)
            twist = Twist()
            twist.linear.x, twist.linear.y, twist.angular.z = vx, vy, wz
            pub.publish(twist)
            rate.sleep()
        for _ in range(3):  # stageros keeps the last command until its watchdog: stop now
            pub.publish(Twist())
            rate.sleep()

    def park(self, name, size, occupied):
        """Takes the block away: into the nearest wall (along its long side) that holds it whole."""
        pose = self.pose(name)
        shift = parking_shift(pose, size, occupied)
        if shift is None:
            raise BlockError("no wall near %s at (%.2f, %.2f) holds its %.2f x %.2f m whole: it cannot be taken "
                             "away in this world" % (name, pose[0], pose[1], size[0], size[1]))
        goal = (pose[0] + math.cos(pose[2]) * shift, pose[1] + math.sin(pose[2]) * shift, pose[2])
        self.move(name, goal)
        with self.lock:
            self.parked[name] = pose
        return goal

    def is_parked(self, name):
        with self.lock:
            return name in self.parked

    def place(self, name, goal):
        """Puts the block (parked or not) at goal (x, y, yaw)."""
        self.move(name, goal)
        with self.lock:
            self.parked.pop(name, None)
