#include "sharing_layer/scan_update.h"

#include <algorithm>
#include <cmath>
#include <iterator>
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

/// A monotonic stand-in for atan2(y, x) in [0, 4) (the "diamond angle"): one division instead of atan2.
inline double pseudoAngle(double x, double y)
{
  if (y >= 0.0)
  {
    return x >= 0.0 ? (x + y == 0.0 ? 0.0 : y / (x + y)) : 1.0 - x / (-x + y);
  }
  return x < 0.0 ? 2.0 - y / (-x - y) : 3.0 + x / (x - y);
}

/// Directions (pseudo-angle intervals, seen from the origin cell) in which beams can cross a watched cell, with
/// the band of distances (in cells) where those cells lie.
class WatchedDirections
{
public:
  struct Interval
  {
    double lo, hi;      ///< pseudo-angles
    double near, far;   ///< distances from the origin cell's centre, cells
  };

  WatchedDirections(const GridGeometry& g, const ScanWatch& watch, unsigned int x0, unsigned int y0)
  {
    if (watch.cells.empty())
    {
      return;
    }
    if (!watch.regions.empty())
    {
      for (const CellRect& r : watch.regions)
      {
        add(r.min_x, r.min_y, r.max_x, r.max_y, x0, y0);
      }
    }
    else
    {
      for (std::uint32_t index : watch.cells)
      {
        unsigned int cx = 0, cy = 0;
        g.indexToCells(index, cx, cy);
        add(static_cast<int>(cx), static_cast<int>(cy), static_cast<int>(cx), static_cast<int>(cy), x0, y0);
      }
    }
  }

  /// @brief Adds the directions and distances of the cells [min_x, max_x] x [min_y, max_y].
  void add(int min_x, int min_y, int max_x, int max_y, unsigned int x0, unsigned int y0)
  {
    if (max_x < min_x || max_y < min_y)
    {
      return;
    }
    // A Bresenham line strays up to half a cell from the exact line between cell centres: grow by that and a
    // margin, on top of the half cell from a centre to the cell's edge.
    constexpr double kGrow = 0.5 + 0.6;
    const double x_lo = min_x - static_cast<double>(x0) - kGrow, x_hi = max_x - static_cast<double>(x0) + kGrow;
    const double y_lo = min_y - static_cast<double>(y0) - kGrow, y_hi = max_y - static_cast<double>(y0) + kGrow;
    // Distances of the cell centres from the origin cell's centre, with room for the line's rounding.
    const double nx = std::max(0.0, std::max(x_lo + kGrow, -(x_hi - kGrow)));
    const double ny = std::max(0.0, std::max(y_lo + kGrow, -(y_hi - kGrow)));
    const double fx = std::max(std::fabs(x_lo + kGrow), std::fabs(x_hi - kGrow));
    const double fy = std::max(std::fabs(y_lo + kGrow), std::fabs(y_hi - kGrow));
    const double near = std::sqrt(nx * nx + ny * ny) - 2.0, far = std::sqrt(fx * fx + fy * fy) + 2.0;
    if (x_lo <= 0.5 && x_hi >= -0.5 && y_lo <= 0.5 && y_hi >= -0.5)
    {
      push(Interval{ 0.0, 4.0, near, far });  // around the origin: every direction
      return;
    }
    const double corners[4][2] = { { x_lo, y_lo }, { x_hi, y_lo }, { x_lo, y_hi }, { x_hi, y_hi } };
    double a[4];
    double lo = 4.0, hi = 0.0;
    for (int i = 0; i < 4; ++i)
    {
      a[i] = pseudoAngle(corners[i][0], corners[i][1]);
      lo = std::min(lo, a[i]);
      hi = std::max(hi, a[i]);
    }
    if (hi - lo > 2.0)  // straddles the +x axis (0 / 4): two intervals
    {
      double below = 0.0, above = 4.0;
      for (double v : a)
      {
        if (v < 2.0)
        {
          below = std::max(below, v);
        }
        else
        {
          above = std::min(above, v);
        }
      }
      push(Interval{ 0.0, below, near, far });
      push(Interval{ above, 4.0, near, far });
    }
    else
    {
      push(Interval{ lo, hi, near, far });
    }
  }

  /// @return whether a beam towards cell offset (dx, dy) from the origin cell can cross a watched cell, and if
  /// so the band of distances (cells) where they lie
  bool crosses(int dx, int dy, double& near, double& far) const
  {
    if (buckets_.empty())
    {
      return false;
    }
    const Band& b = buckets_[bucketOf(pseudoAngle(dx, dy))];
    if (b.far < 0.0)
    {
      return false;
    }
    near = b.near;
    far = b.far;
    return true;
  }

private:
  /// Pseudo-angle buckets (about 0.18 degrees each), each with the band of distances of the watched cells
  /// whose directions overlap it; far < 0: none.
  struct Band
  {
    double near, far;
  };
  static constexpr int kBuckets = 2048;
  static int bucketOf(double angle)
  {
    return std::min(kBuckets - 1, std::max(0, static_cast<int>(angle * (kBuckets / 4.0))));
  }
  void push(const Interval& iv)
  {
    if (buckets_.empty())
    {
      buckets_.assign(kBuckets, Band{ 0.0, -1.0 });
    }
    for (int i = bucketOf(iv.lo), end = bucketOf(iv.hi); i <= end; ++i)
    {
      Band& b = buckets_[i];
      if (b.far < 0.0)
      {
        b = Band{ iv.near, iv.far };
      }
      else
      {
        b.near = std::min(b.near, iv.near);
        b.far = std::max(b.far, iv.far);
      }
    }
  }
  std::vector<Band> buckets_;
};

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
    const WatchedDirections directions(g, watch, x0, y0);
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

      double watch_from = 0.0, watch_until = 0.0;
      if (!watching || !directions.crosses(static_cast<int>(x1) - static_cast<int>(x0),
                                           static_cast<int>(y1) - static_cast<int>(y0), watch_from, watch_until))
      {
        raytraceLine(clear, x0, y0, x1, y1, g.size_x, cell_raytrace_range);
        continue;
      }
      // Cells up to free_margin before the (unclipped) endpoint are seen free; the rest of the beam
      // (the face it hit, a neighbour it grazed) only clears.
      // Shadow filter: the shortest range among this point and its free_neighbours neighbours on each side
      // (computed only for the few beams that can cross a watched cell).
      double shadow_sq = a * a + b * b;
      {
        const std::size_t n = observation.points.size();
        const std::size_t k = watch.free_neighbours;
        const std::size_t lo = point_index >= k ? point_index - k : 0;
        const std::size_t hi = std::min(n - 1, point_index + k);
        for (std::size_t j = lo; j <= hi; ++j)
        {
          const Point3& q = observation.points[j];
          const double r_sq = (q.x - ox) * (q.x - ox) + (q.y - oy) * (q.y - oy);
          if (std::isfinite(r_sq))
          {
            shadow_sq = std::min(shadow_sq, r_sq);
          }
        }
      }
      const double deep_until = (std::sqrt(shadow_sq) - watch.free_margin) / g.resolution;
      raytraceLineSplit(clear_deep, clear_shallow, clear, x0, y0, x1, y1, g.size_x, cell_raytrace_range, watch_from,
                        deep_until, watch_until);
    }
  }

  // Marking; while watching, endpoints at any range in watched cells are also recorded as evidence of
  // occupancy (costmap_2d marks only within obstacle_range, so a face beyond it would otherwise look free to
  // the beams that graze it).
  const double sq_obstacle_range = limits.obstacle_range * limits.obstacle_range;
  const double oz = observation.origin.z;
  const bool watching = !watch.cells.empty();
  // Endpoints farther than the farthest watched cell (plus a cell) cannot lie in one.
  double sq_hit_range = -1.0;
  const auto farther = [&](unsigned int cx, unsigned int cy) {
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(cx, cy, wx, wy);
    sq_hit_range = std::max(sq_hit_range, (wx - ox) * (wx - ox) + (wy - oy) * (wy - oy));
  };
  if (!watch.regions.empty())
  {
    for (const CellRect& r : watch.regions)  // the farthest corner of each
    {
      if (!r.empty())
      {
        for (int cx : { r.min_x, r.max_x })
        {
          for (int cy : { r.min_y, r.max_y })
          {
            farther(static_cast<unsigned int>(std::max(0, cx)), static_cast<unsigned int>(std::max(0, cy)));
          }
        }
      }
    }
  }
  else
  {
    for (std::uint32_t index : watch.cells)
    {
      unsigned int cx = 0, cy = 0;
      g.indexToCells(index, cx, cy);
      farther(cx, cy);
    }
  }
  if (sq_hit_range >= 0.0)
  {
    const double r = std::sqrt(sq_hit_range) + 1.5 * g.resolution;
    sq_hit_range = r * r;
  }
  for (const Point3& p : observation.points)
  {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < limits.min_obstacle_height ||
        p.z > limits.max_obstacle_height)
    {
      continue;  // counted in the clearing pass, or below when it did not run
    }
    const double sq_dist = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + (p.z - oz) * (p.z - oz);
    const bool in_range = sq_dist < sq_obstacle_range;
    const double sq_planar = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy);
    if (!in_range && !(watching && sq_planar <= sq_hit_range))
    {
      continue;
    }
    unsigned int mx = 0, my = 0;
    if (!g.worldToMap(p.x, p.y, mx, my))
    {
      continue;
    }
    const std::uint32_t index = g.getIndex(mx, my);
    if (watching && costs[index] >= kTracked && costs[index] <= kFreeShallow)
    {
      costs[index] = static_cast<std::uint8_t>(costs[index] | kHitBit);
      touch.watched_hit.push_back(index);
    }
    if (in_range)
    {
      costs[index] = LETHAL_OBSTACLE;
      touch.marked.push_back(index);
    }
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
