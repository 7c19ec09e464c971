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
  if (std::isnan(max_marking_height))
  {
    throw std::invalid_argument("ScanLimits: max_marking_height must not be NaN");
  }
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
constexpr std::uint8_t kFlagged = ScanWatch::kFlaggedWatched;  ///< the owner's: watched between scans
constexpr std::uint8_t kVisitedDeep = 2;     ///< a beam passed with its endpoint at least free_margin beyond
constexpr std::uint8_t kVisitedShallow = 4;  ///< a beam passed with its endpoint closer
constexpr std::uint8_t kHit = 8;             ///< an endpoint of this scan lies in the cell
constexpr std::uint8_t kListed = 16;         ///< listed in the watch for this scan
static_assert(((kFlagged | kVisitedDeep | kVisitedShallow | kHit | kListed) & ScanWatch::kOwnerBits) == 0,
              "the scan's bits must leave the owner's alone");
constexpr std::uint8_t kWatched = kFlagged | kListed;
constexpr std::uint8_t kSeen = kVisitedDeep | kVisitedShallow | kHit;  ///< this scan's evidence

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
/// the beams able to cross a watched region are found without walking every beam. Raytracing only stores each
/// beam's end cell, by point index. The first few regions test every beam against the region's wedge of
/// directions (two cross products, vectorised); later ones test only the beams in buckets of pseudo-angle covering
/// the wedge, sorted once. Beams that end nearer than a region's nearest cell are left out too (most beams towards
/// a far obstacle end on something in front of it). A beam's line is computed when a region first reaches it.
class BeamIndex
{
public:
  struct Beam
  {
    LineSteps line;
    std::size_t point;         ///< index in the observation
    unsigned int deep_steps;   ///< steps before which a watched cell counts as seen free (kUnset until needed)
    unsigned int own_steps;    ///< the same by the beam's own range only, >= deep_steps (kUnset until needed)
    unsigned int end_x, end_y; ///< end cell
    bool end_is_point;         ///< the end cell holds the point (not clipped to the grid edge)
    std::uint32_t scan;        ///< BeamIndex's stamp of the scan that filled it
  };
  static constexpr unsigned int kUnset = UINT_MAX;
  static constexpr int kBuckets = 1024;      ///< about 0.35 degrees each
  static constexpr int kLinearQueries = 2;  ///< regions answered by testing every beam before buckets pay off

  /// For an observation of `points` points, raytraced from cell (x0, y0) over at most max_length cells.
  BeamIndex(std::size_t points, unsigned int x0, unsigned int y0, unsigned int max_length)
    : x0_(x0), y0_(y0), max_length_(max_length), n_(static_cast<std::uint32_t>(points)), s_(storage())
  {
    if (s_.dx.size() < points)
    {
      s_.end_x.resize(points);
      s_.end_y.resize(points);
      s_.dx.resize(points);
      s_.dy.resize(points);
      s_.pass.resize(points);
    }
    s_.state.assign(points, kNone);
    end_x_ = s_.end_x.data();
    end_y_ = s_.end_y.data();
    dx_ = s_.dx.data();
    dy_ = s_.dy.data();
    state_ = s_.state.data();
  }

  /// The beam of point `point` ends in cell (x1, y1); clipped: the point lies off the grid, (x1, y1) on its edge.
  void add(std::size_t point, unsigned int x1, unsigned int y1, bool clipped)
  {
    end_x_[point] = x1;  // (raytracing's inner loop: as little as possible here)
    end_y_[point] = y1;
    state_[point] = clipped ? kClipped : kEndsInPoint;
  }

  /// Calls f(beam) for every beam that can visit a cell of [min_x, max_x] x [min_y, max_y]: its direction lies
  /// within the directions of the rectangle's corners grown by the slack of a Bresenham line, and its end cell is
  /// not nearer than the rectangle. No add after the first call.
  template <class F>
  void forEachTowards(int min_x, int min_y, int max_x, int max_y, F f)
  {
    if (!prepared_)
    {
      prepare();
    }
    // A beam visits a cell only where the exact line between the start and end cells' centres passes within
    // half a cell of the cell's centre along b (Bresenham rounds b to the nearest cell), so only through the
    // cell's own square: its corners bound the directions, with a margin for rounding.
    constexpr double kGrow = 0.5 + 0.05;
    const double x_lo = min_x - static_cast<double>(x0_) - kGrow, x_hi = max_x - static_cast<double>(x0_) + kGrow;
    const double y_lo = min_y - static_cast<double>(y0_) - kGrow, y_hi = max_y - static_cast<double>(y0_) + kGrow;
    // The cells a beam visits lie within half a cell beyond its end cell's distance from the origin cell (step i
    // is i cells along a and within half a cell of the exact line along b).
    const double near_x = std::max(0.0, std::max(min_x - static_cast<double>(x0_), static_cast<double>(x0_) - max_x));
    const double near_y = std::max(0.0, std::max(min_y - static_cast<double>(y0_), static_cast<double>(y0_) - max_y));
    // (near - 0.5)^2 >= near^2 - (near_x + near_y), as near <= near_x + near_y: a bound without a square root.
    const double reach_sq = near_x * near_x + near_y * near_y - (near_x + near_y);
    Wedge w;
    // Single precision, so that testing every beam vectorises; the thresholds are loosened far beyond its rounding
    // (a beam let through in excess is walked to no effect).
    w.reach_sq = reach_sq > 0.0 ? static_cast<float>(reach_sq * (1.0 - 1e-5)) : -1.0f;
    const bool around_origin = x_lo <= 0.5 && x_hi >= -0.5 && y_lo <= 0.5 && y_hi >= -0.5;
    const double corners[4][2] = { { x_lo, y_lo }, { x_hi, y_lo }, { x_lo, y_hi }, { x_hi, y_hi } };
    int first = 0, last = 0;
    if (!around_origin)  // (around it, the zero wedge admits every direction)
    {
      // The rectangle does not hold the origin, so its directions span less than half a turn: the clockwise-most
      // and counter-clockwise-most corners bound them, and a beam lies between them when both cross products
      // are >= 0.
      const auto cross = [](double ax, double ay, double bx, double by) { return ax * by - ay * bx; };
      for (int j = 1; j < 4; ++j)
      {
        if (cross(corners[first][0], corners[first][1], corners[j][0], corners[j][1]) < 0.0)
        {
          first = j;
        }
        if (cross(corners[last][0], corners[last][1], corners[j][0], corners[j][1]) > 0.0)
        {
          last = j;
        }
      }
      w.first_x = static_cast<float>(corners[first][0]);
      w.first_y = static_cast<float>(corners[first][1]);
      w.last_x = static_cast<float>(corners[last][0]);
      w.last_y = static_cast<float>(corners[last][1]);
    }
    const float* dx = dx_;
    const float* dy = dy_;
    const std::uint8_t* state = state_;
    if (queries_ < kLinearQueries)  // test every beam
    {
      ++queries_;
      std::uint8_t* pass = s_.pass.data();
      const std::uint32_t n = n_;  // a local: the byte stores below could alias a member
      for (std::uint32_t i = 0; i < n; ++i)  // (a point without a beam holds an old direction: state says so)
      {
        pass[i] = (state[i] != kNone) & w.admits(dx[i], dy[i]);
      }
      for (std::uint32_t i = 0; i < n; ++i)
      {
        if (pass[i])
        {
          visitBeam(i, f);
        }
      }
      return;
    }
    if (!bucketed_)
    {
      buildBuckets();
    }
    // The beams of a run of buckets lie side by side in sorted order: tested together (vectorised), then visited.
    const auto visit_range = [&](double lo, double hi) {
      const std::uint32_t from = s_.start[bucketOf(lo)], to = s_.start[bucketOf(hi) + 1];
      const float* sorted_dx = s_.sorted_dx.data();
      const float* sorted_dy = s_.sorted_dy.data();
      std::uint8_t* pass = s_.pass.data();
      for (std::uint32_t k = from; k < to; ++k)
      {
        pass[k] = w.admits(sorted_dx[k], sorted_dy[k]);
      }
      for (std::uint32_t k = from; k < to; ++k)
      {
        if (pass[k])
        {
          visitBeam(s_.order[k], f);
        }
      }
    };
    if (around_origin)
    {
      visit_range(0.0, 4.0);
      return;
    }
    // The wedge runs counter-clockwise from the first corner's direction to the last's.
    const double lo = pseudoAngle(corners[first][0], corners[first][1]);
    const double hi = pseudoAngle(corners[last][0], corners[last][1]);
    if (lo > hi)  // straddles the +x axis (0 / 4): two intervals
    {
      visit_range(lo, 4.0);
      visit_range(0.0, hi);
      return;
    }
    visit_range(lo, hi);
  }

private:
  static constexpr std::uint8_t kNone = 0;        ///< the point made no beam (unusable, or no clearing)
  static constexpr std::uint8_t kEndsInPoint = 1;
  static constexpr std::uint8_t kClipped = 2;

  /// Directions between first and last (counter-clockwise; all zero: every direction), and a least squared length.
  struct Wedge
  {
    float first_x = 0.0f, first_y = 0.0f, last_x = 0.0f, last_y = 0.0f;
    float reach_sq = -1.0f;
    bool admits(float x, float y) const
    {
      return (first_x * y - first_y * x >= 0.0f) & (x * last_y - y * last_x >= 0.0f) & (x * x + y * y >= reach_sq);
    }
  };

  static int bucketOf(double angle)
  {
    return std::min(kBuckets - 1, std::max(0, static_cast<int>(angle * (kBuckets / 4.0))));
  }

  void prepare()
  {
    if (s_.beams.size() < n_)
    {
      s_.beams.resize(n_);  // a beam is filled when first reached in a scan
    }
    // Directions in single precision, which holds any cell offset of a grid below 2^24 cells a side exactly.
    const std::uint32_t n = n_;
    const std::uint32_t* end_x = end_x_;
    const std::uint32_t* end_y = end_y_;
    float* dx = dx_;
    float* dy = dy_;
    const float x0 = static_cast<float>(x0_), y0 = static_cast<float>(y0_);
    for (std::uint32_t i = 0; i < n; ++i)
    {
      dx[i] = static_cast<float>(static_cast<std::int32_t>(end_x[i])) - x0;
      dy[i] = static_cast<float>(static_cast<std::int32_t>(end_y[i])) - y0;
    }
    if (++s_.scan == 0)  // wrapped: stamps of old scans could match again
    {
      for (Beam& beam : s_.beams)
      {
        beam.scan = 0;
      }
      s_.scan = 1;
    }
    prepared_ = true;
  }

  /// Counting sort by the bucket of each beam's pseudo-angle into order; afterwards bucket b holds
  /// order[start[b] .. start[b + 1]).
  void buildBuckets()
  {
    s_.start.assign(kBuckets + 2, 0);
    s_.bucket_of.resize(n_);
    const float* dx = s_.dx.data();
    const float* dy = s_.dy.data();
    std::uint16_t* bucket_of = s_.bucket_of.data();
    const std::uint32_t n = n_;
    for (std::uint32_t i = 0; i < n; ++i)  // pseudoAngle without branches, so that it vectorises
    {
      const float sum = std::max(std::fabs(dx[i]) + std::fabs(dy[i]), 1e-30f);
      const float p = dy[i] / sum;  // [-1, 1]
      // x >= 0: p, or 4 + p below the axis; x < 0: 2 - p (pseudoAngle's four quadrants)
      const float right = static_cast<float>(dx[i] >= 0.0f), below = static_cast<float>(p < 0.0f);
      const float angle = right * (p + 4.0f * below) + (1.0f - right) * (2.0f - p);
      // (a point without a beam lands in some bucket, and is never admitted)
      bucket_of[i] = static_cast<std::uint16_t>(
          std::max(0.0f, std::min(static_cast<float>(kBuckets - 1), angle * (kBuckets / 4.0f))));
    }
    for (std::uint32_t i = 0; i < n; ++i)
    {
      ++s_.start[bucket_of[i] + 2];
    }
    for (int b = 2; b < kBuckets + 2; ++b)
    {
      s_.start[b] += s_.start[b - 1];
    }
    // Bucket b's entries are placed from start[b + 1] on, which then ends where bucket b + 1 begins. Points
    // without a beam get a NaN direction, which no wedge admits.
    s_.order.resize(n);
    s_.sorted_dx.resize(n);
    s_.sorted_dy.resize(n);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (std::uint32_t i = 0; i < n; ++i)
    {
      const std::uint32_t k = s_.start[bucket_of[i] + 1]++;
      s_.order[k] = i;
      s_.sorted_dx[k] = state_[i] != kNone ? dx[i] : nan;
      s_.sorted_dy[k] = state_[i] != kNone ? dy[i] : nan;
    }
    bucketed_ = true;
  }

  template <class F>
  void visitBeam(std::uint32_t i, F& f)
  {
    Beam& beam = s_.beams[i];
    if (beam.scan != s_.scan)
    {
      beam.scan = s_.scan;
      beam.end_x = end_x_[i];
      beam.end_y = end_y_[i];
      beam.line = lineSteps(x0_, y0_, beam.end_x, beam.end_y, max_length_);  // as raytraced
      beam.point = i;
      beam.deep_steps = kUnset;
      beam.own_steps = kUnset;
      beam.end_is_point = state_[i] == kEndsInPoint;
    }
    f(beam);
  }

  /// Buffers kept from scan to scan, one set per thread: once grown, a scan allocates nothing for its beams.
  struct Storage
  {
    std::vector<std::uint8_t> state;         ///< per point: kNone, kEndsInPoint or kClipped
    std::vector<std::uint32_t> end_x, end_y;  ///< per point with a beam: its end cell
    std::vector<float> dx, dy;               ///< the same minus the origin cell (filled when first asked)
    std::vector<std::uint8_t> pass;          ///< wedge test of every beam
    std::vector<Beam> beams;
    std::uint32_t scan = 0;  ///< stamp of the current scan: a beam with another stamp is not filled yet
    std::vector<std::uint16_t> bucket_of;
    std::vector<std::uint32_t> start;  ///< see buildBuckets
    std::vector<std::uint32_t> order;  ///< beam indexes by bucket
    std::vector<float> sorted_dx, sorted_dy;  ///< their directions in that order
  };
  static Storage& storage()
  {
    thread_local Storage storage;
    return storage;
  }

  unsigned int x0_, y0_, max_length_;
  std::uint32_t n_;
  Storage& s_;
  std::uint32_t* end_x_;
  std::uint32_t* end_y_;
  float* dx_;
  float* dy_;
  std::uint8_t* state_;
  bool prepared_ = false;
  bool bucketed_ = false;
  int queries_ = 0;
};

/// @return whether cell (x, y) lies in one of the rectangles (flagged cells are watched only there)
bool inRegion(const std::vector<CellRect>& regions, unsigned int x, unsigned int y)
{
  return std::any_of(regions.begin(), regions.end(), [x, y](const CellRect& r) {
    return r.contains(static_cast<int>(x), static_cast<int>(y));
  });
}

/// A scan's temporaries, kept from scan to scan (per thread) so that a scan does not allocate them again.
struct ScanScratch
{
  std::vector<std::uint32_t> seen_cells;
  std::vector<double> range_sq;
};

ScanScratch& scanScratch()
{
  thread_local ScanScratch scratch;
  return scratch;
}

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
      flags[index] |= kListed;
    }
  }
  // Watched cells given evidence by this scan, each once: the cells to read back and reset.
  ScanScratch& scan_scratch = scanScratch();
  std::vector<std::uint32_t>& seen_cells = scan_scratch.seen_cells;
  seen_cells.clear();
  const auto note = [&seen_cells, flags](std::uint32_t index, std::uint8_t evidence) {
    if (!(flags[index] & kSeen))
    {
      seen_cells.push_back(index);
    }
    flags[index] |= evidence;
  };
  touch.marked.reserve(observation.points.size());

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
      bool clipped = false;
      const double a = wx - ox;
      const double b = wy - oy;
      // Clip the endpoint to the grid as costmap_2d does, so beams leaving the map still clear inside it.
      if (wx < g.origin_x)
      {
        const double t = (g.origin_x - ox) / a;
        wx = g.origin_x;
        clipped = true;
        wy = oy + b * t;
      }
      if (wy < g.origin_y)
      {
        const double t = (g.origin_y - oy) / b;
        wx = ox + a * t;
        wy = g.origin_y;
        clipped = true;
      }
      if (wx > map_end_x)
      {
        const double t = (map_end_x - ox) / a;
        wx = map_end_x - .001;
        clipped = true;
        wy = oy + b * t;
      }
      if (wy > map_end_y)
      {
        const double t = (map_end_y - oy) / b;
        wx = ox + a * t;
        wy = map_end_y - .001;
        clipped = true;
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
        beams.add(pi, x1, y1, clipped);
      }
    }
  }

  // Marking; while watching, endpoints at any range in watched cells are also recorded as evidence of
  // occupancy (costmap_2d marks only within obstacle_range, so a face beyond it would otherwise look free to
  // the beams that graze it).
  const double sq_obstacle_range = limits.obstacle_range * limits.obstacle_range;
  const double oz = observation.origin.z;
  // When clearing recorded the beams, the walk below finds the endpoints in watched cells beyond obstacle_range
  // (it visits every beam whose end cell lies in a region); otherwise every endpoint within reach is looked up.
  const bool hits_in_walk = watching && clearing;
  // Endpoints farther than the farthest watched cell (plus a cell) cannot lie in one.
  double sq_hit_range = -1.0;
  if (watching && !hits_in_walk)
  {
    const auto farther = [&](unsigned int cx, unsigned int cy) {
      double wx = 0.0, wy = 0.0;
      g.mapToWorld(cx, cy, wx, wy);
      sq_hit_range = std::max(sq_hit_range, (wx - ox) * (wx - ox) + (wy - oy) * (wy - oy));
    };
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
  }
  for (const Point3& p : observation.points)
  {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < limits.min_obstacle_height ||
        p.z > limits.max_obstacle_height)
    {
      continue;  // counted in the clearing pass, or below when it did not run
    }
    const double sq_dist = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + (p.z - oz) * (p.z - oz);
    const bool in_range = limits.marking && sq_dist < sq_obstacle_range && !(p.z > limits.max_marking_height);
    const double sq_planar = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy);
    if (!in_range && !(sq_planar <= sq_hit_range))
    {
      continue;
    }
    unsigned int mx = 0, my = 0;
    if (!g.worldToMap(p.x, p.y, mx, my))
    {
      continue;
    }
    const std::uint32_t index = g.getIndex(mx, my);
    if (watching && (flags[index] & kWatched) && !(flags[index] & kHit) &&
        ((flags[index] & kListed) || inRegion(watch.regions, mx, my)))
    {
      note(index, kHit);
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
  if (watching && clearing)
  {
    // Each point's planar range squared (+inf when not finite; -1 until a beam needs it).
    std::vector<double>& range_sq = scan_scratch.range_sq;
    range_sq.clear();
    const std::size_t n = observation.points.size();
    const auto point_range_sq = [&](std::size_t j) {
      if (range_sq.empty())
      {
        range_sq.assign(n, -1.0);
      }
      if (range_sq[j] < 0.0)
      {
        const Point3& q = observation.points[j];
        const double r_sq = (q.x - ox) * (q.x - ox) + (q.y - oy) * (q.y - oy);
        range_sq[j] = std::isfinite(r_sq) ? r_sq : std::numeric_limits<double>::infinity();
      }
      return range_sq[j];
    };
    // Cells up to free_margin before the (unclipped) endpoint are seen free; the rest of the beam (the face it hit,
    // a neighbour it grazed) only clears. By the beam's own range first: most beams that reach a watched cell end
    // on it, and the shadow filter below can only shorten what is seen free.
    const auto own_deep_steps = [&](BeamIndex::Beam& beam) {
      const double deep_until = (std::sqrt(point_range_sq(beam.point)) - watch.free_margin) / g.resolution;
      return stepsWithin(deep_until, beam.line.abs_da, beam.line.dist);
    };
    // Shadow filter: the shortest range among this point and its free_neighbours neighbours on each side.
    const auto shadow_deep_steps = [&](BeamIndex::Beam& beam) {
      const std::size_t k = watch.free_neighbours;
      const std::size_t lo = beam.point >= k ? beam.point - k : 0;
      const std::size_t hi = std::min(n - 1, beam.point + k);
      double shadow_sq = std::numeric_limits<double>::infinity();
      for (std::size_t j = lo; j <= hi; ++j)
      {
        shadow_sq = std::min(shadow_sq, point_range_sq(j));
      }
      const double deep_until = (std::sqrt(shadow_sq) - watch.free_margin) / g.resolution;
      return stepsWithin(deep_until, beam.line.abs_da, beam.line.dist);
    };
    const auto walk_region = [&](const CellRect& r) {
      beams.forEachTowards(r.min_x, r.min_y, r.max_x, r.max_y, [&](BeamIndex::Beam& beam) {
        if (beam.end_is_point && r.contains(static_cast<int>(beam.end_x), static_cast<int>(beam.end_y)))
        {
          const std::uint32_t end = g.getIndex(beam.end_x, beam.end_y);
          if ((flags[end] & kWatched) && !(flags[end] & kHit))  // an endpoint in a watched cell, at any range
          {
            note(end, kHit);
          }
        }
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
              if (beam.own_steps == BeamIndex::kUnset)
              {
                beam.own_steps = own_deep_steps(beam);
              }
              bool deep = false;
              if (static_cast<unsigned int>(i) < beam.own_steps)
              {
                if (beam.deep_steps == BeamIndex::kUnset)
                {
                  beam.deep_steps = shadow_deep_steps(beam);
                }
                deep = static_cast<unsigned int>(i) < beam.deep_steps;
              }
              note(index, deep ? kVisitedDeep : kVisitedShallow);
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

  // Read the flags back, in index order (so the lists come out sorted), and leave the scratch as it was. A
  // visited cell that is lethal now was marked again by this scan: not seen free, as costmap_2d keeps it.
  std::sort(seen_cells.begin(), seen_cells.end());  // unique: a cell is added when it first gets a bit
  std::size_t hits = 0, passed = 0;  // sizes first: one allocation per list, none for an empty one
  for (std::uint32_t index : seen_cells)
  {
    hits += (flags[index] & kHit) != 0;
    passed += (flags[index] & (kVisitedDeep | kVisitedShallow)) != 0;
  }
  touch.watched_hit.reserve(hits);
  touch.watched_cleared.reserve(passed);
  for (std::uint32_t index : seen_cells)
  {
    const std::uint8_t f = flags[index];
    flags[index] = f & ~kSeen;
    if (f & kHit)
    {
      touch.watched_hit.push_back(index);
    }
    if (!(f & (kVisitedDeep | kVisitedShallow)) || costs[index] == LETHAL_OBSTACLE)
    {
      continue;  // only hit, or marked again
    }
    touch.watched_cleared.push_back(index);
    if ((f & kVisitedDeep) && !(f & kHit))
    {
      touch.watched_free.push_back(index);
    }
  }
  if (watching)
  {
    for (const std::vector<std::uint32_t>* list : { &watch.cells, &watch.loose_cells })
    {
      for (std::uint32_t index : *list)
      {
        flags[index] &= ~kListed;
      }
    }
  }
  return touch;
}

}  // namespace sharing_layer
