#include "sharing_layer/scan_update.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/raytrace.h"

namespace sharing_layer
{
void ScanLimits::validate() const
{
  const auto check_range = [](double value, const char* name) {
    if (!std::isfinite(value) || value < 0.0)
    {
      throw std::invalid_argument(std::string("ScanLimits: ") + name + " must be finite and >= 0, got " +
                                  std::to_string(value));
    }
  };
  check_range(obstacle_range, "obstacle_range");
  check_range(raytrace_range, "raytrace_range");
  if (std::isnan(min_obstacle_height) || std::isnan(max_obstacle_height) || min_obstacle_height > max_obstacle_height)
  {
    throw std::invalid_argument("ScanLimits: need min_obstacle_height <= max_obstacle_height, got " +
                                std::to_string(min_obstacle_height) + " > " + std::to_string(max_obstacle_height));
  }
}

namespace
{
bool usable(const Point3& p, const ScanLimits& limits, ScanTouch& touch)
{
  if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
  {
    ++touch.rejected_points;
    return false;
  }
  if (p.z < limits.min_obstacle_height || p.z > limits.max_obstacle_height)
  {
    ++touch.height_filtered;
    return false;
  }
  return true;
}

/// A cost the grid never holds (it holds FREE_SPACE, LETHAL_OBSTACLE and NO_INFORMATION): a watched
/// cell flagged with it and found FREE_SPACE after the scan was cleared by this scan.
constexpr std::uint8_t kWatchedFlag = 1;

void sortUnique(std::vector<std::uint32_t>& cells)
{
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
}
}  // namespace

ScanWatch ScanWatch::fromRects(const GridGeometry& geometry, const std::vector<CellRect>& rects)
{
  ScanWatch watch;
  for (const CellRect& r : rects)
  {
    for (int y = std::max(0, r.min_y); y <= std::min(r.max_y, static_cast<int>(geometry.size_y) - 1); ++y)
    {
      for (int x = std::max(0, r.min_x); x <= std::min(r.max_x, static_cast<int>(geometry.size_x) - 1); ++x)
      {
        watch.cells.push_back(geometry.getIndex(x, y));
      }
    }
  }
  return watch;
}

ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const ScanWatch& watch)
{
  limits.validate();
  const GridGeometry& g = grid.geometry();
  std::uint8_t* costs = grid.data();
  ScanTouch touch;
  const std::size_t cell_count = g.cellCount();
  for (std::uint32_t index : watch.cells)
  {
    if (index >= cell_count)
    {
      throw std::invalid_argument("applyScan: watched cell " + std::to_string(index) + " outside " + g.describe());
    }
  }
  // Flag the watched cells that are not lethal; lethal ones need no flag, as FREE_SPACE after the scan
  // can only come from this scan's clearing.
  std::vector<std::uint8_t> watched_before(watch.cells.size());
  for (std::size_t i = 0; i < watch.cells.size(); ++i)
  {
    std::uint8_t& cost = costs[watch.cells[i]];
    watched_before[i] = cost;
    if (cost != LETHAL_OBSTACLE)
    {
      cost = kWatchedFlag;
    }
  }

  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  unsigned int x0 = 0, y0 = 0;
  touch.origin_in_map = std::isfinite(observation.origin.z) && g.worldToMap(ox, oy, x0, y0);

  if (touch.origin_in_map)
  {
    const double map_end_x = g.endX();
    const double map_end_y = g.endY();
    const unsigned int cell_raytrace_range = g.cellDistance(limits.raytrace_range);
    SetCellAction clear{ costs, FREE_SPACE };

    for (const Point3& p : observation.points)
    {
      if (!usable(p, limits, touch))
      {
        continue;
      }
      double wx = p.x;
      double wy = p.y;
      const double a = wx - ox;
      const double b = wy - oy;
      // Clip the endpoint to the grid as costmap_2d does, so beams leaving the map still clear inside it.
      if (wx < g.origin_x)
      {
        const double t = (g.origin_x - ox) / a;
        wx = g.origin_x;
        wy = oy + b * t;
      }
      if (wy < g.origin_y)
      {
        const double t = (g.origin_y - oy) / b;
        wx = ox + a * t;
        wy = g.origin_y;
      }
      if (wx > map_end_x)
      {
        const double t = (map_end_x - ox) / a;
        wx = map_end_x - .001;
        wy = oy + b * t;
      }
      if (wy > map_end_y)
      {
        const double t = (map_end_y - oy) / b;
        wx = ox + a * t;
        wy = map_end_y - .001;
      }
      unsigned int x1 = 0, y1 = 0;
      if (!g.worldToMap(wx, wy, x1, y1))
      {
        continue;
      }

      raytraceLine(clear, x0, y0, x1, y1, g.size_x, cell_raytrace_range);
    }
  }

  const double sq_obstacle_range = limits.obstacle_range * limits.obstacle_range;
  const double oz = observation.origin.z;
  for (const Point3& p : observation.points)
  {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < limits.min_obstacle_height ||
        p.z > limits.max_obstacle_height)
    {
      continue;  // counted in the clearing pass, or below when it did not run
    }
    const double sq_dist = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + (p.z - oz) * (p.z - oz);
    if (sq_dist >= sq_obstacle_range)
    {
      continue;
    }
    unsigned int mx = 0, my = 0;
    if (!g.worldToMap(p.x, p.y, mx, my))
    {
      continue;
    }
    const std::uint32_t index = g.getIndex(mx, my);
    costs[index] = LETHAL_OBSTACLE;
    touch.marked.push_back(index);
  }
  if (!touch.origin_in_map)
  {
    for (const Point3& p : observation.points)
    {
      usable(p, limits, touch);
    }
  }
  sortUnique(touch.marked);

  // Read the flags back: FREE_SPACE means cleared by this scan (a cell marked again is lethal and was not
  // seen free, as costmap_2d keeps it). Restored in reverse so a duplicate's saved flag is overwritten by
  // the first occurrence's true cost.
  for (std::uint32_t index : watch.cells)
  {
    if (costs[index] == FREE_SPACE)
    {
      touch.watched_cleared.push_back(index);
    }
  }
  for (std::size_t i = watch.cells.size(); i-- > 0;)
  {
    if (costs[watch.cells[i]] == kWatchedFlag)
    {
      costs[watch.cells[i]] = watched_before[i];
    }
  }
  sortUnique(touch.watched_cleared);
  return touch;
}

}  // namespace sharing_layer
