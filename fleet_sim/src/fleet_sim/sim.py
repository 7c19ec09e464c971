"""The simulation core (no ROS): robots, blocks, lasers, localisation error.

One ``step()`` advances ``dt`` (the world's ``interval_sim``): each robot applies
its last velocity command unless the watchdog expired, and stops where it would
hit a wall, a block or another robot (Stage's "stall"). Lasers are raycast by the
C++ core against a grid holding the floorplans, the blocks and the other robots'
footprints. Time is only ``self.time``: nothing here reads a clock.

Frames: the world frame is Stage's. Odometry is perfect and its frame is the
world frame, as stageros publishes it with Stage's default "gps" localisation.
``map_to_odom(i)`` is what a localiser would publish: T_map_world (derived from
the floorplan, see ``frames.world_from_map``) with robot i's configurable error
(offset + Gaussian noise, redrawn every step from ``seed``) applied at the robot.
"""
import logging
import math
from dataclasses import dataclass, field
from typing import List, Tuple

import numpy as np

from fleet_sim import frames
from fleet_sim.errors import InvalidRequestError
from fleet_sim.world.model import BlockSpec, rect_corners
from fleet_sim.world.raster import GridGeometry, paint_floorplan, rect_cells

_LOG = logging.getLogger(__name__)

GRID_MARGIN = 1.0          # metres of free grid around the world's bounds
ROBOT_CELL = 2             # value of other robots' cells in the raycast grid


@dataclass(frozen=True)
class LocalisationError:
    """Per-robot map→odom error: offset in the map frame (m, m, rad) plus noise std."""
    dx: float = 0.0
    dy: float = 0.0
    dyaw: float = 0.0
    std_xy: float = 0.0
    std_yaw: float = 0.0

    def __post_init__(self):
        for name in ("dx", "dy", "dyaw", "std_xy", "std_yaw"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError("localisation error %s must be a finite number, got %r" % (name, v))
        if self.std_xy < 0 or self.std_yaw < 0:
            raise ValueError("localisation noise std must be >= 0, got %r / %r" % (self.std_xy, self.std_yaw))


@dataclass
class RobotState:
    spec: object
    index: int
    pose: Tuple[float, float, float]
    cmd: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    cmd_time: float = -math.inf
    velocity: Tuple[float, float, float] = (0.0, 0.0, 0.0)   # applied in the last step
    stalled: bool = False
    loc_error: LocalisationError = field(default_factory=LocalisationError)
    loc_noise: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    scans: List[np.ndarray] = field(default_factory=list)     # one per ranger
    cells: Tuple[np.ndarray, np.ndarray] = None               # footprint in the raycast grid


class Simulation:
    """N robots in a loaded ``World``.

    ``raycast`` is the core's ``raycast_ranges`` (injectable for tests);
    ``map_from_world`` is T_map_world (default: from the first floorplan, as
    map_server would serve its bitmap with origin 0).
    """

    def __init__(self, world, raycast=None, seed=0, watchdog_timeout=0.2, laser_rate=10.0,
                 resolution=None, map_from_world=None, localisation=None):
        if raycast is None:
            from fleet_sim.raycast import core_raycaster
            raycast = core_raycaster()
        self.world = world
        self._raycast = raycast
        self.dt = world.interval_sim
        self.time = 0.0
        self.steps = 0
        self.watchdog_timeout = watchdog_timeout
        self.laser_every = max(1, int(round(1.0 / (laser_rate * self.dt)))) if laser_rate > 0 else 0
        self.scan_time = None
        self.rng = np.random.default_rng(seed)
        res = resolution or world.resolution
        self.bounds = world.bounds()
        self.geom = GridGeometry.covering(world.bounds(GRID_MARGIN), res)
        shape = (self.geom.size_y, self.geom.size_x)
        self._base_laser = np.zeros(shape, dtype=np.uint8)
        self._base_coll = np.zeros(shape, dtype=np.uint8)
        for fp in world.floorplans:
            if fp.visible:
                paint_floorplan(self._base_laser, self.geom, fp)
            if fp.obstacle:
                paint_floorplan(self._base_coll, self.geom, fp)
        self.laser_grid = self._base_laser.copy()     # floorplans + blocks (+ robots while scanning)
        self.coll_grid = self._base_coll.copy()       # floorplans + blocks
        self.blocks = {}
        for b in world.blocks:
            self.blocks[b.name] = b
            self._paint_block(b)
        if map_from_world is None:
            map_from_world = default_map_from_world(world)
        self.map_from_world = map_from_world
        self.robots = [RobotState(spec=r, index=i, pose=r.pose) for i, r in enumerate(world.robots)]
        localisation = localisation or {}
        for i, err in localisation.items():
            self.set_localisation_error(i, err)
        for r in self.robots:
            if self._hits_static(r, r.pose):
                _LOG.warning("robot_%d (%s) starts inside a wall or block at (%.2f, %.2f); "
                             "it cannot move until freed", r.index, r.spec.name, r.pose[0], r.pose[1])
        self._draw_noise()
        self._update_scans()

    # --- commands -------------------------------------------------------------
    def robot(self, index):
        if not isinstance(index, int) or not 0 <= index < len(self.robots):
            raise InvalidRequestError("no robot %r (the world has %d)" % (index, len(self.robots)))
        return self.robots[index]

    def set_cmd_vel(self, index, vx, vy, wz):
        """Velocity command in the robot frame (vy ignored for diff drive), stamped now."""
        r = self.robot(index)
        if not all(math.isfinite(v) for v in (vx, vy, wz)):
            raise InvalidRequestError("robot_%d: cmd_vel must be finite, got (%r, %r, %r)"
                                      % (index, vx, vy, wz))
        if r.spec.drive == "diff":
            vy = 0.0
        r.cmd = (float(vx), float(vy), float(wz))
        r.cmd_time = self.time

    def set_localisation_error(self, index, err):
        self.robot(index).loc_error = err if isinstance(err, LocalisationError) else LocalisationError(*err)

    def teleport(self, index, pose):
        """Puts a robot at a world pose (tests, scenario set-up); refuses a colliding pose."""
        r = self.robot(index)
        pose = tuple(float(v) for v in pose)
        if not all(math.isfinite(v) for v in pose):
            raise InvalidRequestError("robot_%d: pose must be finite, got %r" % (index, pose))
        if self._collides(r, pose):
            raise InvalidRequestError("robot_%d: pose (%.2f, %.2f) collides" % (index, pose[0], pose[1]))
        r.pose = (pose[0], pose[1], frames.normalize_angle(pose[2]))
        self._update_scans()

    # --- stepping -------------------------------------------------------------
    def step(self):
        """Advances one interval: motion, then (when due) the lasers."""
        dt = self.dt
        self.time = (self.steps + 1) * dt
        for r in self.robots:
            if self.time - r.cmd_time > self.watchdog_timeout + 1e-9:
                r.cmd = (0.0, 0.0, 0.0)
            vx, vy, wz = r.cmd
            if vx == 0.0 and vy == 0.0 and wz == 0.0:
                r.velocity = (0.0, 0.0, 0.0)
                r.stalled = False
                continue
            x, y, th = r.pose
            mid = th + 0.5 * wz * dt
            c, s = math.cos(mid), math.sin(mid)
            new = (x + (c * vx - s * vy) * dt, y + (s * vx + c * vy) * dt,
                   frames.normalize_angle(th + wz * dt))
            if self._collides(r, new):
                r.velocity = (0.0, 0.0, 0.0)
                r.stalled = True
            else:
                r.pose = new
                r.velocity = (vx, vy, wz)
                r.stalled = False
        self.steps += 1
        self._draw_noise()
        if self.laser_every and self.steps % self.laser_every == 0:
            self._update_scans()

    def _draw_noise(self):
        for r in self.robots:
            e = r.loc_error
            if e.std_xy > 0 or e.std_yaw > 0:
                n = self.rng.normal(size=3)
                r.loc_noise = (n[0] * e.std_xy, n[1] * e.std_xy, n[2] * e.std_yaw)
            else:
                r.loc_noise = (0.0, 0.0, 0.0)

    # --- collisions -------------------------------------------------------------
    def _hits_static(self, r, pose):
        rows, cols = rect_cells(self.geom, pose, r.spec.size, r.spec.origin)
        return bool(rows.size and self.coll_grid[rows, cols].any())

    def _collides(self, r, pose):
        if self._hits_static(r, pose):
            return True
        mine = rect_corners(pose, r.spec.size, r.spec.origin)
        reach = 0.5 * math.hypot(*r.spec.size) + math.hypot(*r.spec.origin)
        for o in self.robots:
            if o is r:
                continue
            oreach = 0.5 * math.hypot(*o.spec.size) + math.hypot(*o.spec.origin)
            if math.hypot(o.pose[0] - pose[0], o.pose[1] - pose[1]) > reach + oreach:
                continue
            if _convex_overlap(mine, rect_corners(o.pose, o.spec.size, o.spec.origin)):
                return True
        return False

    # --- lasers -------------------------------------------------------------------
    def sensor_pose(self, index, ranger_index):
        r = self.robots[index]
        return frames.compose(r.pose, r.spec.rangers[ranger_index].pose)

    def _update_scans(self):
        g = self.geom
        grid = self.laser_grid
        saved = []
        for r in self.robots:
            rows, cols = rect_cells(g, r.pose, r.spec.size, r.spec.origin)
            r.cells = (rows, cols)
            saved.append(grid[rows, cols].copy())
            grid[rows, cols] = ROBOT_CELL
        try:
            for r, own in zip(self.robots, saved):
                if not r.spec.rangers:
                    continue
                rows, cols = r.cells
                grid[rows, cols] = own               # a robot does not see itself
                try:
                    scans = []
                    for k, ranger in enumerate(r.spec.rangers):
                        # As in Stage, a beam hits only robots whose body spans its height.
                        over = [(o, s) for o, s in zip(self.robots, saved)
                                if o is not r and not beam_hits_body(r.spec.height, ranger.z, o.spec.height)]
                        for o, s in over:
                            grid[o.cells[0], o.cells[1]] = s
                        sx, sy, sth = frames.compose(r.pose, ranger.pose)
                        angles = sth + ranger.beam_angles()
                        ranges = self._raycast(grid, g.resolution, g.origin_x, g.origin_y, sx, sy,
                                               angles, ranger.range_min, ranger.range_max)
                        for o, _s in over:
                            grid[o.cells[0], o.cells[1]] = ROBOT_CELL
                        scans.append(np.asarray(ranges, dtype=np.float32))
                    r.scans = scans
                finally:
                    grid[rows, cols] = ROBOT_CELL
        finally:
            for r, own in zip(self.robots, saved):
                grid[r.cells[0], r.cells[1]] = own
        self.scan_time = self.time

    # --- localisation -------------------------------------------------------------
    def map_to_odom(self, index):
        """T_map_odom as robot ``index`` believes it (odom = world frame).

        The error is robot-centred, as a localiser's error is: the believed pose in
        the map is the true one shifted by (dx, dy) in the map frame and turned by
        dyaw about the robot, plus this step's noise. Without error this is
        T_map_world.
        """
        r = self.robot(index)
        e, n = r.loc_error, r.loc_noise
        true_map = frames.compose(self.map_from_world, r.pose)
        believed = (true_map[0] + e.dx + n[0], true_map[1] + e.dy + n[1], true_map[2] + e.dyaw + n[2])
        return frames.compose(believed, frames.inverse(r.pose))

    # --- blocks -------------------------------------------------------------------
    def add_block(self, name, x, y, yaw, size_x, size_y, color=(255, 0, 0)):
        """Adds a solid block (world frame, metres/radians). Raises InvalidRequestError."""
        if not isinstance(name, str) or not name.strip():
            raise InvalidRequestError("block name must not be empty")
        if name in self.blocks:
            raise InvalidRequestError("block '%s' exists already (use move_block)" % name)
        block = self._valid_block(name, (x, y, yaw), (size_x, size_y), color)
        self.blocks[name] = block
        self._paint_block(block)
        self._update_scans()
        return block

    def move_block(self, name, x, y, yaw):
        old = self._existing(name)
        block = self._valid_block(name, (x, y, yaw), old.size, old.color, old)
        del self.blocks[name]
        self._unpaint(old)
        self.blocks[name] = block
        self._paint_block(block)
        self._update_scans()
        return block

    def remove_block(self, name):
        old = self._existing(name)
        del self.blocks[name]
        self._unpaint(old)
        self._update_scans()
        return old

    def _existing(self, name):
        if name not in self.blocks:
            raise InvalidRequestError("no block named '%s' (blocks: %s)"
                                      % (name, ", ".join(sorted(self.blocks)) or "none"))
        return self.blocks[name]

    def _valid_block(self, name, pose, size, color, old=None):
        try:
            pose = tuple(float(v) for v in pose)
            size = tuple(float(v) for v in size)
            block = BlockSpec(name=name, pose=(pose[0], pose[1], frames.normalize_angle(pose[2])),
                              size=size, color=color,
                              obstacle=old.obstacle if old else True,
                              visible=old.visible if old else True, where="service")
        except (TypeError, ValueError) as err:
            raise InvalidRequestError(str(err)) from None
        min_x, min_y, max_x, max_y = self.bounds
        for cx, cy in rect_corners(block.pose, block.size):
            if not (min_x - 1e-9 <= cx <= max_x + 1e-9 and min_y - 1e-9 <= cy <= max_y + 1e-9):
                raise InvalidRequestError(
                    "block '%s' at (%.2f, %.2f) size %.2f x %.2f would leave the world "
                    "[%.2f, %.2f] x [%.2f, %.2f]" % (name, pose[0], pose[1], size[0], size[1],
                                                     min_x, max_x, min_y, max_y))
        if block.obstacle:
            corners = rect_corners(block.pose, block.size)
            for r in self.robots:
                if _convex_overlap(corners, rect_corners(r.pose, r.spec.size, r.spec.origin)):
                    raise InvalidRequestError("block '%s' at (%.2f, %.2f) would overlap robot_%d"
                                              % (name, pose[0], pose[1], r.index))
        return block

    def _paint_block(self, b, box=None):
        rows, cols = rect_cells(self.geom, b.pose, b.size)
        if box is not None:
            c0, r0, c1, r1 = box
            keep = (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
            rows, cols = rows[keep], cols[keep]
        if b.visible:
            self.laser_grid[rows, cols] = 1
        if b.obstacle:
            self.coll_grid[rows, cols] = 1

    def _unpaint(self, b):
        """Restores the cells under a removed block, then repaints blocks that overlapped them."""
        box = self.geom.bbox_cells(rect_corners(b.pose, b.size))
        if box is None:
            return
        c0, r0, c1, r1 = box
        self.laser_grid[r0:r1, c0:c1] = self._base_laser[r0:r1, c0:c1]
        self.coll_grid[r0:r1, c0:c1] = self._base_coll[r0:r1, c0:c1]
        for other in self.blocks.values():
            if self.geom.bbox_cells(rect_corners(other.pose, other.size)) is not None:
                self._paint_block(other, box)


def default_map_from_world(world):
    """T_map_world for the map map_server serves from the first floorplan's bitmap
    at its native scale with origin (0, 0, 0); identity if there is no floorplan."""
    if not world.floorplans:
        return (0.0, 0.0, 0.0)
    fp = world.floorplans[0]
    return frames.inverse(frames.world_from_map(fp.pose, fp.size))


def _convex_overlap(a, b):
    """Separating-axis test for two convex polygons given as corner lists."""
    for poly in (a, b):
        n = len(poly)
        for i in range(n):
            x1, y1 = poly[i]
            x2, y2 = poly[(i + 1) % n]
            ax, ay = y1 - y2, x2 - x1
            pa = [ax * px + ay * py for px, py in a]
            pb = [ax * px + ay * py for px, py in b]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True


# Stage casts a ranger's beams at the height of its sensor's middle: the ranger sits on top of the robot's
# body (its size z) plus its own pose z, and its sensor's default 0.02 m box puts the beam 0.01 m above that.
BEAM_ABOVE_SENSOR_POSE = 0.01


def beam_hits_body(robot_height, ranger_z, other_height):
    """Whether a beam of a ranger at pose z ``ranger_z`` on a body ``robot_height`` tall hits another
    robot's body ``other_height`` tall (Stage's z test: the beam's height within the body's [0, height]).
    A world that gives no heights (Stage-3 sizes [x y]: height 0) has every beam hit every robot."""
    if robot_height <= 0.0 or other_height <= 0.0:
        return True
    beam = robot_height + ranger_z + BEAM_ABOVE_SENSOR_POSE
    return 0.0 <= beam <= other_height
