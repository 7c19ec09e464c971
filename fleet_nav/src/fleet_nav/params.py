"""The parameters fleet_nav shares with move_base and costmap_2d, read from the usual YAML layout.

The navigation tutorials load ``costmap_common_params.yaml`` into ``global_costmap`` and
``local_costmap``, ``global_costmap_params.yaml`` / ``local_costmap_params.yaml`` and the local
planner's file at the node's top level. ``NavParams.from_dict`` takes the node's private
parameter tree and returns validated values plus the keys it did not use (logged once).

Lookup order for a costmap key K: ``global_costmap/K``, ``global_costmap/inflation_layer/K``
(inflation keys only), then ``K``. Local-planner keys come from ``TrajectoryPlannerROS/``, then
``DWAPlannerROS/``, then the top level. Layer parameters of the sharing layer come from
``sharing/`` or ``sharing_layer/`` (static_tolerance, proposal_strategy, trigger_debounce,
cluster_gap, min_cluster_cells, rectangle_padding, max_update_cells, static_occupied_cost, clearing_margin,
clearing_scans, clearing_time, clearing_neighbours, trigger_memory, trigger_radius, memory_on_stuck_feedback,
lease_renewal_interval), and the fleet-robot exclusion from the same place (robot_exclusion_margin, robot_timeout,
robot_exclusion_trail).
"""
import ast
import math
from dataclasses import dataclass, field
from typing import Dict, List, Tuple

from fleet_nav.errors import ParameterError

SHARING_KEYS = ("static_tolerance", "proposal_strategy", "trigger_debounce", "cluster_gap",
                "min_cluster_cells", "rectangle_padding", "max_update_cells", "static_occupied_cost",
                "clearing_margin", "clearing_scans", "clearing_time", "clearing_neighbours", "trigger_memory",
                "trigger_radius", "memory_on_stuck_feedback", "lease_renewal_interval")


def flatten(tree, prefix=""):
    """A nested parameter tree as {"global_costmap/obstacle_range": value, ...}."""
    out = {}
    for key, value in (tree or {}).items():
        name = prefix + str(key)
        if isinstance(value, dict):
            out.update(flatten(value, name + "/"))
        else:
            out[name] = value
    return out


def _number(name, value, low=None, high=None, low_open=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError("parameter %s must be a number, got %r" % (name, value))
    value = float(value)
    if not math.isfinite(value):
        raise ParameterError("parameter %s must be finite, got %r" % (name, value))
    if low is not None and (value <= low if low_open else value < low):
        raise ParameterError("parameter %s must be %s %s, got %r" % (name, ">" if low_open else ">=", low, value))
    if high is not None and value > high:
        raise ParameterError("parameter %s must be <= %s, got %r" % (name, high, value))
    return value


def parse_footprint(name, value):
    """costmap_2d accepts a list of [x, y] points or the same written as a string."""
    if isinstance(value, str):
        try:
            value = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            raise ParameterError("parameter %s must be [[x, y], ...], got %r" % (name, value)) from None
    if not isinstance(value, (list, tuple)) or len(value) < 3:
        raise ParameterError("parameter %s needs at least 3 points, got %r" % (name, value))
    points = []
    for p in value:
        if not isinstance(p, (list, tuple)) or len(p) != 2:
            raise ParameterError("parameter %s: point %r is not [x, y]" % (name, p))
        points.append((_number(name, p[0]), _number(name, p[1])))
    return tuple(points)


def pad_footprint(points, padding):
    """costmap_2d's padFootprint: every coordinate moved away from zero by padding."""
    return tuple((x + math.copysign(padding, x) if x != 0 else x,
                  y + math.copysign(padding, y) if y != 0 else y) for x, y in points)


def inscribed_radius(points):
    """Smallest distance from the robot centre to an edge of the footprint polygon."""
    best = math.inf
    n = len(points)
    for i in range(n):
        (x0, y0), (x1, y1) = points[i], points[(i + 1) % n]
        dx, dy = x1 - x0, y1 - y0
        length2 = dx * dx + dy * dy
        t = 0.0 if length2 == 0 else max(0.0, min(1.0, -(x0 * dx + y0 * dy) / length2))
        best = min(best, math.hypot(x0 + t * dx, y0 + t * dy))
    return best


@dataclass(frozen=True)
class NavParams:
    robot_name: str = "robot"
    global_frame: str = "map"
    robot_base_frame: str = "base_link"
    obstacle_range: float = 2.5
    raytrace_range: float = 3.0
    min_obstacle_height: float = 0.0
    max_obstacle_height: float = 2.0
    inflation_radius: float = 0.55
    cost_scaling_factor: float = 10.0
    footprint: Tuple[Tuple[float, float], ...] = ()
    robot_radius: float = 0.46
    update_frequency: float = 5.0
    # move_base's own parameters, with move_base's defaults
    planner_frequency: float = 0.0
    controller_frequency: float = 20.0
    planner_patience: float = 5.0
    controller_patience: float = 15.0
    max_planning_retries: int = -1
    oscillation_timeout: float = 0.0
    oscillation_distance: float = 0.5
    recovery_behavior_enabled: bool = True
    clearing_rotation_allowed: bool = True
    conservative_reset_dist: float = 3.0
    conservative_reset_layer_names: Tuple[str, ...] = ("obstacle_layer",)
    aggressive_reset_layer_names: Tuple[str, ...] = ("obstacle_layer",)
    # the thesis's modified move_base: stuck_feedback when computeVelocityCommands fails
    stuck_feedback_on_local_failure: bool = False
    lethal_cost_threshold: int = 100
    track_unknown_space: bool = False
    # base_local_planner's (TrajectoryPlannerROS) parameters, with its defaults
    max_vel_x: float = 0.5
    max_rotational_vel: float = 1.0
    min_in_place_rotational_vel: float = 0.4
    acc_lim_th: float = 3.2
    sim_time: float = 1.0
    xy_goal_tolerance: float = 0.1
    yaw_goal_tolerance: float = 0.05
    escape_vel: float = -0.1
    # fleet_nav's own controller (a stand-in for base_local_planner)
    lookahead: float = 0.6
    blocked_lookahead: float = 0.0   # 0: the local planner's reach, sim_time x max_vel_x
    clearance_margin: float = 0.1
    collision_horizon: float = 0.5
    stall_time: float = 1.5
    sharing_enabled: bool = True
    # the sharing layer's plan-blocked trigger (the plugin's plan_topics; empty there = off)
    plan_trigger: bool = True
    sharing: Dict[str, object] = field(default_factory=dict)
    # fleet robots are never shared: cells within a known robot's footprint plus this margin (m), and its
    # footprints of the last robot_exclusion_trail s; robots not heard for robot_timeout (s) are forgotten
    # (the layer's FleetRobots)
    robot_exclusion_margin: float = 0.2
    robot_timeout: float = 3.0
    robot_exclusion_trail: float = 1.0
    map_wait_log_period: float = 5.0

    def __post_init__(self):
        for name in ("obstacle_range", "raytrace_range", "inflation_radius", "cost_scaling_factor",
                     "robot_radius", "planner_frequency", "xy_goal_tolerance", "yaw_goal_tolerance",
                     "max_obstacle_height", "clearance_margin"):
            _number(name, getattr(self, name), low=0.0)
        for name in ("update_frequency", "controller_frequency", "max_vel_x", "max_rotational_vel",
                     "lookahead", "map_wait_log_period", "collision_horizon", "stall_time", "sim_time",
                     "acc_lim_th", "min_in_place_rotational_vel"):
            _number(name, getattr(self, name), low=0.0, low_open=True)
        for name in ("planner_patience", "controller_patience", "oscillation_timeout", "oscillation_distance",
                     "conservative_reset_dist", "blocked_lookahead"):
            _number(name, getattr(self, name), low=0.0)
        if self.blocked_lookahead == 0.0:
            object.__setattr__(self, "blocked_lookahead", self.sim_time * self.max_vel_x)
        if (not isinstance(self.max_planning_retries, int) or isinstance(self.max_planning_retries, bool)
                or self.max_planning_retries < -1):
            raise ParameterError("parameter max_planning_retries must be an integer >= -1 (-1: no limit), got %r"
                                 % (self.max_planning_retries,))
        if self.planner_frequency > 0 and not 0.05 <= self.planner_frequency <= 50:
            raise ParameterError("parameter planner_frequency must be 0 (plan on new goals only) or "
                                 "0.05..50 Hz, got %r" % self.planner_frequency)
        if not 1 <= self.lethal_cost_threshold <= 100:
            raise ParameterError("parameter lethal_cost_threshold must be 1..100, got %r"
                                 % self.lethal_cost_threshold)
        if self.footprint and len(self.footprint) < 3:
            raise ParameterError("parameter footprint needs at least 3 points, got %r" % (self.footprint,))
        _number("robot_exclusion_margin", self.robot_exclusion_margin, low=0.0, high=50.0)
        _number("robot_timeout", self.robot_timeout, low=0.0)
        _number("robot_exclusion_trail", self.robot_exclusion_trail, low=0.0, high=10.0)

    @property
    def inscribed_radius(self):
        return inscribed_radius(self.footprint) if self.footprint else self.robot_radius

    @property
    def robot_extent(self):
        """Circumscribed radius: the farthest footprint point from the centre."""
        if self.footprint:
            return max(math.hypot(x, y) for x, y in self.footprint)
        return self.robot_radius

    @property
    def footprint_polygon(self):
        """The footprint, or a 16-gon of robot_radius when only a radius is set."""
        if self.footprint:
            return self.footprint
        return tuple((self.robot_radius * math.cos(a * math.pi / 8), self.robot_radius * math.sin(a * math.pi / 8))
                     for a in range(16))

    @classmethod
    def from_dict(cls, tree, robot_name="robot"):
        """Validated parameters from the node's private parameter tree.

        Returns (params, unused): unused is the sorted list of keys present but not read.
        """
        flat = flatten(tree)
        used = set()

        def take(keys, default):
            for key in keys:
                if key in flat:
                    used.add(key)
                    return flat[key], key
            return default, keys[0]

        def costmap(key, default):
            keys = ["global_costmap/" + key]
            if key in ("inflation_radius", "cost_scaling_factor"):
                keys.append("global_costmap/inflation_layer/" + key)
            keys.append(key)
            return take(keys, default)

        def local(key, default, aliases=()):
            keys = []
            for name in (key,) + tuple(aliases):
                keys += ["TrajectoryPlannerROS/" + name, "DWAPlannerROS/" + name]
            return take(keys + [key], default)

        values = {"robot_name": robot_name}

        def num(target, pair, low=None, integer=False):
            value, key = pair
            if integer:
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ParameterError("parameter %s must be an integer, got %r" % (key, value))
                values[target] = value
            else:
                values[target] = _number(key, value, low=low)

        def flag(target, pair):
            value, key = pair
            if not isinstance(value, bool):
                raise ParameterError("parameter %s must be true or false, got %r" % (key, value))
            values[target] = value

        def text(target, pair):
            value, key = pair
            if not isinstance(value, str) or not value.strip():
                raise ParameterError("parameter %s must be a frame name, got %r" % (key, value))
            values[target] = value.strip().lstrip("/")

        # Frames: the private ~ names win over the costmap's (the tutorials' "base_link" gets the
        # robot's tf prefix, as tf_prefix did for move_base).
        text("global_frame", take(["global_frame", "global_costmap/global_frame"], "map"))
        text("robot_base_frame", take(["robot_base_frame", "global_costmap/robot_base_frame"], "base_link"))
        if "/" not in values["robot_base_frame"] and robot_name and robot_name != "robot":
            values["robot_base_frame"] = robot_name + "/" + values["robot_base_frame"]
        num("obstacle_range", costmap("obstacle_range", 2.5))
        num("raytrace_range", costmap("raytrace_range", 3.0))
        num("min_obstacle_height", costmap("min_obstacle_height", 0.0))
        num("max_obstacle_height", costmap("max_obstacle_height", 2.0))
        num("inflation_radius", costmap("inflation_radius", 0.55))
        num("cost_scaling_factor", costmap("cost_scaling_factor", 10.0))
        num("update_frequency", costmap("update_frequency", 5.0))
        num("lethal_cost_threshold", costmap("lethal_cost_threshold", 100), integer=True)
        flag("track_unknown_space", costmap("track_unknown_space", False))
        padding_value, padding_key = costmap("footprint_padding", 0.01)
        padding = _number(padding_key, padding_value, low=0.0)
        footprint_value, footprint_key = costmap("footprint", None)
        radius_value, radius_key = costmap("robot_radius", 0.46)
        values["robot_radius"] = _number(radius_key, radius_value, low=0.0, low_open=True) + padding
        if footprint_value is not None:
            values["footprint"] = pad_footprint(parse_footprint(footprint_key, footprint_value), padding)
        for name in ("planner_frequency", "controller_frequency", "planner_patience", "controller_patience",
                     "oscillation_timeout", "oscillation_distance", "conservative_reset_dist"):
            num(name, take([name], getattr(cls, name)))
        num("max_planning_retries", take(["max_planning_retries"], -1), integer=True)
        for name in ("recovery_behavior_enabled", "clearing_rotation_allowed", "stuck_feedback_on_local_failure"):
            flag(name, take([name], getattr(cls, name)))
        for name in ("conservative_reset", "aggressive_reset"):
            layers, key = take([name + "/layer_names"], None)
            if layers is not None:
                if not isinstance(layers, (list, tuple)) or not all(isinstance(x, str) and x for x in layers):
                    raise ParameterError("parameter %s must be a list of layer names, got %r" % (key, layers))
                values[name + "_layer_names"] = tuple(layers)
        num("max_vel_x", local("max_vel_x", cls.max_vel_x))
        num("max_rotational_vel", local("max_rotational_vel", cls.max_rotational_vel, aliases=("max_rot_vel",)))
        num("min_in_place_rotational_vel", local("min_in_place_rotational_vel", cls.min_in_place_rotational_vel,
                                                 aliases=("min_in_place_vel_theta",)))
        num("acc_lim_th", local("acc_lim_th", cls.acc_lim_th, aliases=("acc_lim_theta",)))
        num("sim_time", local("sim_time", cls.sim_time))
        num("xy_goal_tolerance", local("xy_goal_tolerance", cls.xy_goal_tolerance))
        num("escape_vel", local("escape_vel", -0.1))
        if values["escape_vel"] > 0:
            raise ParameterError("parameter escape_vel must be <= 0 (a reverse speed), got %r" % values["escape_vel"])
        num("yaw_goal_tolerance", local("yaw_goal_tolerance", cls.yaw_goal_tolerance))
        for name in ("lookahead", "blocked_lookahead", "clearance_margin", "collision_horizon", "stall_time",
                     "map_wait_log_period"):
            num(name, take([name], getattr(cls, name)))
        flag("sharing_enabled", take(["sharing_enabled"], True))
        flag("plan_trigger", take(["sharing/plan_trigger", "sharing_layer/plan_trigger"], True))
        for key in ("robot_exclusion_margin", "robot_timeout", "robot_exclusion_trail"):
            num(key, take(["sharing/" + key, "sharing_layer/" + key], getattr(cls, key)))
        sharing = {}
        for key in SHARING_KEYS:
            value, _ = take(["sharing/" + key, "sharing_layer/" + key], None)
            if value is not None:
                sharing[key] = value
        values["sharing"] = sharing
        unused = sorted(k for k in flat if k not in used)
        return cls(**values), unused
