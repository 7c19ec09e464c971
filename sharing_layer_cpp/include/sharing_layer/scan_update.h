#ifndef SHARING_LAYER_SCAN_UPDATE_H
#define SHARING_LAYER_SCAN_UPDATE_H

#include <vector>

#include "sharing_layer/cost_grid.h"
#include "sharing_layer/observation.h"

namespace sharing_layer
{
/**
 * @brief Clears and then marks one observation in a grid, with costmap_2d ObstacleLayer's rules.
 *
 * Clearing (raytraceFreespace): skipped entirely when the origin is off the grid; each
 * endpoint is first clipped to the grid edge, then the Bresenham line from the origin is
 * set to FREE_SPACE for at most raytrace_range (the endpoint cell included).
 * Marking: endpoints closer than obstacle_range (3D distance to the origin) and inside the
 * grid are set to LETHAL_OBSTACLE. Points outside the height limits or not finite are ignored
 * for both.
 *
 * Rays that cross one of the watched rectangles also record the cells they clear there, so a
 * caller can tell which known cells this scan saw free; other rays pay nothing for it.
 *
 * @throws std::invalid_argument when the limits are invalid (grid left untouched)
 */
ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const std::vector<CellRect>& watched = {});

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SCAN_UPDATE_H
