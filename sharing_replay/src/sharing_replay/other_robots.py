"""The bag's other robots, placed at a scan's stamp, so that the replay never shares a robot.

Live, every robot's Coaty bridge advertises its footprint at its pose, and each layer excludes the
robots its bridge hears of: their footprint plus ``robot_exclusion_margin`` is never shared. A bag has
no bridges, so the replay takes the same from what the bag holds:

- the pose: tf, ``<ns>/<base frame>`` in the global frame at the scan's stamp (the pose the robot
  believed, which is what its own advert carried); when tf has none at that stamp, the last pose
  found, for at most ``robot_timeout`` seconds (as a layer forgets a robot it no longer hears of);
- the footprint: the robot's recorded ``<ns>/move_base/global_costmap/footprint`` (move_base and
  fleet_nav publish the padded footprint placed at the pose; its shape is taken once, relative to the
  pose tf gives at its stamp), else the footprint of the parameters (``footprint`` or ``robot_radius``
  with ``footprint_padding``, as fleet_nav builds it).

Ground truth (``base_pose_ground_truth``) is not used: stageros labels it with the odom frame although
it is in Stage's world frame, which is not the map frame in general (the Willow world is rotated).
No ROS in here: the runner hands in tf samples and footprint messages."""
import collections
import math

import numpy as np

from sharing_replay.errors import TransformError
from sharing_replay.tf_chain import yaw_of

#: move_base's (costmap_2d's) and fleet_nav's footprint topic, relative to a robot's namespace
FOOTPRINT_TOPIC = "move_base/global_costmap/footprint"


def place(shape, x, y, yaw):
    """The (N, 2) shape of a footprint (robot frame) at pose (x, y, yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = np.array([[c, -s], [s, c]])
    return shape @ rotation.T + np.array([x, y])


class OtherRobots:
    """Every robot of the bag (name -> base frame), placed at a stamp for the others' layers."""

    def __init__(self, chain, global_frame, frames, default_shape, timeout):
        self.chain = chain
        self.global_frame = global_frame
        self.frames = dict(frames)
        self.default_shape = np.asarray(default_shape, dtype=np.float64).reshape(-1, 2)
        self.timeout = timeout
        self.shapes = {}                               # name -> (N, 2) shape from its recorded footprint
        self.bad_footprints = collections.Counter()     # name -> recorded footprints that were unusable
        self.last = {}                                 # name -> (stamp, (x, y, yaw)) of the last pose found
        self.unplaced = collections.Counter()          # name -> scans of others it could not be placed for

    def footprint_source(self, name):
        return "recorded footprint" if name in self.shapes else "parameters"

    def on_footprint(self, name, msg):
        """A recorded geometry_msgs/PolygonStamped of robot `name`: its shape, once tf places it.
        Returns a line saying why it cannot be used, or None."""
        if name in self.shapes or name not in self.frames:
            return None
        points = [(p.x, p.y) for p in msg.polygon.points]
        if not points or not all(math.isfinite(v) for point in points for v in point):
            self.bad_footprints[name] += 1
            return "%s: a recorded footprint with %d points, or a non-finite one: not used" % (name, len(points))
        frame = msg.header.frame_id.lstrip("/") or self.global_frame
        try:
            pose = self.chain.lookup(frame, self.frames[name], msg.header.stamp.to_sec())
        except TransformError:
            return None   # tf for its stamp may come later in the bag: the next footprint tries again
        x, y, yaw = pose[0], pose[1], yaw_of(pose)
        relative = np.asarray(points, dtype=np.float64) - np.array([x, y])
        c, s = math.cos(-yaw), math.sin(-yaw)
        self.shapes[name] = relative @ np.array([[c, -s], [s, c]]).T
        return None

    def pose(self, name, stamp):
        """(x, y, yaw) of robot `name` at stamp, or None."""
        try:
            tr = self.chain.lookup(self.global_frame, self.frames[name], stamp)
        except TransformError:
            last = self.last.get(name)
            if last is not None and (self.timeout == 0 or abs(stamp - last[0]) <= self.timeout):
                return last[1]
            return None
        pose = (tr[0], tr[1], yaw_of(tr))
        self.last[name] = (stamp, pose)
        return pose

    def placed(self, stamp, for_robot):
        """[(name, (N, 2) footprint at its pose, stamp)] of every robot but `for_robot` that has a pose."""
        out = []
        for name in sorted(self.frames):
            if name == for_robot:
                continue
            pose = self.pose(name, stamp)
            if pose is None:
                self.unplaced[name] += 1
                continue
            out.append((name, place(self.shapes.get(name, self.default_shape), *pose), stamp))
        return out
