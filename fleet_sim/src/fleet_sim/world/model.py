"""What a loaded world holds: validated, frozen values in SI units (metres, radians, seconds)."""
import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

Pose2D = Tuple[float, float, float]    # x, y, yaw (radians)
RGB = Tuple[int, int, int]


@dataclass(frozen=True)
class RangerSpec:
    """One laser: pose relative to the robot's pose, limits as published on base_scan."""
    name: str
    pose: Pose2D
    range_min: float
    range_max: float
    fov: float                # radians
    samples: int
    where: str = ""           # file:line of the ranger, for log lines
    z: float = 0.0            # height above the top of the robot (Stage pose z of the ranger and its sensor)

    def __post_init__(self):
        if not (isinstance(self.samples, int) and self.samples >= 1):
            raise ValueError("ranger %s: samples must be >= 1, got %r" % (self.name, self.samples))
        if not (0.0 < self.fov <= 2.0 * math.pi + 1e-9):
            raise ValueError("ranger %s: fov must be in (0, 360] degrees, got %.3f degrees"
                             % (self.name, math.degrees(self.fov)))
        if not (0.0 <= self.range_min < self.range_max and math.isfinite(self.range_max)):
            raise ValueError("ranger %s: need 0 <= range_min < range_max, got [%r %r]"
                             % (self.name, self.range_min, self.range_max))

    @property
    def angle_min(self):
        return -self.fov / 2.0

    @property
    def angle_increment(self):
        """As stage_ros: fov / (samples - 1); 0 for a single beam."""
        return self.fov / (self.samples - 1) if self.samples > 1 else 0.0

    def beam_angles(self):
        """Beam angles relative to the sensor, angle_min first."""
        if self.samples == 1:
            return np.zeros(1)
        return self.angle_min + self.angle_increment * np.arange(self.samples, dtype=np.float64)


@dataclass(frozen=True)
class RobotSpec:
    """A Stage ``position`` model."""
    name: str
    pose: Pose2D
    size: Tuple[float, float]
    origin: Tuple[float, float]          # body centre offset in the robot frame
    color: RGB
    drive: str                           # 'diff' or 'omni'
    rangers: Tuple[RangerSpec, ...]
    where: str = ""
    height: float = 0.0                  # Stage size z: a ranger sits on top, as stage_ros publishes it

    def __post_init__(self):
        if self.drive not in ("diff", "omni"):
            raise ValueError("robot %s: drive must be \"diff\" or \"omni\", got %r" % (self.name, self.drive))
        if not (self.size[0] > 0 and self.size[1] > 0):
            raise ValueError("robot %s: size must be positive, got %r" % (self.name, self.size))


@dataclass(frozen=True)
class BlockSpec:
    """A plain model without bitmap: a solid rectangle (also the run-time movable blocks)."""
    name: str
    pose: Pose2D
    size: Tuple[float, float]
    color: RGB = (255, 0, 0)
    obstacle: bool = True     # obstacle_return: robots collide with it
    visible: bool = True      # ranger_return >= 0: lasers see it
    where: str = ""

    def __post_init__(self):
        if not all(math.isfinite(v) for v in self.pose):
            raise ValueError("block %s: pose must be finite, got %r" % (self.name, self.pose))
        if not (self.size[0] > 0 and self.size[1] > 0 and all(math.isfinite(v) for v in self.size)):
            raise ValueError("block %s: size must be positive, got %r" % (self.name, self.size))


@dataclass(frozen=True, eq=False)
class FloorplanSpec:
    """A model with a ``bitmap``: ``occupied[row, col]`` (row 0 = top of the image)
    is scaled to ``size`` and centred on ``pose``."""
    name: str
    pose: Pose2D
    size: Tuple[float, float]
    bitmap_path: str
    occupied: np.ndarray            # bool, image rows top-down
    boundary: bool
    color: RGB
    obstacle: bool = True
    visible: bool = True
    where: str = ""


@dataclass
class World:
    """A loaded world file. ``problems`` lists what was dropped (one line each)."""
    path: str
    resolution: float = 0.02
    interval_sim: float = 0.1
    speedup: Optional[float] = None
    floorplans: List[FloorplanSpec] = field(default_factory=list)
    blocks: List[BlockSpec] = field(default_factory=list)
    robots: List[RobotSpec] = field(default_factory=list)
    problems: List[str] = field(default_factory=list)
    files: List[str] = field(default_factory=list)

    def bounds(self, margin=0.0):
        """(min_x, min_y, max_x, max_y) covering every floorplan, block and robot."""
        xs, ys = [], []
        for f in self.floorplans:
            for cx, cy in _rect_corners(f.pose, f.size):
                xs.append(cx)
                ys.append(cy)
        for b in self.blocks:
            for cx, cy in _rect_corners(b.pose, b.size):
                xs.append(cx)
                ys.append(cy)
        for r in self.robots:
            reach = max(r.size) + max((math.hypot(g.pose[0], g.pose[1]) for g in r.rangers), default=0.0)
            xs += [r.pose[0] - reach, r.pose[0] + reach]
            ys += [r.pose[1] - reach, r.pose[1] + reach]
        if not xs:
            return (-5.0, -5.0, 5.0, 5.0)
        return (min(xs) - margin, min(ys) - margin, max(xs) + margin, max(ys) + margin)


def _rect_corners(pose, size, origin=(0.0, 0.0)):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = []
    for dx, dy in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
        lx = origin[0] + dx * size[0]
        ly = origin[1] + dy * size[1]
        out.append((pose[0] + c * lx - s * ly, pose[1] + s * lx + c * ly))
    return out


rect_corners = _rect_corners
