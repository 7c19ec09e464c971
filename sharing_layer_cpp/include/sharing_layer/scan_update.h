#ifndef SHARING_LAYER_SCAN_UPDATE_H
#define SHARING_LAYER_SCAN_UPDATE_H

#include <vector>

#include "sharing_layer/cost_grid.h"
#include "sharing_layer/observation.h"

namespace sharing_layer
{
/**
 * @brief Which cells a scan should report when it clears them: the cells of the monitored rectangles.
 *
 * The mask says per cell whether it is watched; the rectangles let the scan skip, with one angle test,
 * every beam that cannot reach a watched cell, so beams elsewhere pay nothing for monitoring.
 */
struct ScanWatch
{
  const std::uint16_t* mask = nullptr;  ///< non-zero for watched cells, one entry per grid cell
  std::vector<CellRect> rects;          ///< the watched rectangles (cells), covering every watched cell

  /// @brief A watch over the given rectangles, owning its mask.
  static ScanWatch fromRects(const GridGeometry& geometry, const std::vector<CellRect>& rects);

  bool empty() const { return mask == nullptr || rects.empty(); }

private:
  std::vector<std::uint16_t> owned_mask_;
};

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
 * Beams aimed at a watched rectangle also record the watched cells they clear, so a caller can tell
 * which known cells this scan saw free; other beams pay nothing for it.
 *
 * @throws std::invalid_argument when the limits are invalid (grid left untouched)
 */
ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const ScanWatch& watch = ScanWatch());

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SCAN_UPDATE_H
