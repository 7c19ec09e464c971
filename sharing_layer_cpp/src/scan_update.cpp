#include "sharing_layer/scan_update.h"

#include <algorithm>
#include <cmath>
#include <limits>
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

/// Costs the grid never holds (it holds FREE_SPACE, LETHAL_OBSTACLE and NO_INFORMATION), used as flags on
/// watched cells during one scan: not touched by a beam yet, seen free with the endpoint well beyond,
/// cleared by a beam ending close behind.
constexpr std::uint8_t kTracked = 1;
constexpr std::uint8_t kFreeDeep = 2;
constexpr std::uint8_t kFreeShallow = 3;
constexpr std::uint8_t kHitBit = 4;  ///< added to a flag when an endpoint of this scan lies in the cell

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
  if (watch.free_neighbours > 10000)
  {
    throw std::invalid_argument("applyScan: free_neighbours must be <= 10000, got " +
                                std::to_string(watch.free_neighbours));
  }
  if (!std::isfinite(watch.free_margin) || watch.free_margin < 0.0)
  {
    throw std::invalid_argument("applyScan: free_margin must be finite and >= 0, got " +
                                std::to_string(watch.free_margin));
  }
  // Flag every watched cell (kTracked) and keep its cost. Beams then move flags through tables instead of
  // writing FREE_SPACE: kFreeDeep where the beam ends at least free_margin beyond the cell, kFreeShallow
  // where it ends closer. Marking overwrites a flag with LETHAL_OBSTACLE; the flags are read back after.
  std::vector<std::uint8_t> watched_before(watch.cells.size());
  for (std::size_t i = 0; i < watch.cells.size(); ++i)
  {
    std::uint8_t& cost = costs[watch.cells[i]];
    watched_before[i] = cost;
    cost = kTracked;
  }
  std::uint8_t deep_table[256];
  std::uint8_t shallow_table[256];
  for (int v = 0; v < 256; ++v)
  {
    const bool flagged = v == kTracked || v == kFreeDeep || v == kFreeShallow;
    deep_table[v] = flagged ? kFreeDeep : FREE_SPACE;
    shallow_table[v] = flagged ? (v == kFreeDeep ? kFreeDeep : kFreeShallow) : FREE_SPACE;
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
    TableAction clear_deep{ costs, deep_table };
    TableAction clear_shallow{ costs, shallow_table };
    const bool watching = !watch.cells.empty();
    // Per point: the shortest 2D range among it and its free_neighbours neighbours on each side.
    std::vector<double> shadow_range;
    if (watching)
    {
      const std::size_t n = observation.points.size();
      std::vector<double> range(n, std::numeric_limits<double>::infinity());
      for (std::size_t i = 0; i < n; ++i)
      {
        const Point3& p = observation.points[i];
        if (std::isfinite(p.x) && std::isfinite(p.y))
        {
          range[i] = std::hypot(p.x - ox, p.y - oy);
        }
      }
      shadow_range = range;
      const std::size_t k = watch.free_neighbours;
      if (k > 0)
      {
        for (std::size_t i = 0; i < n; ++i)
        {
          const std::size_t lo = i >= k ? i - k : 0;
          const std::size_t hi = std::min(n - 1, i + k);
          double m = range[i];
          for (std::size_t j = lo; j <= hi; ++j)
          {
            m = std::min(m, range[j]);
          }
          shadow_range[i] = m;
        }
      }
    }
    std::size_t point_index = 0;

    for (std::size_t pi = 0; pi < observation.points.size(); ++pi)
    {
      const Point3& p = observation.points[pi];
      point_index = pi;
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

      if (!watching)
      {
        raytraceLine(clear, x0, y0, x1, y1, g.size_x, cell_raytrace_range);
        continue;
      }
      // Cells up to free_margin before the (unclipped) endpoint are seen free; the rest of the beam
      // (the face it hit, a neighbour it grazed) only clears.
      const double deep_until = (std::min(std::hypot(a, b), shadow_range[point_index]) - watch.free_margin) /
                                g.resolution;
      raytraceLineSplit(clear_deep, clear_shallow, x0, y0, x1, y1, g.size_x, cell_raytrace_range, deep_until);
    }
  }

  // Endpoints at any range in watched cells: evidence of occupancy (costmap_2d marks only within
  // obstacle_range, so a face beyond it would otherwise look free to the beams that graze it).
  if (!watch.cells.empty())
  {
    for (const Point3& p : observation.points)
    {
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < limits.min_obstacle_height ||
          p.z > limits.max_obstacle_height)
      {
        continue;
      }
      unsigned int mx = 0, my = 0;
      if (!g.worldToMap(p.x, p.y, mx, my))
      {
        continue;
      }
      std::uint8_t& cost = costs[g.getIndex(mx, my)];
      if (cost >= kTracked && cost <= kFreeShallow)
      {
        cost = static_cast<std::uint8_t>(cost | kHitBit);
        touch.watched_hit.push_back(g.getIndex(mx, my));
      }
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

  // Read the flags back: kFreeDeep / kFreeShallow mean cleared by this scan and not marked again (a cell
  // marked again is lethal and was not seen free, as costmap_2d keeps it), and the grid gets FREE_SPACE as
  // without a watch; kTracked means untouched, and the cost is restored. Restored in reverse so a
  // duplicate's saved flag is overwritten by the first occurrence's true cost.
  for (std::uint32_t index : watch.cells)
  {
    const std::uint8_t v = costs[index];
    if (v > (kFreeShallow | kHitBit))
    {
      continue;  // marked (LETHAL_OBSTACLE) by this scan
    }
    const std::uint8_t state = static_cast<std::uint8_t>(v & ~kHitBit);
    if (state == kFreeDeep || state == kFreeShallow)
    {
      touch.watched_cleared.push_back(index);
      if (state == kFreeDeep && !(v & kHitBit))
      {
        touch.watched_free.push_back(index);
      }
    }
  }
  for (std::size_t i = watch.cells.size(); i-- > 0;)
  {
    std::uint8_t& cost = costs[watch.cells[i]];
    if (cost > (kFreeShallow | kHitBit))
    {
      continue;
    }
    const std::uint8_t state = static_cast<std::uint8_t>(cost & ~kHitBit);
    if (state == kTracked)
    {
      cost = watched_before[i];
    }
    else if (state == kFreeDeep || state == kFreeShallow)
    {
      cost = FREE_SPACE;
    }
  }
  sortUnique(touch.watched_hit);
  sortUnique(touch.watched_free);
  sortUnique(touch.watched_cleared);
  return touch;
}

}  // namespace sharing_layer
