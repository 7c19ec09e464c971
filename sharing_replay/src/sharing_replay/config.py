"""Validated settings of a replay: frames, topics, tf limits, layer and handler parameters, map.

Layer parameters are read exactly as fleet_nav reads them (``fleet_nav.params.NavParams``,
the move_base/costmap_2d YAML layout), so a replay with the same files as a live run uses the
same obstacle_range, raytrace_range, heights, lethal threshold and ``sharing/`` keys.
"""
import math
import os
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import numpy as np

from fleet_nav.costmap import static_costs as nav_static_costs
from fleet_nav.errors import ParameterError
from fleet_nav.params import NavParams
from fleet_sim import map_io
from fleet_sim.errors import MapError
from sharing_replay.errors import InputError


@dataclass(frozen=True)
class MapData:
    """The static map the layer filters against: OccupancyGrid values, row 0 = lowest y."""
    occupancy: np.ndarray      # int8 (size_y, size_x)
    resolution: float
    origin_x: float
    origin_y: float
    source: str                # where it came from, for the report

    @property
    def size_x(self):
        return int(self.occupancy.shape[1])

    @property
    def size_y(self):
        return int(self.occupancy.shape[0])


#: move_base's default footprint where no parameter gives one: a circle of robot_radius 0.46 m plus
#: footprint_padding 0.01 m, as fleet_nav.params builds it (a 16-gon)
DEFAULT_FOOTPRINT = NavParams.from_dict({})[0].footprint_polygon


@dataclass(frozen=True)
class ReplaySettings:
    scan_topic: str = "base_scan"
    global_frame: str = "map"
    base_frame: str = "base_link"           # gets the robot namespace as prefix ("robot_0/base_link")
    robots: Tuple[str, ...] = ()            # namespaces to replay; () = every namespace with a scan topic
    single_robot_name: str = "robot"        # name of the robot of an un-namespaced bag
    trigger: str = "auto"                   # auto | stuck_feedback | recovery_status | both | none
    trigger_at: Tuple[Tuple[Optional[str], float], ...] = ()  # (robot or None for all, seconds from start)
    # global-plan topics (nav_msgs/Path) for the layer's plan-blocked trigger, relative to each
    # namespace; () switches it off. move_base publishes its global planner's plan on one of them.
    plan_topics: Tuple[str, ...] = ("move_base/NavfnROS/plan", "move_base/GlobalPlanner/plan")
    tf_max_gap: float = 1.0
    tf_tolerance: float = 0.2
    tf_wait: float = 1.0
    obstacle_duration: float = 1200.0
    expiry_rate: float = 1.0
    max_cells_per_message: int = 100000
    wall_distance: int = 3
    layer: Dict[str, object] = field(default_factory=dict)   # kwargs of core.LayerParams (minus robot_name)
    lethal_cost_threshold: int = 100
    track_unknown_space: bool = False
    seed: int = 0
    # Fleet robots are never shared (the layer's FleetRobots): the bag's other robots, placed from tf, with
    # their recorded footprint or this one (robot frame; fleet_nav's footprint_polygon), plus the margin.
    robot_exclusion: bool = True
    robot_exclusion_margin: float = 0.2
    robot_timeout: float = 3.0
    robot_exclusion_trail: float = 1.0
    footprint: Tuple[Tuple[float, float], ...] = DEFAULT_FOOTPRINT
    # a --map that is not the bag's /map (resolution, origin, size) is refused unless this is set
    allow_map_mismatch: bool = False

    def __post_init__(self):
        def positive(name, allow_zero=False):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or (v < 0 if allow_zero else v <= 0):
                raise InputError("%s must be a %s finite number, got %r"
                                 % (name, "non-negative" if allow_zero else "positive", v))
        for name in ("tf_max_gap", "obstacle_duration", "expiry_rate"):
            positive(name)
        for name in ("tf_tolerance", "tf_wait"):
            positive(name, allow_zero=True)
        if self.obstacle_duration > 2 ** 32 - 1:
            raise InputError("obstacle_duration must be at most 4294967295 s, got %r" % self.obstacle_duration)
        if not isinstance(self.wall_distance, int) or self.wall_distance < 0:
            raise InputError("wall_distance must be a non-negative integer, got %r" % (self.wall_distance,))
        if not isinstance(self.max_cells_per_message, int) or self.max_cells_per_message < 1:
            raise InputError("max_cells_per_message must be a positive integer, got %r"
                             % (self.max_cells_per_message,))
        if not all(isinstance(t, str) and t.strip() and " " not in t for t in self.plan_topics):
            raise InputError("plan_topics must be topic names without spaces, got %r" % (self.plan_topics,))
        if self.trigger not in ("auto", "stuck_feedback", "recovery_status", "both", "none"):
            raise InputError("trigger must be auto, stuck_feedback, recovery_status, both or none; got %r"
                             % (self.trigger,))
        for name in ("scan_topic", "global_frame", "base_frame", "single_robot_name"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.strip("/"):
                raise InputError("%s must be a non-empty name, got %r" % (name, value))
        positive("robot_timeout", allow_zero=True)
        positive("robot_exclusion_margin", allow_zero=True)
        positive("robot_exclusion_trail", allow_zero=True)
        if self.robot_exclusion_trail > 10.0:
            raise InputError("robot_exclusion_trail must be 0..10 s (the layer's limit), got %r"
                             % (self.robot_exclusion_trail,))
        if len(self.footprint) < 1 or not all(len(p) == 2 and all(math.isfinite(v) for v in p) for p in self.footprint):
            raise InputError("footprint must be a list of finite [x, y] points, got %r" % (self.footprint,))
        for robot, t in self.trigger_at:
            if not math.isfinite(t) or t < 0:
                raise InputError("--trigger-at time must be >= 0 seconds from the bag start, got %r" % t)


def load_params_tree(paths, overrides):
    """Merges YAML files (like rosparam load into the node's private namespace) and key=value
    overrides (values parsed as YAML, keys with '/' nest). Raises InputError."""
    import yaml
    tree = {}

    def merge(dst, src):
        for key, value in src.items():
            if isinstance(value, dict) and isinstance(dst.get(key), dict):
                merge(dst[key], value)
            else:
                dst[key] = value
    for path in paths:
        try:
            with open(path, "r", encoding="utf-8") as handle:
                doc = yaml.safe_load(handle)
        except OSError as err:
            raise InputError("parameter file %s cannot be read (%s)" % (path, err.strerror)) from None
        except yaml.YAMLError as err:
            raise InputError("parameter file %s is not valid YAML (%s)" % (path, str(err).splitlines()[0]))
        if doc is None:
            continue
        if not isinstance(doc, dict):
            raise InputError("parameter file %s must hold a mapping, got %s" % (path, type(doc).__name__))
        merge(tree, doc)
    for item in overrides:
        if "=" not in item:
            raise InputError("--param needs key=value, got %r" % item)
        key, text = item.split("=", 1)
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        node = tree
        parts = [p for p in key.strip().split("/") if p]
        if not parts:
            raise InputError("--param needs key=value, got %r" % item)
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise InputError("--param %s: %s is not a namespace" % (item, part))
        node[parts[-1]] = value
    return tree


def exclusion_from_tree(tree):
    """The fleet-robot exclusion's settings (ReplaySettings keywords) via fleet_nav's reader: footprint
    (padded, or a 16-gon of robot_radius), robot_exclusion_margin, robot_timeout, robot_exclusion_trail."""
    try:
        params, _unused = NavParams.from_dict(tree)
    except ParameterError as err:
        raise InputError("bad parameter: %s" % err) from None
    return dict(footprint=tuple(params.footprint_polygon), robot_exclusion_margin=params.robot_exclusion_margin,
                robot_timeout=params.robot_timeout, robot_exclusion_trail=params.robot_exclusion_trail)


def layer_kwargs_from_tree(tree):
    """(layer kwargs, lethal_cost_threshold, track_unknown_space, unused keys) via fleet_nav's reader."""
    try:
        params, unused = NavParams.from_dict(tree)
    except ParameterError as err:
        raise InputError("bad parameter: %s" % err) from None
    # inscribed_radius: the plan-blocked trigger looks this far beside the plan, as the plugin does
    # with its layered costmap's footprint.
    kwargs = dict(obstacle_range=params.obstacle_range, raytrace_range=params.raytrace_range,
                  min_obstacle_height=params.min_obstacle_height, max_obstacle_height=params.max_obstacle_height,
                  inscribed_radius=params.inscribed_radius)
    kwargs.update(params.sharing)
    return kwargs, params.lethal_cost_threshold, params.track_unknown_space, unused


def load_map(map_yaml=None, map_image=None, resolution=None, origin=(0.0, 0.0, 0.0)):
    """A MapData from a map_server YAML or an image + resolution (map_server's semantics, through
    fleet_sim.map_io). Raises InputError."""
    try:
        if map_yaml:
            m = map_io.load_map_yaml(map_yaml)
        else:
            if resolution is None:
                raise InputError("--map-image %s needs --resolution (metres per pixel)" % map_image)
            m = map_io.load_map_image(map_image, resolution, origin)
    except MapError as err:
        raise InputError(str(err)) from None
    if abs(m.origin[2]) > 1e-6:
        raise InputError("map origin yaw %r: a rotated map is not supported (costmap_2d ignores it too)"
                         % m.origin[2])
    return MapData(np.ascontiguousarray(m.data), float(m.resolution), float(m.origin[0]), float(m.origin[1]),
                   os.path.abspath(map_yaml or map_image))


#: how far a given map's origin may lie from the bag's /map's (m): far below a cell, above float rounding
ORIGIN_TOLERANCE = 1e-3
#: relative difference of resolutions taken as equal (float32 on the wire holds about 7 digits)
RESOLUTION_TOLERANCE = 1e-6


def describe_map(m):
    return "%g m/cell, origin (%g, %g), %d x %d cells" % (m.resolution, m.origin_x, m.origin_y, m.size_x, m.size_y)


def map_differences(given, recorded):
    """What differs between two maps' grids (resolution, origin, size), as lines; [] when they are one grid."""
    out = []
    if abs(given.resolution - recorded.resolution) > RESOLUTION_TOLERANCE * recorded.resolution:
        out.append("resolution %g m/cell, the bag's %g" % (given.resolution, recorded.resolution))
    if max(abs(given.origin_x - recorded.origin_x), abs(given.origin_y - recorded.origin_y)) > ORIGIN_TOLERANCE:
        out.append("origin (%g, %g), the bag's (%g, %g)" % (given.origin_x, given.origin_y, recorded.origin_x,
                                                            recorded.origin_y))
    if (given.size_x, given.size_y) != (recorded.size_x, recorded.size_y):
        out.append("size %d x %d cells, the bag's %d x %d" % (given.size_x, given.size_y, recorded.size_x,
                                                              recorded.size_y))
    return out


def map_from_message(msg, topic):
    """A MapData from a nav_msgs/OccupancyGrid found in the bag; raises InputError when unusable."""
    info = msg.info
    if info.width == 0 or info.height == 0 or len(msg.data) != info.width * info.height:
        raise InputError("%s in the bag is %dx%d with %d cells of data" % (topic, info.width, info.height,
                                                                           len(msg.data)))
    if not (info.resolution > 0 and math.isfinite(info.resolution)):
        raise InputError("%s in the bag has resolution %r" % (topic, info.resolution))
    data = np.frombuffer(bytes(np.asarray(msg.data, dtype=np.int8).tobytes()), dtype=np.int8)
    # OccupancyGrid resolution is float32 on the wire: 0.1 arrives as 0.10000000149; float32 holds
    # 7 significant digits, so rounding to 7 gives back what the map's YAML said.
    resolution = float("%.7g" % info.resolution)
    return MapData(data.reshape(info.height, info.width).copy(), resolution, float(info.origin.position.x),
                   float(info.origin.position.y), "%s (from the bag)" % topic)


def static_costs(map_data, lethal_cost_threshold=100, track_unknown_space=False):
    """costmap_2d's StaticLayer interpretation, exactly as fleet_nav's global costmap does it."""
    return nav_static_costs(map_data.occupancy, lethal_cost_threshold, track_unknown_space)
