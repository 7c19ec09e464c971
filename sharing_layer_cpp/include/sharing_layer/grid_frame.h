#ifndef SHARING_LAYER_GRID_FRAME_H
#define SHARING_LAYER_GRID_FRAME_H

#include <cstddef>
#include <cstdint>

#include "sharing_layer/cost_grid.h"
#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/shared_obstacle.h"

namespace sharing_layer
{
/// @brief What moving the layer onto another grid (SharingCore::moveTo) kept and dropped.
struct MoveReport
{
  std::size_t shared_cells_dropped = 0;    ///< present shared cells whose centre lies off the new grid
  std::size_t obstacles_out_of_grid = 0;   ///< shared obstacles left with no present cell on it (still held)
  std::size_t obstacle_cells_kept = 0;     ///< lethal cells of the own obstacle grid carried over
};

/// @brief Where a cell of one grid lies on another: the cell holding its centre (false: off the other grid).
/// Every part of the layer moves its cells with it, so that all of them agree on where a cell went.
class CellMover
{
public:
  CellMover(const GridGeometry& from, const GridGeometry& to) : from_(from), to_(to) {}
  bool operator()(std::uint32_t index, std::uint32_t& moved) const
  {
    unsigned int mx = 0, my = 0;
    from_.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    from_.mapToWorld(mx, my, wx, wy);
    unsigned int nx = 0, ny = 0;
    if (!to_.worldToMap(wx, wy, nx, ny))
    {
      return false;
    }
    moved = to_.getIndex(nx, ny);
    return true;
  }

private:
  GridGeometry from_;
  GridGeometry to_;
};

/**
 * @brief The obstacle grid on the new grid: a caller's buffer (costs not null, already resized or moved by the
 * caller, as Costmap2D::resizeMap and updateOrigin do) taken as it is, or a grid of the core's own, empty
 * (costmap_2d's resize) or holding the old grid's cells by world position (keep_observations: a rolling window).
 * Allocated before anything changes, so that a std::bad_alloc leaves the layer as it was.
 * @param lethal_kept lethal cells carried over (when keep_observations)
 */
CostGrid moveObstacleGrid(const CostGrid& old, const GridGeometry& to, bool keep_observations, std::uint8_t* costs,
                          std::uint8_t default_value, std::size_t& lethal_kept);

/**
 * @brief What move_base's ClearCostmapRecovery does to a layer (CostmapLayer::clearArea with invert_area false):
 * every cell outside the open window (x0, x1) x (y0, y1) goes back to the grid's default value.
 * @return the number of cells that held an obstacle and were cleared
 */
std::size_t clearGridOutside(CostGrid& grid, int x0, int y0, int x1, int y1);

/// @brief Whether cell (mx, my) lies inside clearGridOutside's open window.
inline bool insideOpenWindow(unsigned int mx, unsigned int my, int x0, int y0, int x1, int y1)
{
  return static_cast<long>(mx) > x0 && static_cast<long>(mx) < x1 && static_cast<long>(my) > y0 &&
         static_cast<long>(my) < y1;
}

/**
 * @brief The same update on another grid, for a layer whose grid is not the sender's (a rolling window, a map of
 * another size or origin): each cell goes to the cell of `to` holding its centre, a marked cell winning over a
 * cleared one that lands on the same cell; cells off `to` are dropped and counted in `dropped`. Everything else
 * (uuid, rectangle in world coordinates, version, deadline, source, stamp) is kept.
 * @throws std::invalid_argument naming the obstacle when an index lies outside the update's own grid
 */
ObstacleUpdate reprojectUpdate(const ObstacleUpdate& update, const GridGeometry& to, std::size_t* dropped = nullptr);

}  // namespace sharing_layer

#endif  // SHARING_LAYER_GRID_FRAME_H
