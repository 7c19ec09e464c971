#include "sharing_layer/scan_update.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/fan_clearing.h"
#include "sharing_layer/raytrace.h"
#include "beam_index.h"

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
static_assert((kVisitedDeep | kVisitedShallow | kHit | kListed) == CellFlags::kScanBits,
              "the scan's bits are CellFlags::kScanBits");
static_assert(((kFlagged | CellFlags::kScanBits) & ScanWatch::kOwnerBits) == 0,
              "the scan's bits must leave the owner's alone");
constexpr std::uint8_t kWatched = kFlagged | kListed;
constexpr std::uint8_t kSeen = kVisitedDeep | kVisitedShallow | kHit;  ///< this scan's evidence


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
  std::vector<LineSteps> beam_lines;
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

namespace
{
/**
 * @brief One applyScan: costmap_2d's clearing (raytrace to each endpoint, clipped to the grid) and marking (endpoints
 * within obstacle_range), and, while watching, the evidence the same beams give about the watched cells: which ones a
 * beam passed (and how far before its end), which hold an endpoint. The passes run in this order: clear (recording
 * the beams), mark (before the walk, so that cells marked again are not seen free), walk the watched cells, read the
 * flags back and leave the scratch as it was found.
 */
class ScanRun
{
public:
  ScanRun(CostGrid& grid, const Observation& observation, const ScanLimits& limits, const ScanWatch& watch)
    : g_(grid.geometry())
    , costs_(grid.data())
    , observation_(observation)
    , limits_(limits)
    , watch_(watch)
    , seen_cells_(scanScratch().seen_cells)
    , range_sq_(scanScratch().range_sq)
    , beam_lines_(scanScratch().beam_lines)
  {
  }

  ScanTouch run()
  {
    limits_.validate();
    validateWatch();
    watching_ = !watch_.empty();
    flags_ = watch_.scratch;
    if (watching_ && flags_ == nullptr)
    {
      own_scratch_.assign(g_.cellCount());
      flags_ = &own_scratch_;
    }
    setListed(true);
    seen_cells_.clear();
    touch_.marked.reserve(observation_.points.size());
    ox_ = observation_.origin.x;
    oy_ = observation_.origin.y;
    touch_.origin_in_map = std::isfinite(observation_.origin.z) && g_.worldToMap(ox_, oy_, x0_, y0_);
    cell_raytrace_range_ = g_.cellDistance(limits_.raytrace_range);
    // (the loose cells are left out of the count: most of them are marked again by the scan and not walked)
    scan_detail::BeamIndex beams(watching_ ? observation_.points.size() : 0, x0_, y0_, beam_lines_,
                                 watch_.regions.empty() ? watch_.cells.size() : watch_.regions.size());
    beams_ = &beams;
    clearing_ = touch_.origin_in_map && limits_.clearing;
    if (clearing_)
    {
      clearPass();
    }
    markPass();
    if (watching_ && clearing_)
    {
      walkWatched();
    }
    if (!clearing_)  // the clearing pass counts the points it could not use; without it, count them here
    {
      for (const Point3& p : observation_.points)
      {
        usable(p, limits_, touch_);
      }
    }
    sortUnique(touch_.marked);
    readBack();
    if (watching_)
    {
      setListed(false);
    }
    return std::move(touch_);
  }

private:
  using Beam = scan_detail::BeamIndex::Beam;

  void validateWatch() const;
  /// @brief Sets (or clears) kListed on the watch's listed cells.
  void setListed(bool listed)
  {
    for (const std::vector<std::uint32_t>* list : { &watch_.cells, &watch_.loose_cells })
    {
      for (std::uint32_t index : *list)
      {
        listed ? flags_->set(index, kListed) : flags_->clear(index, kListed);
      }
    }
  }
  /// @brief Records evidence for a watched cell; the first time, the cell joins the cells to read back.
  void note(std::uint32_t index, std::uint8_t evidence)
  {
    if (!(flags_->get(index) & kSeen))
    {
      seen_cells_.push_back(index);
    }
    flags_->set(index, evidence);
  }
  void clearPass();
  /// @brief Endpoints farther than this (squared, planar) cannot lie in a watched cell; -1: none can. Only needed
  /// when the walk does not find them (no clearing pass recorded the beams).
  double hitRangeSquared() const;
  void markPass();
  void walkWatched();
  void walkRegion(const CellRect& r);
  /// @brief Each point's planar range squared (+inf when not finite), computed when a beam first needs it.
  double pointRangeSquared(std::size_t j);
  /// @brief Steps of the beam up to free_margin before its own endpoint.
  unsigned int ownDeepSteps(const Beam& beam);
  /// @brief The same with the shadow filter: the shortest range among this point and free_neighbours each side.
  unsigned int shadowDeepSteps(const Beam& beam);
  void readBack();

  const GridGeometry& g_;
  std::uint8_t* costs_;
  const Observation& observation_;
  const ScanLimits& limits_;
  const ScanWatch& watch_;
  ScanTouch touch_;
  CellFlags own_scratch_;
  CellFlags* flags_ = nullptr;
  std::vector<std::uint32_t>& seen_cells_;  ///< watched cells given evidence by this scan, each once
  std::vector<double>& range_sq_;
  std::vector<LineSteps>& beam_lines_;  ///< the clearing pass's lines, cleared together (clearFan)
  scan_detail::BeamIndex* beams_ = nullptr;
  bool watching_ = false;
  bool clearing_ = false;
  double ox_ = 0.0, oy_ = 0.0;
  unsigned int x0_ = 0, y0_ = 0;
  unsigned int cell_raytrace_range_ = 0;
};

void ScanRun::validateWatch() const
{
  const std::size_t cell_count = g_.cellCount();
  for (const std::vector<std::uint32_t>* list : { &watch_.cells, &watch_.loose_cells })
  {
    for (std::uint32_t index : *list)
    {
      if (index >= cell_count)
      {
        throw std::invalid_argument("applyScan: watched cell " + std::to_string(index) + " outside " +
                                    g_.describe());
      }
    }
  }
  if (!watch_.point_cells.empty() && watch_.point_cells.size() != observation_.points.size())
  {
    throw std::invalid_argument("applyScan: point_cells holds " + std::to_string(watch_.point_cells.size()) +
                                " cells for " + std::to_string(observation_.points.size()) + " points");
  }
  if (watch_.free_neighbours > 10000)
  {
    throw std::invalid_argument("applyScan: free_neighbours must be <= 10000, got " +
                                std::to_string(watch_.free_neighbours));
  }
  if (!std::isfinite(watch_.free_margin) || watch_.free_margin < 0.0)
  {
    throw std::invalid_argument("applyScan: free_margin must be finite and >= 0, got " +
                                std::to_string(watch_.free_margin));
  }
  if (watch_.scratch != nullptr && watch_.scratch->size() != cell_count)
  {
    throw std::invalid_argument("applyScan: scratch holds " + std::to_string(watch_.scratch->size()) +
                                " cells, the grid " + std::to_string(cell_count));
  }
}

void ScanRun::clearPass()
{
  // Clearing, exactly as without a watch; the beams that reach a watched cell are walked again in walkWatched.
  // The lines are collected here and cleared together: the same cells as beam by beam, written once near the
  // sensor where the beams overlap (clearFan).
  beam_lines_.clear();
  const double map_end_x = g_.endX();
  const double map_end_y = g_.endY();
  touch_.touchPoint(ox_, oy_);
  const double ox = ox_, oy = oy_;
  // (squared lengths below this have a square root well below raytrace_range, whatever the rounding)
  const double sq_within_range = limits_.raytrace_range * limits_.raytrace_range * (1.0 - 1e-9);
  for (std::size_t pi = 0; pi < observation_.points.size(); ++pi)
  {
    const Point3& p = observation_.points[pi];
    if (!usable(p, limits_, touch_))
    {
      continue;
    }
    double wx = p.x;
    double wy = p.y;
    bool clipped = false;
    const double a = wx - ox;
    const double b = wy - oy;
    // Clip the endpoint to the grid as costmap_2d does, so beams leaving the map still clear inside it.
    if (wx < g_.origin_x)
    {
      const double t = (g_.origin_x - ox) / a;
      wx = g_.origin_x;
      clipped = true;
      wy = oy + b * t;
    }
    if (wy < g_.origin_y)
    {
      const double t = (g_.origin_y - oy) / b;
      wx = ox + a * t;
      wy = g_.origin_y;
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
    if (!clipped && !watch_.point_cells.empty())  // looked up by the caller
    {
      const ScanWatch::Cell cell = watch_.point_cells[pi];
      if (cell.x == ScanWatch::kNoCell)
      {
        continue;
      }
      x1 = cell.x;
      y1 = cell.y;
    }
    else if (!g_.worldToMap(wx, wy, x1, y1))
    {
      continue;
    }
    {
      // costmap_2d's updateRaytraceBounds (sqrt of squares: the same value as its hypot, at a fraction of it). A
      // beam clearly within raytrace_range has scale 1 there too: no square root for it.
      const double dx = wx - ox, dy = wy - oy;
      const double sq = dx * dx + dy * dy;
      const double scale = sq < sq_within_range ? 1.0 : std::min(1.0, limits_.raytrace_range / std::sqrt(sq));
      touch_.touchPoint(ox + dx * scale, oy + dy * scale);
    }
    beam_lines_.emplace_back(x0_, y0_, x1, y1, cell_raytrace_range_);
    if (watching_)
    {
      beams_->add(pi, x1, y1, clipped, beam_lines_.size() - 1);
    }
  }
  clearFan(costs_, g_.size_x, x0_, y0_, beam_lines_, FREE_SPACE);
}

double ScanRun::hitRangeSquared() const
{
  double sq_hit_range = -1.0;
  const auto farther = [&](unsigned int cx, unsigned int cy) {
    double wx = 0.0, wy = 0.0;
    g_.mapToWorld(cx, cy, wx, wy);
    sq_hit_range = std::max(sq_hit_range, (wx - ox_) * (wx - ox_) + (wy - oy_) * (wy - oy_));
  };
  for (const CellRect& r : watch_.regions)  // the farthest corner of each
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
  for (const std::vector<std::uint32_t>* list : { &watch_.cells, &watch_.loose_cells })
  {
    if (list == &watch_.cells && !watch_.regions.empty())
    {
      continue;  // the regions' corners bound them
    }
    for (std::uint32_t index : *list)
    {
      unsigned int cx = 0, cy = 0;
      g_.indexToCells(index, cx, cy);
      farther(cx, cy);
    }
  }
  if (sq_hit_range >= 0.0)
  {
    const double r = std::sqrt(sq_hit_range) + 1.5 * g_.resolution;
    sq_hit_range = r * r;
  }
  return sq_hit_range;
}

void ScanRun::markPass()
{
  // While watching, endpoints at any range in watched cells are also recorded as evidence of occupancy (costmap_2d
  // marks only within obstacle_range, so a face beyond it would otherwise look free to the beams that graze it).
  // When clearing recorded the beams, the walk finds the endpoints in watched cells beyond obstacle_range (it
  // visits every beam whose end cell lies in a region); otherwise every endpoint within reach is looked up here.
  const double sq_obstacle_range = limits_.obstacle_range * limits_.obstacle_range;
  const double ox = ox_, oy = oy_, oz = observation_.origin.z;
  const double sq_hit_range = watching_ && !clearing_ ? hitRangeSquared() : -1.0;
  const bool have_cells = !watch_.point_cells.empty();
  for (std::size_t pi = 0; pi < observation_.points.size(); ++pi)
  {
    const Point3& p = observation_.points[pi];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < limits_.min_obstacle_height ||
        p.z > limits_.max_obstacle_height)
    {
      continue;  // counted in the clearing pass, or in run() when it did not run
    }
    const double sq_dist = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + (p.z - oz) * (p.z - oz);
    const bool in_range = limits_.marking && sq_dist < sq_obstacle_range && !(p.z > limits_.max_marking_height);
    const double sq_planar = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy);
    if (!in_range && !(sq_planar <= sq_hit_range))
    {
      continue;
    }
    unsigned int mx = 0, my = 0;
    std::uint32_t index = 0;
    if (have_cells)
    {
      const ScanWatch::Cell cell = watch_.point_cells[pi];
      if (cell.x == ScanWatch::kNoCell)
      {
        continue;
      }
      mx = cell.x;
      my = cell.y;
    }
    else if (!g_.worldToMap(p.x, p.y, mx, my))
    {
      continue;
    }
    index = g_.getIndex(mx, my);
    const std::uint8_t f = watching_ ? flags_->get(index) : 0;
    if ((f & kWatched) && !(f & kHit) && ((f & kListed) || inRegion(watch_.regions, mx, my)))
    {
      note(index, kHit);
    }
    if (in_range)
    {
      costs_[index] = LETHAL_OBSTACLE;
      touch_.marked.push_back(index);
      touch_.touchPoint(p.x, p.y);
    }
  }
}

double ScanRun::pointRangeSquared(std::size_t j)
{
  if (range_sq_.empty())
  {
    range_sq_.assign(observation_.points.size(), -1.0);
  }
  if (range_sq_[j] < 0.0)
  {
    const Point3& q = observation_.points[j];
    const double r_sq = (q.x - ox_) * (q.x - ox_) + (q.y - oy_) * (q.y - oy_);
    range_sq_[j] = std::isfinite(r_sq) ? r_sq : std::numeric_limits<double>::infinity();
  }
  return range_sq_[j];
}

unsigned int ScanRun::ownDeepSteps(const Beam& beam)
{
  // Cells up to free_margin before the (unclipped) endpoint are seen free; the rest of the beam (the face it hit, a
  // neighbour it grazed) only clears. By the beam's own range first: most beams that reach a watched cell end on it,
  // and the shadow filter can only shorten what is seen free.
  const double deep_until = (std::sqrt(pointRangeSquared(beam.point)) - watch_.free_margin) / g_.resolution;
  return stepsWithin(deep_until, beam.line.abs_da, beam.line.dist());
}

unsigned int ScanRun::shadowDeepSteps(const Beam& beam)
{
  const std::size_t n = observation_.points.size();
  const std::size_t k = watch_.free_neighbours;
  const std::size_t lo = beam.point >= k ? beam.point - k : 0;
  const std::size_t hi = std::min(n - 1, beam.point + k);
  double shadow_sq = std::numeric_limits<double>::infinity();
  for (std::size_t j = lo; j <= hi; ++j)
  {
    shadow_sq = std::min(shadow_sq, pointRangeSquared(j));
  }
  const double deep_until = (std::sqrt(shadow_sq) - watch_.free_margin) / g_.resolution;
  return stepsWithin(deep_until, beam.line.abs_da, beam.line.dist());
}

void ScanRun::walkWatched()
{
  // Which watched cells the beams passed, and how far before their endpoints. Only the beams pointing at a region
  // are walked, and only over the steps inside it: the cost grows with the watched area in view, not with the
  // length of the beams. After marking, so that loose cells marked again (not seen free whatever the beams did) are
  // not walked at all.
  range_sq_.clear();
  for (const CellRect& r : watch_.regions)
  {
    if (!r.empty())
    {
      walkRegion(r);
    }
  }
  // Cells covered by no region are walked one by one.
  const auto walk_cell = [&](std::uint32_t index) {
    if ((flags_->get(index) & (kVisitedDeep | kVisitedShallow)) || costs_[index] == LETHAL_OBSTACLE)
    {
      return;  // a duplicate walked already, or marked by this scan
    }
    unsigned int cx = 0, cy = 0;
    g_.indexToCells(index, cx, cy);
    walkRegion(CellRect{ static_cast<int>(cx), static_cast<int>(cy), static_cast<int>(cx), static_cast<int>(cy) });
  };
  if (watch_.regions.empty())
  {
    std::for_each(watch_.cells.begin(), watch_.cells.end(), walk_cell);
  }
  std::for_each(watch_.loose_cells.begin(), watch_.loose_cells.end(), walk_cell);
}

void ScanRun::walkRegion(const CellRect& r)
{
  beams_->forEachTowards(r.min_x, r.min_y, r.max_x, r.max_y, [&](Beam& beam) {
    if (beam.end_is_point && r.contains(static_cast<int>(beam.end_x), static_cast<int>(beam.end_y)))
    {
      const std::uint32_t end = g_.getIndex(beam.end_x, beam.end_y);
      const std::uint8_t f = flags_->get(end);
      if ((f & kWatched) && !(f & kHit))  // an endpoint in a watched cell, at any range
      {
        note(end, kHit);
      }
    }
    const LineSteps& line = beam.line;
    const int a0 = static_cast<int>(line.x_major ? x0_ : y0_);
    const int b0 = static_cast<int>(line.x_major ? y0_ : x0_);
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
        const std::uint32_t index = line.x_major ? g_.getIndex(a, b) : g_.getIndex(b, a);
        if (flags_->get(index) & kWatched)
        {
          if (beam.own_steps == scan_detail::BeamIndex::kUnset)
          {
            beam.own_steps = ownDeepSteps(beam);
          }
          bool deep = false;
          if (static_cast<unsigned int>(i) < beam.own_steps)
          {
            if (beam.deep_steps == scan_detail::BeamIndex::kUnset)
            {
              beam.deep_steps = shadowDeepSteps(beam);
            }
            deep = static_cast<unsigned int>(i) < beam.deep_steps;
          }
          note(index, deep ? kVisitedDeep : kVisitedShallow);
        }
      }
      // Without a branch: whether b moves is data, and a branch on it mispredicts on most slopes.
      error += line.abs_db;
      const bool carry = error >= line.abs_da;
      error -= carry ? line.abs_da : 0;
      carries += carry;
    }
  });
}

void ScanRun::readBack()
{
  // Read the flags back, in index order (so the lists come out sorted), and leave the scratch as it was. A visited
  // cell that is lethal now was marked again by this scan: not seen free, as costmap_2d keeps it.
  std::sort(seen_cells_.begin(), seen_cells_.end());  // unique: a cell is added when it first gets a bit
  std::size_t hits = 0, passed = 0;  // sizes first: one allocation per list, none for an empty one
  for (std::uint32_t index : seen_cells_)
  {
    const std::uint8_t f = flags_->get(index);
    hits += (f & kHit) != 0;
    passed += (f & (kVisitedDeep | kVisitedShallow)) != 0;
  }
  touch_.watched_hit.reserve(hits);
  touch_.watched_cleared.reserve(passed);
  for (std::uint32_t index : seen_cells_)
  {
    const std::uint8_t f = flags_->get(index);
    flags_->clear(index, kSeen);
    if (f & kHit)
    {
      touch_.watched_hit.push_back(index);
    }
    if (!(f & (kVisitedDeep | kVisitedShallow)) || costs_[index] == LETHAL_OBSTACLE)
    {
      continue;  // only hit, or marked again
    }
    touch_.watched_cleared.push_back(index);
    if ((f & kVisitedDeep) && !(f & kHit))
    {
      touch_.watched_free.push_back(index);
    }
  }
}
}  // namespace

ScanTouch applyScan(CostGrid& grid, const Observation& observation, const ScanLimits& limits,
                    const ScanWatch& watch)
{
  return ScanRun(grid, observation, limits, watch).run();
}

}  // namespace sharing_layer
