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

/// Liang-Barsky test of the segment (x0,y0)-(x1,y1), in cell units, against a rectangle grown by one cell,
/// so a Bresenham line that grazes the rectangle is never missed.
bool segmentNearRect(double x0, double y0, double x1, double y1, const CellRect& r)
{
  double t0 = 0.0, t1 = 1.0;
  const double dx = x1 - x0, dy = y1 - y0;
  const double p[4] = { -dx, dx, -dy, dy };
  const double q[4] = { x0 - (r.min_x - 1.0), (r.max_x + 2.0) - x0, y0 - (r.min_y - 1.0), (r.max_y + 2.0) - y0 };
  for (int i = 0; i < 4; ++i)
  {
    if (p[i] == 0.0)
    {
      if (q[i] < 0.0)
      {
        return false;
      }
      continue;
    }
    const double t = q[i] / p[i];
    if (p[i] < 0.0)
    {
      t0 = std::max(t0, t);
    }
    else
    {
      t1 = std::min(t1, t);
    }
    if (t0 > t1)
    {
      return false;
    }
  }
  return true;
}

void sortUnique(std::vector<std::uint32_t>& cells)
{
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
}
}  // namespace

ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const std::vector<CellRect>& watched)
{
  limits.validate();
  const GridGeometry& g = grid.geometry();
  std::uint8_t* costs = grid.data();
  ScanTouch touch;

  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  unsigned int x0 = 0, y0 = 0;
  touch.origin_in_map = std::isfinite(observation.origin.z) && g.worldToMap(ox, oy, x0, y0);

  std::vector<std::uint32_t> watched_visits;
  if (touch.origin_in_map)
  {
    const double map_end_x = g.endX();
    const double map_end_y = g.endY();
    const unsigned int cell_raytrace_range = g.cellDistance(limits.raytrace_range);
    SetCellAction clear{ costs, FREE_SPACE };
    SetAndCollectAction<std::vector<std::uint32_t>> clear_and_collect{ costs, FREE_SPACE, &watched_visits };
    const double origin_cx = (ox - g.origin_x) / g.resolution;
    const double origin_cy = (oy - g.origin_y) / g.resolution;

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

      bool crosses_watch = false;
      if (!watched.empty())
      {
        // Only the part of the beam within raytrace_range is cleared.
        double ex = (wx - g.origin_x) / g.resolution;
        double ey = (wy - g.origin_y) / g.resolution;
        const double len = std::hypot(ex - origin_cx, ey - origin_cy);
        if (len > cell_raytrace_range + 1.0)
        {
          const double s = (cell_raytrace_range + 1.0) / len;
          ex = origin_cx + (ex - origin_cx) * s;
          ey = origin_cy + (ey - origin_cy) * s;
        }
        for (const CellRect& r : watched)
        {
          if (segmentNearRect(origin_cx, origin_cy, ex, ey, r))
          {
            crosses_watch = true;
            break;
          }
        }
      }
      if (crosses_watch)
      {
        raytraceLine(clear_and_collect, x0, y0, x1, y1, g.size_x, cell_raytrace_range);
      }
      else
      {
        raytraceLine(clear, x0, y0, x1, y1, g.size_x, cell_raytrace_range);
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

  if (!watched_visits.empty())
  {
    sortUnique(watched_visits);
    touch.watched_cleared.reserve(watched_visits.size());
    for (std::uint32_t index : watched_visits)
    {
      if (costs[index] == LETHAL_OBSTACLE)
      {
        continue;  // marked again after clearing in this scan: costmap_2d keeps it
      }
      unsigned int mx = 0, my = 0;
      g.indexToCells(index, mx, my);
      for (const CellRect& r : watched)
      {
        if (r.contains(static_cast<int>(mx), static_cast<int>(my)))
        {
          touch.watched_cleared.push_back(index);
          break;
        }
      }
    }
  }
  return touch;
}

}  // namespace sharing_layer
