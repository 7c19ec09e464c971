#include "sharing_layer/scan_update.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <memory>
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

/// Per-cell scratch flags of one scan (ScanWatch::scratch).
constexpr std::uint8_t kWatched = 1;
constexpr std::uint8_t kVisitedDeep = 2;     ///< a beam passed with its endpoint at least free_margin beyond
constexpr std::uint8_t kVisitedShallow = 4;  ///< a beam passed with its endpoint closer
constexpr std::uint8_t kHit = 8;             ///< an endpoint of this scan lies in the cell

/// A monotonic stand-in for atan2(y, x) in [0, 4) (the "diamond angle"): one division instead of atan2.
inline double pseudoAngle(double x, double y)
{
  if (y >= 0.0)
  {
    return x >= 0.0 ? (x + y == 0.0 ? 0.0 : y / (x + y)) : 1.0 - x / (-x + y);
  }
  return x < 0.0 ? 2.0 - y / (-x - y) : 3.0 + x / (x - y);
}

/// The scan's beams as raytraced (endpoint cells after clipping), found by direction from the origin cell so that
/// the beams able to cross a watched region are found without walking every beam. Raytracing only records each
/// beam's end cell. Directions are computed when the first region is walked; the first few regions test every
/// beam's direction (a scan watching one obstacle pays no index), later ones use buckets sorted once. A beam's
/// line is computed when a region first reaches it.
class BeamIndex
{
public:
  struct Beam
  {
    LineSteps line;
    std::size_t point;         ///< index in the observation
    unsigned int deep_steps;   ///< steps before which a watched cell counts as seen free (kUnset until needed)
  };
  static constexpr unsigned int kUnset = UINT_MAX;
  static constexpr int kBuckets = 2048;      ///< about 0.18 degrees each
  static constexpr int kLinearQueries = 4;  ///< regions answered by testing every beam before buckets pay off

  BeamIndex(std::size_t capacity, unsigned int x0, unsigned int y0, unsigned int max_length)
    : x0_(x0), y0_(y0), max_length_(max_length)
  {
    ends_.reserve(capacity);
  }

  void add(std::size_t point, unsigned int x1, unsigned int y1)
  {
    ends_.push_back(End{ x1, y1, static_cast<std::uint32_t>(point) });
  }

  /// Calls f(beam) for every beam whose direction can cross a cell of [min_x, max_x] x [min_y, max_y]: its
  /// pseudo-angle lies within that of the rectangle's corners grown by the slack of a Bresenham line. No add
  /// after the first call.
  template <class F>
  void forEachTowards(int min_x, int min_y, int max_x, int max_y, F f)
  {
    if (angles_.empty())
    {
      prepare();
    }
    // A beam visits a cell only where the exact line between the start and end cells' centres passes within
    // half a cell of the cell's centre along b (Bresenham rounds b to the nearest cell), so only through the
    // cell's own square: its corners bound the directions, with a margin for rounding.
    constexpr double kGrow = 0.5 + 0.05;
    const double x_lo = min_x - static_cast<double>(x0_) - kGrow, x_hi = max_x - static_cast<double>(x0_) + kGrow;
    const double y_lo = min_y - static_cast<double>(y0_) - kGrow, y_hi = max_y - static_cast<double>(y0_) + kGrow;
    if (x_lo <= 0.5 && x_hi >= -0.5 && y_lo <= 0.5 && y_hi >= -0.5)
    {
      visit(0.0, 4.0, f);  // around the origin: every direction
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
        (v < 2.0 ? below : above) = v < 2.0 ? std::max(below, v) : std::min(above, v);
      }
      visit(0.0, below, f);
      visit(above, 4.0, f);
      return;
    }
    visit(lo, hi, f);
  }

  bool empty() const { return ends_.empty(); }

private:
  struct End
  {
    std::uint32_t x1, y1;
    std::uint32_t point;
  };

  static int bucketOf(double angle)
  {
    return std::min(kBuckets - 1, std::max(0, static_cast<int>(angle * (kBuckets / 4.0))));
  }

  void prepare()
  {
    angles_.resize(ends_.size());
    for (std::size_t i = 0; i < ends_.size(); ++i)
    {
      const int dx = static_cast<int>(ends_[i].x1) - static_cast<int>(x0_);
      const int dy = static_cast<int>(ends_[i].y1) - static_cast<int>(y0_);
      angles_[i] = pseudoAngle(dx, dy);
    }
    beams_.reset(new Beam[ends_.size()]);  // left uninitialised: a beam is filled when first reached
    line_ready_.assign(ends_.size(), 0);
  }

  /// Counting sort by bucket into order_; afterwards bucket b holds order_[start_[b] .. start_[b + 1]).
  void buildBuckets()
  {
    start_.assign(kBuckets + 2, 0);
    bucket_of_.resize(ends_.size());
    for (std::size_t i = 0; i < ends_.size(); ++i)
    {
      bucket_of_[i] = static_cast<std::uint16_t>(bucketOf(angles_[i]));
      ++start_[bucket_of_[i] + 2];
    }
    for (int b = 2; b < kBuckets + 2; ++b)
    {
      start_[b] += start_[b - 1];
    }
    // Bucket b's entries are placed from start_[b + 1] on, which then ends where bucket b + 1 begins.
    order_.resize(ends_.size());
    for (std::size_t i = 0; i < ends_.size(); ++i)
    {
      order_[start_[bucket_of_[i] + 1]++] = static_cast<std::uint32_t>(i);
    }
  }

  template <class F>
  void visitBeam(std::uint32_t i, F& f)
  {
    Beam& beam = beams_[i];
    if (!line_ready_[i])
    {
      beam.line = lineSteps(x0_, y0_, ends_[i].x1, ends_[i].y1, max_length_);  // as raytraced
      beam.point = ends_[i].point;
      beam.deep_steps = kUnset;
      line_ready_[i] = 1;
    }
    f(beam);
  }

  /// Every beam whose pseudo-angle lies in [lo, hi] (and, once bucketed, some just outside it).
  template <class F>
  void visit(double lo, double hi, F& f)
  {
    if (queries_ < kLinearQueries)
    {
      ++queries_;
      for (std::uint32_t i = 0; i < angles_.size(); ++i)
      {
        if (angles_[i] >= lo && angles_[i] <= hi)
        {
          visitBeam(i, f);
        }
      }
      return;
    }
    if (order_.size() != ends_.size())
    {
      buildBuckets();
    }
    for (std::uint32_t k = start_[bucketOf(lo)]; k < start_[bucketOf(hi) + 1]; ++k)
    {
      visitBeam(order_[k], f);
    }
  }

  unsigned int x0_, y0_, max_length_;
  std::vector<End> ends_;
  std::vector<double> angles_;  ///< pseudo-angle of each beam's end cell from the origin cell
  std::unique_ptr<Beam[]> beams_;
  std::vector<std::uint8_t> line_ready_;
  int queries_ = 0;
  std::vector<std::uint16_t> bucket_of_;
  std::vector<std::uint32_t> start_;  ///< see buildBuckets
  std::vector<std::uint32_t> order_;  ///< beam indexes by bucket
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
  for (const std::vector<std::uint32_t>* list : { &watch.cells, &watch.loose_cells })
  {
    for (std::uint32_t index : *list)
    {
      if (index >= cell_count)
      {
        throw std::invalid_argument("applyScan: watched cell " + std::to_string(index) + " outside " +
                                    g.describe());
      }
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
  if (watch.scratch != nullptr && watch.scratch_size != cell_count)
  {
    throw std::invalid_argument("applyScan: scratch holds " + std::to_string(watch.scratch_size) +
                                " cells, the grid " + std::to_string(cell_count));
  }
  const bool watching = !watch.empty();
  std::vector<std::uint8_t> own_scratch;
  std::uint8_t* flags = watch.scratch;
  if (watching && flags == nullptr)
  {
    own_scratch.assign(cell_count, 0);
    flags = own_scratch.data();
  }
  for (const std::vector<std::uint32_t>* list : { &watch.cells, &watch.loose_cells })
  {
    for (std::uint32_t index : *list)
    {
      flags[index] = kWatched;
    }
  }

  // Clearing, exactly as without a watch; the beams that reach a watched cell are walked again below.
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  unsigned int x0 = 0, y0 = 0;
  touch.origin_in_map = std::isfinite(observation.origin.z) && g.worldToMap(ox, oy, x0, y0);
  const unsigned int cell_raytrace_range = g.cellDistance(limits.raytrace_range);
  BeamIndex beams(watching ? observation.points.size() : 0, x0, y0, cell_raytrace_range);
  const bool clearing = touch.origin_in_map && limits.clearing;
  if (clearing)
  {
    const double map_end_x = g.endX();
    const double map_end_y = g.endY();
    SetCellAction clear{ costs, FREE_SPACE };
    touch.touchPoint(ox, oy);
    for (std::size_t pi = 0; pi < observation.points.size(); ++pi)
    {
      const Point3& p = observation.points[pi];
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
      {
        // costmap_2d's updateRaytraceBounds (sqrt of squares: the same value as its hypot, at a fraction of it).
        const double dx = wx - ox, dy = wy - oy;
        const double scale = std::min(1.0, limits.raytrace_range / std::sqrt(dx * dx + dy * dy));
        touch.touchPoint(ox + dx * scale, oy + dy * scale);
      }
      const LineSteps line = lineSteps(x0, y0, x1, y1, cell_raytrace_range);
      const int row = static_cast<int>(g.size_x);
      bresenham2D(clear, line.abs_da, line.abs_db, static_cast<int>(line.abs_da / 2),
                  line.x_major ? line.sign_a : line.sign_a * row, line.x_major ? line.sign_b * row : line.sign_b,
                  y0 * g.size_x + x0, line.end);
      if (watching)
      {
        beams.add(pi, x1, y1);
      }
    }
  }

  // Marking; while watching, endpoints at any range in watched cells are also recorded as evidence of
  // occupancy (costmap_2d marks only within obstacle_range, so a face beyond it would otherwise look free to
  // the beams that graze it).
  const double sq_obstacle_range = limits.obstacle_range * limits.obstacle_range;
  const double oz = observation.origin.z;
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
  for (const std::vector<std::uint32_t>* list : { &watch.cells, &watch.loose_cells })
  {
    if (list == &watch.cells && !watch.regions.empty())
    {
      continue;  // the regions' corners bound them
    }
    for (std::uint32_t index : *list)
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
    const bool in_range = limits.marking && sq_dist < sq_obstacle_range;
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
    if (watching && (flags[index] & kWatched) && !(flags[index] & kHit))
    {
      flags[index] |= kHit;
      touch.watched_hit.push_back(index);
    }
    if (in_range)
    {
      costs[index] = LETHAL_OBSTACLE;
      touch.marked.push_back(index);
      touch.touchPoint(p.x, p.y);
    }
  }
  // Which watched cells the beams passed, and how far before their endpoints. Only the beams pointing at a
  // region are walked, and only over the steps inside it: the cost grows with the watched area in view, not
  // with the length of the beams. After marking, so that loose cells marked again (not seen free whatever the
  // beams did) are not walked at all.
  if (watching && !beams.empty())
  {
    const auto shadow_deep_steps = [&](BeamIndex::Beam& beam) {
      // Cells up to free_margin before the (unclipped) endpoint are seen free; the rest of the beam (the face
      // it hit, a neighbour it grazed) only clears. Shadow filter: the shortest range among this point and its
      // free_neighbours neighbours on each side.
      const Point3& p = observation.points[beam.point];
      double shadow_sq = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy);
      const std::size_t n = observation.points.size();
      const std::size_t k = watch.free_neighbours;
      const std::size_t lo = beam.point >= k ? beam.point - k : 0;
      const std::size_t hi = std::min(n - 1, beam.point + k);
      for (std::size_t j = lo; j <= hi; ++j)
      {
        const Point3& q = observation.points[j];
        const double r_sq = (q.x - ox) * (q.x - ox) + (q.y - oy) * (q.y - oy);
        if (std::isfinite(r_sq))
        {
          shadow_sq = std::min(shadow_sq, r_sq);
        }
      }
      const double deep_until = (std::sqrt(shadow_sq) - watch.free_margin) / g.resolution;
      return stepsWithin(deep_until, beam.line.abs_da, beam.line.dist);
    };
    const auto walk_region = [&](const CellRect& r) {
      beams.forEachTowards(r.min_x, r.min_y, r.max_x, r.max_y, [&](BeamIndex::Beam& beam) {
        const LineSteps& line = beam.line;
        const int a0 = static_cast<int>(line.x_major ? x0 : y0);
        const int b0 = static_cast<int>(line.x_major ? y0 : x0);
        const int a_min = line.x_major ? r.min_x : r.min_y, a_max = line.x_major ? r.max_x : r.max_y;
        const int b_min = line.x_major ? r.min_y : r.min_x, b_max = line.x_major ? r.max_y : r.max_x;
        // The steps whose a coordinate lies in the region.
        long first = 0, last = 0;
        if (line.sign_a > 0)
        {
          first = a_min - a0;
          last = a_max - a0;
        }
        else if (line.sign_a < 0)
        {
          first = a0 - a_max;
          last = a0 - a_min;
        }
        else if (a0 < a_min || a0 > a_max)
        {
          return;
        }
        first = std::max(first, 0L);
        last = std::min(last, static_cast<long>(line.end));
        if (first > last)
        {
          return;
        }
        unsigned int carries = 0;
        std::uint64_t error = line.abs_da / 2;
        if (first > 0)
        {
          carries = line.carries(static_cast<unsigned int>(first));
          error += static_cast<std::uint64_t>(first) * line.abs_db - static_cast<std::uint64_t>(carries) * line.abs_da;
        }
        for (long i = first; i <= last; ++i)
        {
          const int b = b0 + line.sign_b * static_cast<int>(carries);
          if (b >= b_min && b <= b_max)
          {
            const int a = a0 + line.sign_a * static_cast<int>(i);
            const std::uint32_t index = line.x_major ? g.getIndex(a, b) : g.getIndex(b, a);
            if (flags[index] & kWatched)
            {
              if (beam.deep_steps == BeamIndex::kUnset)
              {
                beam.deep_steps = shadow_deep_steps(beam);
              }
              flags[index] |= static_cast<unsigned int>(i) < beam.deep_steps ? kVisitedDeep : kVisitedShallow;
            }
          }
          error += line.abs_db;
          if (error >= line.abs_da)
          {
            error -= line.abs_da;
            ++carries;
          }
        }
      });
    };
    for (const CellRect& r : watch.regions)
    {
      if (!r.empty())
      {
        walk_region(r);
      }
    }
    // Cells covered by no region are walked one by one.
    const auto walk_cell = [&](std::uint32_t index) {
      if ((flags[index] & (kVisitedDeep | kVisitedShallow)) || costs[index] == LETHAL_OBSTACLE)
      {
        return;  // a duplicate walked already, or marked by this scan
      }
      unsigned int cx = 0, cy = 0;
      g.indexToCells(index, cx, cy);
      walk_region(CellRect{ static_cast<int>(cx), static_cast<int>(cy), static_cast<int>(cx), static_cast<int>(cy) });
    };
    if (watch.regions.empty())
    {
      std::for_each(watch.cells.begin(), watch.cells.end(), walk_cell);
    }
    std::for_each(watch.loose_cells.begin(), watch.loose_cells.end(), walk_cell);
  }

  if (!clearing)  // the clearing pass counts the points it could not use; without it, count them here
  {
    for (const Point3& p : observation.points)
    {
      usable(p, limits, touch);
    }
  }
  sortUnique(touch.marked);

  // Read the flags back and leave the scratch zeroed. A visited cell that is lethal now was marked again by this
  // scan: not seen free, as costmap_2d keeps it.
  for (const std::vector<std::uint32_t>* list : { &watch.cells, &watch.loose_cells })
  {
    for (std::uint32_t index : *list)
    {
      const std::uint8_t f = flags[index];
      flags[index] = 0;
      if (!(f & (kVisitedDeep | kVisitedShallow)) || costs[index] == LETHAL_OBSTACLE)
      {
        continue;  // untouched, marked again, or a duplicate already read
      }
      touch.watched_cleared.push_back(index);
      if ((f & kVisitedDeep) && !(f & kHit))
      {
        touch.watched_free.push_back(index);
      }
    }
  }
  sortUnique(touch.watched_hit);
  sortUnique(touch.watched_free);
  sortUnique(touch.watched_cleared);
  return touch;
}

}  // namespace sharing_layer
