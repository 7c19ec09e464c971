#include "sharing_layer/grid_frame.h"

#include <algorithm>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
CostGrid moveObstacleGrid(const CostGrid& old, const GridGeometry& to, bool keep_observations, std::uint8_t* costs,
                          std::uint8_t default_value, std::size_t& lethal_kept)
{
  lethal_kept = 0;
  // A caller's buffer holds the moved grid already (the old one may be gone).
  CostGrid grid = costs != nullptr ? CostGrid::view(to, costs, default_value) : CostGrid(to, FREE_SPACE);
  if (!keep_observations)
  {
    return grid;
  }
  if (costs != nullptr)
  {
    lethal_kept = static_cast<std::size_t>(std::count(grid.data(), grid.data() + to.cellCount(), LETHAL_OBSTACLE));
    return grid;
  }
  const CellMover mover(old.geometry(), to);
  for (std::uint32_t index = 0; index < old.geometry().cellCount(); ++index)
  {
    std::uint32_t moved = 0;
    if (old.at(index) != FREE_SPACE && mover(index, moved))
    {
      grid.set(moved, old.at(index));
      lethal_kept += old.at(index) == LETHAL_OBSTACLE;
    }
  }
  return grid;
}

std::size_t clearGridOutside(CostGrid& grid, int x0, int y0, int x1, int y1)
{
  const GridGeometry& g = grid.geometry();
  const std::uint8_t cleared_value = grid.defaultValue();
  std::size_t cleared = 0;
  for (unsigned int my = 0; my < g.size_y; ++my)
  {
    for (unsigned int mx = 0; mx < g.size_x; ++mx)
    {
      if (insideOpenWindow(mx, my, x0, y0, x1, y1))
      {
        continue;
      }
      const std::uint32_t index = g.getIndex(mx, my);
      if (grid.at(index) != cleared_value)
      {
        cleared += grid.at(index) == LETHAL_OBSTACLE ? 1 : 0;
        grid.set(index, cleared_value);
      }
    }
  }
  return cleared;
}

ObstacleUpdate reprojectUpdate(const ObstacleUpdate& update, const GridGeometry& to, std::size_t* dropped)
{
  ObstacleUpdate out = update;
  out.geometry = to;
  out.marked.clear();
  out.cleared.clear();
  std::size_t off_grid = 0;
  const auto move = [&](const std::vector<std::uint32_t>& from, std::vector<std::uint32_t>& into) {
    into.reserve(from.size());
    for (std::uint32_t index : from)
    {
      if (!update.geometry.containsIndex(index))
      {
        throw std::invalid_argument("obstacle " + update.uuid + " from " + update.source + ": cell " +
                                    std::to_string(index) + " outside its grid " + update.geometry.describe());
      }
      unsigned int mx = 0, my = 0, tx = 0, ty = 0;
      update.geometry.indexToCells(index, mx, my);
      double wx = 0.0, wy = 0.0;
      update.geometry.mapToWorld(mx, my, wx, wy);
      if (to.worldToMap(wx, wy, tx, ty))
      {
        into.push_back(to.getIndex(tx, ty));
      }
      else
      {
        ++off_grid;
      }
    }
    std::sort(into.begin(), into.end());
    into.erase(std::unique(into.begin(), into.end()), into.end());
  };
  move(update.marked, out.marked);
  move(update.cleared, out.cleared);
  std::vector<std::uint32_t> cleared_only;
  std::set_difference(out.cleared.begin(), out.cleared.end(), out.marked.begin(), out.marked.end(),
                      std::back_inserter(cleared_only));
  out.cleared.swap(cleared_only);
  if (dropped != nullptr)
  {
    *dropped = off_grid;
  }
  return out;
}

}  // namespace sharing_layer
