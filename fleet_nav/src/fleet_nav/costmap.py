"""The global costmap of fleet_nav: static layer, sharing layer (the C++ SharingCore), inflation.

Like costmap_2d's LayeredCostmap with plugins [static_layer, sharing_layer, inflation_layer]:
``master = static``, obstacle cells marked lethal on top, shared obstacles drawn lethal, then
costmap_2d inflation. Everything per cell runs in C++ or NumPy; ``update`` re-inflates only the
window that can have changed (the scan's reach around the robot and the bounds of shared
obstacles that changed), and everything after a new map or an obstacle-layer reset.
"""
import logging
import math

import numpy as np

from sharing_layer_cpp import core
from fleet_nav import nav_core as nav

from fleet_nav.errors import GoalRejected

LOG = logging.getLogger(__name__)
LETHAL = 254
INSCRIBED = 253
UNKNOWN = 255


def static_costs(occupancy, lethal_cost_threshold=100, track_unknown_space=False):
    """costmap_2d StaticLayer::interpretValue on an OccupancyGrid's int8 data (any shape)."""
    data = np.asarray(occupancy, dtype=np.int16)
    costs = np.zeros(data.shape, dtype=np.uint8)
    costs[data >= lethal_cost_threshold] = LETHAL
    unknown = data == -1
    costs[unknown] = UNKNOWN if track_unknown_space else 0
    # costmap_2d scales values between free and lethal; fleet_nav keeps them as obstacles or free.
    return costs


class GlobalCostmap:
    """Static + sharing + inflation on one grid geometry (the map's)."""

    def __init__(self, geometry, occupancy, params, layer_params):
        self.geometry = geometry
        self.params = params
        shape = (geometry.size_y, geometry.size_x)
        occupancy = np.asarray(occupancy).reshape(shape)
        self.static = static_costs(occupancy, params.lethal_cost_threshold, params.track_unknown_space)
        self.layer = core.SharingCore(geometry, layer_params)
        self.layer.fleet_robots.set_params(margin=params.robot_exclusion_margin, timeout=params.robot_timeout,
                                           trail=params.robot_exclusion_trail)
        self.layer.set_static_map(self.static)
        self.layer.set_unknown_map(occupancy == -1)  # unknown map cells are never shared
        self.inflator = nav.Inflator(geometry.resolution, params.inscribed_radius, params.inflation_radius,
                                     params.cost_scaling_factor)
        self.master = self.static.copy()
        self.costs = self.inflator.inflate_all(self.master)
        self._full_pending = False

    @property
    def shape(self):
        return self.static.shape

    def request_full_update(self):
        self._full_pending = True

    def _compose(self):
        np.copyto(self.master, self.static)
        self.master[self.layer.obstacle_grid() == LETHAL] = LETHAL
        self.layer.draw_shared(self.master)

    def _cell_window(self, min_x, min_y, max_x, max_y):
        g = self.geometry
        x0 = max(0, int(math.floor((min_x - g.origin_x) / g.resolution)))
        y0 = max(0, int(math.floor((min_y - g.origin_y) / g.resolution)))
        x1 = min(g.size_x, int(math.ceil((max_x - g.origin_x) / g.resolution)) + 1)
        y1 = min(g.size_y, int(math.ceil((max_y - g.origin_y) / g.resolution)) + 1)
        return x0, y0, x1, y1

    def update(self, robot_x, robot_y):
        """Rebuilds the master grid and re-inflates what can have changed since the last update."""
        self._compose()
        if self._full_pending:
            self._full_pending = False
            self.layer.take_dirty_bounds()
            self.inflator.inflate(self.master, self.costs, 0, 0, self.geometry.size_x, self.geometry.size_y)
            return
        reach = max(self.params.obstacle_range, self.params.raytrace_range) + self.geometry.resolution
        windows = [(robot_x - reach, robot_y - reach, robot_x + reach, robot_y + reach)]
        dirty = self.layer.take_dirty_bounds()
        if dirty is not None:
            windows.append(dirty)
        for bounds in windows:
            x0, y0, x1, y1 = self._cell_window(*bounds)
            if x0 < x1 and y0 < y1:
                self.inflator.inflate(self.master, self.costs, x0, y0, x1, y1)

    def reset_obstacle_layer(self):
        """On reaching a goal: the obstacle layer is cleared, shared obstacles stay."""
        self.layer.reset_obstacle_layer()
        self.request_full_update()

    # costmap_2d names the obstacle layer of old-style parameter files (the tutorials') this way;
    # the sharing layer takes its place in fleet_nav's global costmap.
    OBSTACLE_LAYER_NAME = "obstacle_layer"

    def clear_obstacles_outside(self, x, y, reset_distance, layer_names):
        """move_base's ClearCostmapRecovery on the global costmap: when the obstacle layer is one of
        layer_names, its cells outside a reset_distance square centred on (x, y) are cleared (shared
        obstacles stay). Returns the number of obstacle cells cleared."""
        if self.OBSTACLE_LAYER_NAME not in layer_names:
            return 0
        g = self.geometry
        half = reset_distance / 2.0
        # worldToMapNoBounds: cells may lie off the map; the window is open on every side.
        x0 = int((x - half - g.origin_x) / g.resolution)
        y0 = int((y - half - g.origin_y) / g.resolution)
        x1 = int((x + half - g.origin_x) / g.resolution)
        y1 = int((y + half - g.origin_y) / g.resolution)
        cleared = self.layer.clear_obstacles_outside(x0, y0, x1, y1)
        self.request_full_update()
        return cleared

    def world_to_cell(self, x, y):
        return self.geometry.world_to_map(x, y)

    def cell_to_world(self, indexes):
        """World (x, y) centres of flat cell indexes, as an (N, 2) array."""
        g = self.geometry
        indexes = np.asarray(indexes, dtype=np.int64)
        xs = g.origin_x + (indexes % g.size_x + 0.5) * g.resolution
        ys = g.origin_y + (indexes // g.size_x + 0.5) * g.resolution
        return np.column_stack((xs, ys))

    def check_goal(self, x, y):
        """Raises GoalRejected with the reason when (x, y) cannot be a goal."""
        if not (math.isfinite(x) and math.isfinite(y)):
            raise GoalRejected("goal (%r, %r) is not finite" % (x, y))
        cell = self.world_to_cell(x, y)
        if cell is None:
            g = self.geometry
            raise GoalRejected("goal (%.2f, %.2f) is outside the map [%.2f..%.2f] x [%.2f..%.2f]"
                               % (x, y, g.origin_x, g.origin_x + g.size_x * g.resolution,
                                  g.origin_y, g.origin_y + g.size_y * g.resolution))
        cost = int(self.costs[cell[1], cell[0]])
        if cost == LETHAL:
            raise GoalRejected("goal (%.2f, %.2f) is inside an obstacle (cost 254)" % (x, y))
        if cost == INSCRIBED:
            raise GoalRejected("goal (%.2f, %.2f) is closer to an obstacle than the robot's inscribed radius "
                               "%.2f m (cost 253)" % (x, y, self.params.inscribed_radius))
        if cost == UNKNOWN:
            raise GoalRejected("goal (%.2f, %.2f) is in unknown space" % (x, y))

    def shared_mask(self):
        """Boolean (size_y, size_x) mask of the cells of every present shared obstacle."""
        mask = np.zeros(self.shape, dtype=bool)
        flat = mask.reshape(-1)
        for uuid in self.layer.shared_uuids():
            flat[self.layer.shared_cells(uuid)] = True
        return mask
