"""Synthetic stage_ros-shaped bags, for the replay's tests and benchmark.

A world is a static grid (the map) plus blocks that are not in the map; robots drive along
polylines at constant speed; every 1 / scan_rate seconds each robot gets a LaserScan raycast
in the world (``core.raycast_ranges``, the simulator's own raycaster), and tf as stageros +
fake_localization publish it: ``map -> <ns>/odom`` (fake_localization, every scan),
``<ns>/odom -> <ns>/base_link`` (every scan) and ``<ns>/base_link -> <ns>/base_laser_link``
(every scan, as stageros does). Optional ``stuck_feedback`` messages, ``/map`` once at the
start (latched in a real recording), ``/clock``. Nothing here needs a roscore.
"""
import math
from dataclasses import dataclass, field
from typing import List, Sequence, Tuple

import numpy as np

from sharing_layer_cpp import core
from fleet_sim.frames import yaw_quaternion


@dataclass
class SynthRobot:
    ns: str                                   # "" for an un-namespaced single robot
    path: Sequence[Tuple[float, float]]       # map-frame waypoints
    speed: float = 0.5                        # m/s along the path; stops at its end
    stuck_at: Sequence[float] = ()            # seconds from the start: one stuck_feedback each
    laser_offset: float = 0.275               # base_link -> base_laser_link, x (PR2/Stage)
    start_delay: float = 0.0                  # seconds standing still before driving


@dataclass
class SynthWorld:
    occupancy: np.ndarray                     # int8 (size_y, size_x): 100 wall, 0 free
    resolution: float
    blocks: List[Tuple[float, float, float, float]] = field(default_factory=list)  # min_x, min_y, max_x, max_y
    origin: Tuple[float, float] = (0.0, 0.0)

    def solid_grid(self):
        grid = (self.occupancy >= 100).astype(np.uint8)
        for min_x, min_y, max_x, max_y in self.blocks:
            x0 = int(math.floor((min_x - self.origin[0]) / self.resolution))
            x1 = int(math.ceil((max_x - self.origin[0]) / self.resolution))
            y0 = int(math.floor((min_y - self.origin[1]) / self.resolution))
            y1 = int(math.ceil((max_y - self.origin[1]) / self.resolution))
            grid[max(0, y0):max(0, y1), max(0, x0):max(0, x1)] = 1
        return grid


def corridor_world(width_m=40.0, height_m=12.0, resolution=0.05, corridor=(4.0, 8.0), block_x=None,
                   block_thickness=0.4):
    """A rectangular hall with a horizontal corridor between y = corridor[0] and corridor[1]
    (walls above and below it, open at both ends into the hall) and, optionally, a block that
    closes the corridor at x = block_x."""
    sx, sy = int(round(width_m / resolution)), int(round(height_m / resolution))
    occ = np.zeros((sy, sx), dtype=np.int8)
    occ[0:2, :] = occ[-2:, :] = 100
    occ[:, 0:2] = occ[:, -2:] = 100
    y_lo, y_hi = int(round(corridor[0] / resolution)), int(round(corridor[1] / resolution))
    x_lo, x_hi = int(round(0.25 * width_m / resolution)), int(round(0.75 * width_m / resolution))
    occ[y_lo - 2:y_lo, x_lo:x_hi] = 100
    occ[y_hi:y_hi + 2, x_lo:x_hi] = 100
    blocks = []
    if block_x is not None:
        blocks.append((block_x - block_thickness / 2, corridor[0], block_x + block_thickness / 2, corridor[1]))
    return SynthWorld(occ, resolution, blocks)


def big_world(size_cells=2000, resolution=0.05, seed=1):
    """A 2000 x 2000 grid (100 m at 0.05 m) with a border and a grid of corridors: the benchmark's map."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((size_cells, size_cells), dtype=np.int8)
    occ[0:2, :] = occ[-2:, :] = 100
    occ[:, 0:2] = occ[:, -2:] = 100
    step = int(10.0 / resolution)
    for k in range(step, size_cells - step + 1, step):
        occ[k:k + 2, :] = 100
        occ[:, k:k + 2] = 100
        # doors every room
        for d in range(step // 2, size_cells, step):
            occ[k:k + 2, d - 20:d + 20] = 0
            occ[d - 20:d + 20, k:k + 2] = 0
    blocks = []
    for _ in range(12):
        cx, cy = rng.uniform(5.0, size_cells * resolution - 5.0, size=2)
        blocks.append((cx - 0.3, cy - 0.3, cx + 0.3, cy + 0.3))
    return SynthWorld(occ, resolution, blocks)


def _pose_along(path, speed, t, start_delay=0.0):
    """(x, y, yaw) at time t along a polyline driven at constant speed."""
    travelled = max(0.0, t - start_delay) * speed
    for (x0, y0), (x1, y1) in zip(path[:-1], path[1:]):
        seg = math.hypot(x1 - x0, y1 - y0)
        yaw = math.atan2(y1 - y0, x1 - x0)
        if seg > 0.0 and travelled <= seg:
            f = travelled / seg
            return x0 + (x1 - x0) * f, y0 + (y1 - y0) * f, yaw
        travelled -= seg
    (x0, y0), (x1, y1) = path[-2], path[-1]
    return x1, y1, math.atan2(y1 - y0, x1 - x0)


def _transform(stamp, parent, child, x, y, yaw, z=0.0):
    from geometry_msgs.msg import TransformStamped
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
    q = yaw_quaternion(yaw)
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = q
    return t


def _name(ns, name):
    return "/".join(p for p in (ns, name) if p)


def write_bag(path, world, robots, duration, scan_rate=10.0, beams=1081, fov=math.radians(270.0),
              range_max=30.0, start=100.0, odom_offset=(0.0, 0.0, 0.0), tf_gaps=(), laser_frame_override=None,
              write_map=True, compression="none", progress=None):
    """Writes the bag; returns the number of messages written.

    odom_offset: (x, y, yaw) of every robot's odom frame in the map (the fake_localization transform).
    tf_gaps: (ns, from_s, to_s) windows in which that robot's map->odom is not published.
    laser_frame_override: {ns: frame} to stamp scans with a frame that tf does not know.
    """
    import rosbag
    import rospy
    from nav_msgs.msg import OccupancyGrid
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import LaserScan
    from std_msgs.msg import Empty
    from tf2_msgs.msg import TFMessage

    solid = world.solid_grid()
    sy, sx = world.occupancy.shape
    angle_min = -fov / 2.0
    increment = fov / (beams - 1)
    rel_angles = angle_min + increment * np.arange(beams)
    ox, oy, oyaw = odom_offset
    co, so = math.cos(oyaw), math.sin(oyaw)
    written = 0
    steps = int(round(duration * scan_rate))
    stuck = sorted((t, r.ns) for r in robots for t in r.stuck_at)
    with rosbag.Bag(path, "w", compression=compression) as bag:
        t0 = rospy.Time.from_sec(start)
        if write_map:
            grid = OccupancyGrid()
            grid.header.stamp = t0
            grid.header.frame_id = "map"
            grid.info.map_load_time = t0
            grid.info.resolution = world.resolution
            grid.info.width, grid.info.height = sx, sy
            grid.info.origin.position.x, grid.info.origin.position.y = world.origin
            grid.info.origin.orientation.w = 1.0
            grid.data = world.occupancy.reshape(-1).tobytes()
            bag.write("/map", grid, t0)
            written += 1
        seq = 0
        for step in range(steps):
            rel = step / scan_rate
            stamp = rospy.Time.from_sec(start + rel)
            clock = Clock()
            clock.clock = stamp
            bag.write("/clock", clock, stamp)
            written += 1
            while stuck and stuck[0][0] <= rel:
                _t, ns = stuck.pop(0)
                bag.write("/" + _name(ns, "stuck_feedback"), Empty(), stamp)
                written += 1
            for robot in robots:
                x, y, yaw = _pose_along(robot.path, robot.speed, rel, robot.start_delay)
                # odom pose = inverse(map->odom) * map pose
                dx, dy = x - ox, y - oy
                odx, ody = co * dx + so * dy, -so * dx + co * dy
                tfs = TFMessage()
                in_gap = any(ns == robot.ns and a <= rel < b for ns, a, b in tf_gaps)
                if not in_gap:
                    tfs.transforms.append(_transform(stamp, "map", _name(robot.ns, "odom"), ox, oy, oyaw))
                tfs.transforms.append(_transform(stamp, _name(robot.ns, "odom"), _name(robot.ns, "base_link"),
                                                 odx, ody, yaw - oyaw))
                tfs.transforms.append(_transform(stamp, _name(robot.ns, "base_link"),
                                                 _name(robot.ns, "base_laser_link"), robot.laser_offset, 0.0, 0.0,
                                                 0.25))
                bag.write("/tf", tfs, stamp)
                lx, ly = x + robot.laser_offset * math.cos(yaw), y + robot.laser_offset * math.sin(yaw)
                ranges = core.raycast_ranges(solid, world.resolution, world.origin[0], world.origin[1], lx, ly,
                                             rel_angles + yaw, 0.0, range_max)
                scan = LaserScan()
                scan.header.seq = seq
                scan.header.stamp = stamp
                scan.header.frame_id = (laser_frame_override or {}).get(robot.ns, _name(robot.ns, "base_laser_link"))
                scan.angle_min, scan.angle_max, scan.angle_increment = angle_min, -angle_min, increment
                scan.time_increment = 0.0
                scan.scan_time = 1.0 / scan_rate
                scan.range_min, scan.range_max = 0.0, range_max
                scan.ranges = ranges
                bag.write("/" + _name(robot.ns, "base_scan"), scan, stamp)
                written += 2
                seq += 1
            if progress is not None and step % 500 == 0:
                progress(step, steps)
    return written
