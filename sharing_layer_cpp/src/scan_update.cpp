#include "sharing_layer/scan_update.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <utility>
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

/// A number in [0, 4) that grows with the direction's angle like atan2 does, without trigonometry.
inline double pseudoAngle(double dx, double dy)
{
  const double p = dx / (std::fabs(dx) + std::fabs(dy));  // in [-1, 1]
  return dy < 0.0 ? 3.0 + p : 1.0 - p;
}
constexpr double kTurn = 4.0;  // a full turn in pseudo-angle units

/// The watched rectangles each beam may cross, found by the beam's direction.
class AimedRectangles
{
public:
  AimedRectangles(const std::vector<CellRect>& rects, double origin_cx, double origin_cy)
  {
    for (std::size_t id = 0; id < rects.size(); ++id)
    {
      const CellRect& r = rects[id];
      // Grown by one cell, so a Bresenham line that grazes the rectangle is never missed.
      const double x0 = r.min_x - 1.0, y0 = r.min_y - 1.0, x1 = r.max_x + 2.0, y1 = r.max_y + 2.0;
      if (origin_cx >= x0 && origin_cx <= x1 && origin_cy >= y0 && origin_cy <= y1)
      {
        always_.push_back(id);
        continue;
      }
      // The rectangle spans less than half a turn; measure its corners relative to its centre's direction.
      const double centre = pseudoAngle((x0 + x1) / 2 - origin_cx, (y0 + y1) / 2 - origin_cy);
      double lo = 0.0, hi = 0.0;
      const double xs[2] = { x0, x1 }, ys[2] = { y0, y1 };
      for (double x : xs)
      {
        for (double y : ys)
        {
          double delta = pseudoAngle(x - origin_cx, y - origin_cy) - centre;
          delta -= kTurn * std::round(delta / kTurn);
          lo = std::min(lo, delta);
          hi = std::max(hi, delta);
        }
      }
      add(centre + lo, centre + hi, id);
    }
    std::sort(intervals_.begin(), intervals_.end(),
              [](const Interval& a, const Interval& b) { return a.lo < b.lo; });
  }

  bool empty() const { return intervals_.empty() && always_.empty(); }

  /// Appends the ids of the rectangles a beam with this pseudo-angle may cross.
  void candidates(double angle, std::vector<std::size_t>& ids) const
  {
    ids.assign(always_.begin(), always_.end());
    auto it = std::upper_bound(intervals_.begin(), intervals_.end(), angle,
                               [](double a, const Interval& iv) { return a < iv.lo; });
    while (it != intervals_.begin())
    {
      --it;
      if (it->lo < angle - max_width_)
      {
        break;
      }
      if (angle <= it->hi)
      {
        ids.push_back(it->id);
      }
    }
  }

private:
  struct Interval
  {
    double lo, hi;
    std::size_t id;
  };

  void add(double lo, double hi, std::size_t id)
  {
    // Keep intervals within [0, 4), splitting those that wrap around.
    if (lo < 0.0)
    {
      push(lo + kTurn, kTurn, id);
      push(0.0, hi, id);
    }
    else if (hi > kTurn)
    {
      push(lo, kTurn, id);
      push(0.0, hi - kTurn, id);
    }
    else
    {
      push(lo, hi, id);
    }
  }

  void push(double lo, double hi, std::size_t id)
  {
    intervals_.push_back(Interval{ lo, hi, id });
    max_width_ = std::max(max_width_, hi - lo);
  }

  std::vector<Interval> intervals_;
  std::vector<std::size_t> always_;
  double max_width_ = 0.0;
};

/// Clears every cell, and records those visited at the given step ranges along the line's dominant axis,
/// where the line may be inside a watched rectangle: a register compare per cell, no memory access.
struct ClearAndRecordAction
{
  using Range = std::pair<long, long>;
  std::uint8_t* costs;
  const std::vector<Range>* ranges;  ///< sorted, disjoint, inclusive
  std::vector<std::uint32_t>* recorded;
  std::size_t current = 0;
  long step = 0;
  inline void operator()(std::uint32_t offset)
  {
    costs[offset] = FREE_SPACE;
    while (current < ranges->size() && step > (*ranges)[current].second)
    {
      ++current;
    }
    if (current < ranges->size() && step >= (*ranges)[current].first)
    {
      recorded->push_back(offset);
    }
    ++step;
  }
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
  watch.owned_mask_.assign(geometry.cellCount(), 0);
  for (const CellRect& r : rects)
  {
    for (int y = std::max(0, r.min_y); y <= std::min(r.max_y, static_cast<int>(geometry.size_y) - 1); ++y)
    {
      for (int x = std::max(0, r.min_x); x <= std::min(r.max_x, static_cast<int>(geometry.size_x) - 1); ++x)
      {
        watch.owned_mask_[geometry.getIndex(x, y)] = 1;
      }
    }
  }
  watch.mask = watch.owned_mask_.data();
  watch.rects = rects;
  return watch;
}

ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const ScanWatch& watch)
{
  limits.validate();
  const GridGeometry& g = grid.geometry();
  std::uint8_t* costs = grid.data();
  ScanTouch touch;

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
    const bool watching = !watch.empty();
    const AimedRectangles aimed(watching ? watch.rects : std::vector<CellRect>(), (ox - g.origin_x) / g.resolution,
                                (oy - g.origin_y) / g.resolution);
    std::vector<std::size_t> candidates;
    std::vector<ClearAndRecordAction::Range> ranges;

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

      ranges.clear();  // steps to record; none unless the beam is aimed at a watched rectangle
      if (watching)
      {
        aimed.candidates(pseudoAngle(wx - ox, wy - oy), candidates);
        // Steps along the dominant axis at which the line is within a candidate rectangle's extent.
        const long dx = static_cast<long>(x1) - static_cast<long>(x0);
        const long dy = static_cast<long>(y1) - static_cast<long>(y0);
        const bool x_dominant = std::labs(dx) >= std::labs(dy);
        const long a0 = x_dominant ? x0 : y0;
        const long direction = (x_dominant ? dx : dy) >= 0 ? 1 : -1;
        for (std::size_t id : candidates)
        {
          const CellRect& r = watch.rects[id];
          const long lo = (x_dominant ? r.min_x : r.min_y) - 1;
          const long hi = (x_dominant ? r.max_x : r.max_y) + 1;
          long k0 = (lo - a0) * direction, k1 = (hi - a0) * direction;
          if (k0 > k1)
          {
            std::swap(k0, k1);
          }
          k0 = std::max(k0, 0L);
          if (k0 > k1)
          {
            continue;
          }
          ranges.emplace_back(k0, k1);
        }
        if (ranges.size() > 1)
        {
          std::sort(ranges.begin(), ranges.end());
          std::size_t kept = 0;
          for (std::size_t i = 1; i < ranges.size(); ++i)
          {
            if (ranges[i].first <= ranges[kept].second + 1)
            {
              ranges[kept].second = std::max(ranges[kept].second, ranges[i].second);
            }
            else
            {
              ranges[++kept] = ranges[i];
            }
          }
          ranges.resize(kept + 1);
        }
      }
      if (!ranges.empty())
      {
        ClearAndRecordAction clear_and_record{ costs, &ranges, &touch.watched_cleared };
        raytraceLine(clear_and_record, x0, y0, x1, y1, g.size_x, cell_raytrace_range);
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

  if (!touch.watched_cleared.empty())
  {
    sortUnique(touch.watched_cleared);
    // Keep watched cells only; one marked again after clearing in this scan was not seen free (costmap_2d
    // keeps it lethal).
    const std::uint16_t* mask = watch.mask;
    touch.watched_cleared.erase(std::remove_if(touch.watched_cleared.begin(), touch.watched_cleared.end(),
                                               [costs, mask](std::uint32_t index) {
                                                 return mask[index] == 0 || costs[index] == LETHAL_OBSTACLE;
                                               }),
                                touch.watched_cleared.end());
  }
  return touch;
}

}  // namespace sharing_layer
