#include "sharing_layer/sharing_core.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <unordered_set>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/scan_update.h"

namespace sharing_layer
{
namespace
{
constexpr double kInf = std::numeric_limits<double>::infinity();

WorldBounds emptyBounds()
{
  return WorldBounds{ kInf, kInf, -kInf, -kInf };
}
}  // namespace

void LayerParams::validate() const
{
  limits.validate();
  if (static_tolerance < 0)
  {
    throw std::invalid_argument("static_tolerance must be >= 0 cells, got " + std::to_string(static_tolerance));
  }
  if (!std::isfinite(trigger_debounce) || trigger_debounce < 0.0)
  {
    throw std::invalid_argument("trigger_debounce must be finite and >= 0 s, got " + std::to_string(trigger_debounce));
  }
  if (!std::isfinite(rectangle_padding) || rectangle_padding < 0.0)
  {
    throw std::invalid_argument("rectangle_padding must be finite and >= 0 m, got " +
                                std::to_string(rectangle_padding));
  }
  if (cluster_gap == 0 || cluster_gap > 50)
  {
    throw std::invalid_argument("cluster_gap must be 1..50 cells, got " + std::to_string(cluster_gap));
  }
  if (max_update_cells == 0)
  {
    throw std::invalid_argument("max_update_cells must be > 0");
  }
  if (robot_name.empty())
  {
    throw std::invalid_argument("robot_name must not be empty");
  }
  const auto check_non_negative = [](double value, const char* name, const char* unit) {
    if (!std::isfinite(value) || value < 0.0)
    {
      throw std::invalid_argument(std::string(name) + " must be finite and >= 0 " + unit + ", got " +
                                  std::to_string(value));
    }
  };
  check_non_negative(clearing_margin, "clearing_margin", "m");
  check_non_negative(trigger_memory, "trigger_memory", "s");
  check_non_negative(clearing_time, "clearing_time", "s");
  check_non_negative(trigger_radius, "trigger_radius", "m");
  check_non_negative(inscribed_radius, "inscribed_radius", "m");
  if (clearing_neighbours > 1000)
  {
    throw std::invalid_argument("clearing_neighbours must be 0..1000 beams, got " +
                                std::to_string(clearing_neighbours));
  }
  if (clearing_scans == 0 || clearing_scans > 1000)
  {
    throw std::invalid_argument("clearing_scans must be 1..1000 scans, got " + std::to_string(clearing_scans));
  }
  check_non_negative(lease_renewal_interval, "lease_renewal_interval", "s");
}

const char* triggerSourceName(TriggerSource source)
{
  switch (source)
  {
    case TriggerSource::StuckFeedback:
      return "stuck_feedback";
    case TriggerSource::RecoveryStatus:
      return "recovery_status";
    case TriggerSource::PlanBlocked:
      return "plan_blocked";
    case TriggerSource::Manual:
      return "manual";
  }
  return "unknown";
}

TriggerSource parseTriggerSource(const std::string& name)
{
  for (TriggerSource source : { TriggerSource::StuckFeedback, TriggerSource::RecoveryStatus,
                                TriggerSource::PlanBlocked, TriggerSource::Manual })
  {
    if (name == triggerSourceName(source))
    {
      return source;
    }
  }
  throw std::invalid_argument("trigger source must be stuck_feedback, recovery_status, plan_blocked or manual, got \"" +
                              name + "\"");
}

const char* triggerReasonName(TriggerReason reason)
{
  switch (reason)
  {
    case TriggerReason::None:
      return "none";
    case TriggerReason::Proposed:
      return "proposed";
    case TriggerReason::Debounced:
      return "debounced";
    case TriggerReason::NothingMarked:
      return "nothing_marked";
    case TriggerReason::OutOfRange:
      return "out_of_range";
    case TriggerReason::Static:
      return "static";
    case TriggerReason::AlreadyShared:
      return "already_shared";
    case TriggerReason::TooSmall:
      return "too_small";
    case TriggerReason::FleetRobot:
      return "fleet_robot";
  }
  return "unknown";
}

SharingCore::SharingCore(const GridGeometry& geometry, const LayerParams& params)
  : params_(params)
  , trigger_(params.trigger_debounce)
  , plan_trigger_(params.trigger_debounce)
  , dirty_(emptyBounds())
  , fleet_robots_(geometry)
{
  last_origin_x_ = last_origin_y_ = std::numeric_limits<double>::quiet_NaN();
  params_.validate();
  obstacles_ = CostGrid(GridGeometry(geometry.resolution, geometry.origin_x, geometry.origin_y, geometry.size_x,
                                     geometry.size_y),
                        FREE_SPACE);
  monitored_.assign(geometry.cellCount());
  cell_flags_.assign(geometry.cellCount(), 0);
}

std::size_t SharingCore::perCellBytes() const
{
  return cell_flags_.capacity() + monitored_.bytes() + static_occupied_.bytes() + static_unknown_.bytes() +
         static_filter_.gridBytes() + fleet_robots_.gridBytes();
}

void SharingCore::setStaticMap(const std::uint8_t* costs, std::size_t cost_count)
{
  // Validate (size) before keeping anything.
  StaticMapFilter check(geometry(), costs, cost_count, params_.static_tolerance, params_.static_occupied_cost);
  (void)check;
  setStaticSource(kStaticOccupied, [&](std::size_t i) { return costs[i] >= params_.static_occupied_cost; });
  rebuildStaticFilter();
}

template <class IsSet>
void SharingCore::setStaticSource(std::uint8_t bit, IsSet is_set)
{
  BitGrid& source = bit == kStaticOccupied ? static_occupied_ : static_unknown_;
  const std::size_t n = geometry().cellCount();
  source.assign(n);
  for (std::size_t i = 0; i < n; ++i)
  {
    if (is_set(i))
    {
      source.set(i);
    }
  }
  static_source_bits_ |= bit;
}

void SharingCore::setUnknownMap(const std::uint8_t* unknown, std::size_t cell_count)
{
  if (unknown == nullptr || cell_count == 0)
  {
    if (static_source_bits_ & kStaticUnknown)
    {
      static_unknown_.release();
      static_source_bits_ &= ~kStaticUnknown;
    }
  }
  else
  {
    if (cell_count != geometry().cellCount())
    {
      throw std::invalid_argument("setUnknownMap: unknown mask has " + std::to_string(cell_count) +
                                  " cells, the layer grid " + geometry().describe());
    }
    setStaticSource(kStaticUnknown, [&](std::size_t i) { return unknown[i] != 0; });
  }
  rebuildStaticFilter();
}

void SharingCore::rebuildStaticFilter()
{
  if (static_source_bits_ == 0)
  {
    static_filter_ = StaticMapFilter();
    return;
  }
  // Occupied or unknown (a byte per cell only while the filter is built).
  std::vector<std::uint8_t> blocked(geometry().cellCount(), 0);
  for (std::size_t i = 0; i < blocked.size(); ++i)
  {
    blocked[i] = (!static_occupied_.empty() && static_occupied_.test(i)) ||
                 (!static_unknown_.empty() && static_unknown_.test(i));
  }
  static_filter_ = StaticMapFilter(geometry(), blocked.data(), blocked.size(), params_.static_tolerance, 1);
  dropStaticCandidates();
}

void SharingCore::dropStaticCandidates()
{
  shareable_.erase(std::remove_if(shareable_.begin(), shareable_.end(),
                                  [&](std::uint32_t index) {
                                    const bool drop = static_filter_.isStatic(index);
                                    if (drop)
                                    {
                                      cell_flags_[index] &= ~kShareableFlag;
                                    }
                                    return drop;
                                  }),
                   shareable_.end());
  for (auto it = memory_.begin(); it != memory_.end();)
  {
    if (static_filter_.isStatic(it->first))
    {
      cell_flags_[it->first] &= ~kRememberedFlag;
      it = memory_.erase(it);
    }
    else
    {
      ++it;
    }
  }
}

void SharingCore::markMonitored(const CellRect& rect, bool monitored)
{
  const GridGeometry& g = geometry();
  for (int y = rect.min_y; y <= rect.max_y; ++y)
  {
    const std::size_t row = static_cast<std::size_t>(y) * g.size_x;
    for (int x = rect.min_x; x <= rect.max_x; ++x)
    {
      monitored_.set(row + static_cast<std::size_t>(x), monitored);
    }
  }
}

void SharingCore::unmarkMonitored(const CellRect& rect)
{
  // Rectangles overlap: unmark the area, then mark again what the others still cover of it.
  markMonitored(rect, false);
  for (const auto& entry : shared_)
  {
    const CellRect& other = entry.second.rectangle_cells;
    const CellRect overlap{ std::max(rect.min_x, other.min_x), std::max(rect.min_y, other.min_y),
                            std::min(rect.max_x, other.max_x), std::min(rect.max_y, other.max_y) };
    if (!overlap.empty())
    {
      markMonitored(overlap, true);
    }
  }
}

ScanOutcome SharingCore::processScan(const Observation& observation, double now_s, const ScanLimits& limits)
{
  limits.validate();
  const GridGeometry& g = geometry();
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  const double view_radius = std::max(limits.obstacle_range, limits.raytrace_range);
  const bool origin_finite = std::isfinite(ox) && std::isfinite(oy);
  fleet_robots_.expire(now_s);

  // Only obstacles this scan can reach are monitored; the rest cost one distance test each. Their present
  // cells and the remembered cells in reach are watched for evidence of free space.
  // (The temporaries of a scan live in buffers_, so that a scan does not allocate them again.)
  std::vector<SharedObstacle*>& in_view = buffers_.in_view;
  in_view.clear();
  ScanWatch& watch = buffers_.watch;
  watch.cells.clear();
  watch.regions.clear();
  watch.loose_cells.clear();
  watch.free_margin = params_.clearing_margin;
  watch.free_neighbours = params_.clearing_neighbours;
  watch.scratch = cell_flags_.data();
  watch.scratch_size = cell_flags_.size();
  // The present cells stay flagged in cell_flags_ between scans (refreshed when they change); the boxes of those in
  // view are the watch's regions.
  refreshSharedFlags();
  if (origin_finite)
  {
    refreshViewIndex();
    for (const ViewEntry& entry : view_index_)  // contiguous: no walk through the map's nodes
    {
      if (entry.rectangle.withinRadius(ox, oy, view_radius))
      {
        in_view.push_back(entry.obstacle);
        if (!entry.obstacle->present_box.empty())
        {
          watch.regions.push_back(entry.obstacle->present_box);
        }
      }
    }
  }
  if (!memory_.empty())
  {
    const double reach_sq = (view_radius + g.resolution) * (view_radius + g.resolution);
    for (auto it = memory_.begin(); it != memory_.end();)
    {
      const double age = now_s - it->second.time;
      if (!(age <= params_.trigger_memory) || age < 0.0)  // forgotten, or time went backwards (a restart)
      {
        cell_flags_[it->first] &= ~kRememberedFlag;
        it = memory_.erase(it);
        continue;
      }
      if (origin_finite)
      {
        unsigned int mx = 0, my = 0;
        g.indexToCells(it->first, mx, my);
        double wx = 0.0, wy = 0.0;
        g.mapToWorld(mx, my, wx, wy);
        if ((wx - ox) * (wx - ox) + (wy - oy) * (wy - oy) <= reach_sq)
        {
          // Scattered cells, mostly marked again by this very scan: walked one by one, and only if not.
          watch.loose_cells.push_back(it->first);
        }
      }
      ++it;
    }
  }

  // Cells this scan will mark that are not lethal now: the "newly marked" cells of the plan trigger. Also the
  // endpoints between obstacle_range and raytrace_range: the rest of a face whose middle the plan trigger fires
  // on (see checkPlan).
  std::vector<std::uint32_t>& not_lethal_before = buffers_.not_lethal_before;
  not_lethal_before.clear();
  last_far_hits_.clear();
  if (!plan_.empty() && limits.marking)  // a source that does not mark makes nothing new
  {
    const double sq_range = limits.obstacle_range * limits.obstacle_range;
    const double sq_far = limits.raytrace_range * limits.raytrace_range;
    const ScanLimits& l = limits;
    for (const Point3& p : observation.points)
    {
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < l.min_obstacle_height ||
          p.z > l.max_obstacle_height)
      {
        continue;
      }
      const double dz = p.z - observation.origin.z;
      const double d_sq = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + dz * dz;
      if (p.z > l.max_marking_height && d_sq < sq_range)
      {
        continue;  // cleared along, not marked
      }
      if (d_sq >= sq_range)
      {
        unsigned int mx = 0, my = 0;
        if (d_sq < sq_far && g.worldToMap(p.x, p.y, mx, my))
        {
          last_far_hits_.push_back(g.getIndex(mx, my));
        }
        continue;
      }
      unsigned int mx = 0, my = 0;
      if (g.worldToMap(p.x, p.y, mx, my) && obstacles_.getCost(mx, my) != LETHAL_OBSTACLE)
      {
        not_lethal_before.push_back(g.getIndex(mx, my));
      }
    }
  }

  ScanOutcome outcome;
  outcome.touch = applyScan(obstacles_, observation, limits, watch);
  trackShareable(outcome.touch, observation, limits.obstacle_range);
  // Signs of occupancy among the watched cells: marked, an endpoint in it beyond obstacle_range, or cleared
  // by a beam that ended close behind it (the face it hit, or a neighbour it grazed).
  std::vector<std::uint32_t>& occupied = buffers_.occupied;
  occupied.clear();
  {
    // Every list is sorted: merged, not sorted again.
    const ScanTouch& t = outcome.touch;
    std::vector<std::uint32_t>& grazed = buffers_.grazed;
    std::vector<std::uint32_t>& marked_known = buffers_.marked_known;
    grazed.clear();
    marked_known.clear();
    std::set_difference(t.watched_cleared.begin(), t.watched_cleared.end(), t.watched_free.begin(),
                        t.watched_free.end(), std::back_inserter(grazed));
    for (std::uint32_t index : t.marked)
    {
      if (insideMonitoredRectangle(index) || (cell_flags_[index] & kRememberedFlag))
      {
        marked_known.push_back(index);
      }
    }
    std::vector<std::uint32_t>& signs = buffers_.signs;
    signs.clear();
    std::set_union(grazed.begin(), grazed.end(), t.watched_hit.begin(), t.watched_hit.end(), std::back_inserter(signs));
    std::set_union(signs.begin(), signs.end(), marked_known.begin(), marked_known.end(), std::back_inserter(occupied));
  }
  remember(outcome.touch, occupied, observation, now_s);
  last_scan_time_ = now_s;
  if (origin_finite)
  {
    last_origin_x_ = ox;
    last_origin_y_ = oy;
  }
  last_static_marked_ = 0;
  last_robot_marked_.clear();
  for (std::uint32_t index : outcome.touch.marked)
  {
    last_static_marked_ += static_filter_.isStatic(index);
    if (fleet_robots_.excludes(index) && !static_filter_.isStatic(index))
    {
      last_robot_marked_.push_back(index);
    }
  }
  last_new_marked_.clear();
  for (std::uint32_t index : not_lethal_before)
  {
    if (!static_filter_.isStatic(index))
    {
      last_new_marked_.push_back(index);
    }
  }
  std::sort(last_new_marked_.begin(), last_new_marked_.end());
  last_new_marked_.erase(std::unique(last_new_marked_.begin(), last_new_marked_.end()), last_new_marked_.end());

  if (in_view.empty())
  {
    return outcome;
  }
  std::vector<std::uint32_t>& marked_watched = buffers_.marked_watched;
  marked_watched.clear();
  for (std::uint32_t index : outcome.touch.marked)
  {
    if (insideMonitoredRectangle(index))
    {
      marked_watched.push_back(index);
    }
  }
  const std::vector<std::uint32_t>& seen_free = outcome.touch.watched_free;
  std::vector<std::uint32_t>& seen_again = buffers_.seen_again;  // present cells this scan marked: an observation
  std::vector<std::uint32_t>& steady = buffers_.steady;
  steadyShareable(steady);  // growth candidates, computed once per scan
  std::vector<std::uint32_t>& steady_all = buffers_.steady_all;  // to reset their flags
  steady_all.assign(steady.begin(), steady.end());
  // Growth candidates lie within obstacle_range of the robot, most obstacles in view far beyond: their box
  // rules those out without looking at their rings.
  CellRect steady_box{ std::numeric_limits<int>::max(), std::numeric_limits<int>::max(),
                       std::numeric_limits<int>::min(), std::numeric_limits<int>::min() };
  for (std::uint32_t index : steady)
  {
    const int x = static_cast<int>(index % g.size_x), y = static_cast<int>(index / g.size_x);
    steady_box = CellRect{ std::min(steady_box.min_x, x), std::min(steady_box.min_y, y),
                           std::max(steady_box.max_x, x), std::max(steady_box.max_y, y) };
  }
  // Calls f(index) for the cells of a sorted list inside rectangle r, in order. One search per list and
  // rectangle: the cells between its first and last row that lie outside its columns are few (the lists hold
  // this scan's events, not the grid).
  const auto for_each_in = [&g](const std::vector<std::uint32_t>& sorted, const CellRect& r, auto f) {
    const std::uint32_t first = g.getIndex(static_cast<unsigned int>(r.min_x), static_cast<unsigned int>(r.min_y));
    const std::uint32_t last = g.getIndex(static_cast<unsigned int>(r.max_x), static_cast<unsigned int>(r.max_y));
    for (auto it = std::lower_bound(sorted.begin(), sorted.end(), first); it != sorted.end() && *it <= last; ++it)
    {
      const int x = static_cast<int>(*it % g.size_x);
      if (x >= r.min_x && x <= r.max_x)
      {
        f(*it);
      }
    }
  };
  std::vector<std::uint32_t>& marked = buffers_.marked;  // of one obstacle; most obstacles in view get neither
  std::vector<std::uint32_t>& cleared = buffers_.cleared;
  for (SharedObstacle* obstacle : in_view)
  {
    const CellRect& r = obstacle->rectangle_cells;
    marked.clear();
    cleared.clear();
    seen_again.clear();
    for_each_in(marked_watched, r, [&](std::uint32_t index) {
      // Walls, and a fleet robot standing on the cell: neither new cells nor an observation of the obstacle.
      if (!static_filter_.isStatic(index) && !fleet_robots_.excludes(index))
      {
        (obstacle->cells.isPresent(index) ? seen_again : marked).push_back(index);
      }
    });
    // A sign of occupancy: the evidence of free space starts again.
    if (!obstacle->free_streaks.empty())
    {
      for_each_in(occupied, r, [&](std::uint32_t index) { obstacle->free_streaks.erase(index); });
    }
    // Evidence of free space: a beam through the cell ending well beyond it. One scan is not enough (a beam
    // grazing along a face through the free part of its cells, localisation jitter): an unbroken streak of
    // clearing_scans scans over clearing_time clears the cell. (occupied and seen_free share no cell.)
    for_each_in(seen_free, r, [&](std::uint32_t index) {
      if (obstacle->cells.isPresent(index) &&
          obstacle->free_streaks[index].add(now_s, params_.clearing_scans, params_.clearing_time))
      {
        obstacle->free_streaks.erase(index);
        cleared.push_back(index);
      }
    });
    const int gap = static_cast<int>(params_.cluster_gap);
    if (!steady.empty() && r.min_x - gap <= steady_box.max_x && steady_box.min_x <= r.max_x + gap &&
        r.min_y - gap <= steady_box.max_y && steady_box.min_y <= r.max_y + gap)
    {
      growInto(*obstacle, steady, marked);
    }
    // Lease: cells seen occupied again renew the obstacle; sent when nobody renewed it for a while.
    if (marked.empty() && !seen_again.empty() &&
        !(now_s - obstacle->last_observation < params_.lease_renewal_interval))
    {
      marked = seen_again;
    }
    if (marked.empty() && cleared.empty())
    {
      continue;
    }
    if (!marked.empty())
    {
      obstacle->last_observation = now_s;
    }
    ObstacleUpdate update;
    update.marked = std::move(marked);  // (cleared again for the next obstacle)
    update.cleared = std::move(cleared);
    update.uuid = obstacle->uuid;
    update.deadline = obstacle->deadline;
    update.rectangle = obstacle->rectangle;
    update.source = params_.robot_name;
    update.geometry = g;
    update.version = obstacle->max_version + 1;
    update.stamp = now_s;
    obstacle->max_version = update.version;
    shared_flags_stale_ |= obstacle->cells.apply(update.marked, update.cleared, update.version, update.source) != 0;
    markDirty(update.marked);
    markDirty(update.cleared);
    outcome.updates.push_back(std::move(update));
  }
  for (std::uint32_t index : steady_all)
  {
    cell_flags_[index] &= ~kSteadyFlag;
  }
  return outcome;
}

void SharingCore::remember(const ScanTouch& touch, const std::vector<std::uint32_t>& occupied,
                           const Observation& observation, double now_s)
{
  if (params_.trigger_memory <= 0.0 || !std::isfinite(now_s))
  {
    return;
  }
  // Remembered cells leave on the same evidence as shared ones, not on costmap clearing: a robot backing off
  // clears a block's face with beams that end on it past obstacle_range.
  for (std::uint32_t index : occupied)
  {
    const auto found = findRemembered(index);
    if (found != memory_.end())
    {
      found->second.free.reset();
    }
  }
  for (std::uint32_t index : touch.watched_free)
  {
    const auto found = findRemembered(index);
    if (found != memory_.end())
    {
      if (found->second.free.add(now_s, params_.clearing_scans, params_.clearing_time))
      {
        cell_flags_[index] &= ~kRememberedFlag;
        memory_.erase(found);
      }
    }
  }
  for (std::uint32_t index : touch.watched_cleared)
  {
    const auto found = findRemembered(index);
    if (found != memory_.end())
    {
      found->second.marks = 0;  // a beam passed through it: not marked steadily
    }
  }
  const float sx = static_cast<float>(observation.origin.x);
  const float sy = static_cast<float>(observation.origin.y);
  for (std::uint32_t index : touch.marked)
  {
    // A cell marked on a fleet robot is not remembered: its trail must not be proposed once it drove on.
    if (!static_filter_.isStatic(index) && !fleet_robots_.excludes(index))
    {
      RememberedCell& cell = memory_[index];
      cell_flags_[index] |= kRememberedFlag;
      if (cell.marks == 0)
      {
        cell.marked_since = now_s;
      }
      cell.marks = static_cast<std::uint16_t>(std::min<int>(cell.marks + 1, 0xFFFF));
      cell.time = now_s;
      cell.sensor_x = sx;
      cell.sensor_y = sy;
      cell.free.reset();
    }
  }
}

void SharingCore::trackShareable(const ScanTouch& touch, const Observation& observation, double obstacle_range)
{
  for (std::uint32_t index : touch.marked)
  {
    // Cells marked on a fleet robot do not become shareable (nor stay so when it drives on); an obstacle
    // beside it becomes shareable with the next scan that marks it after the robot left.
    if (!(cell_flags_[index] & kShareableFlag) && !static_filter_.isStatic(index) && !insideMonitoredRectangle(index) &&
        !fleet_robots_.excludes(index))
    {
      cell_flags_[index] |= kShareableFlag;
      shareable_.push_back(index);
    }
  }
  const GridGeometry& g = geometry();
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  const double range_sq = obstacle_range * obstacle_range;
  const bool origin_finite = std::isfinite(ox) && std::isfinite(oy);
  const std::uint8_t* costs = obstacles_.data();
  auto keep_end = std::remove_if(shareable_.begin(), shareable_.end(), [&](std::uint32_t index) {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    // Dropped when raytracing cleared it, or when it left obstacle_range.
    const bool drop = costs[index] != LETHAL_OBSTACLE ||
                      (origin_finite && (wx - ox) * (wx - ox) + (wy - oy) * (wy - oy) >= range_sq);
    if (drop)
    {
      cell_flags_[index] &= ~kShareableFlag;
    }
    return drop;
  });
  shareable_.erase(keep_end, shareable_.end());
}

std::vector<std::uint32_t> SharingCore::candidates(double robot_x, double robot_y, bool use_memory,
                                                   bool with_robots) const
{
  std::vector<std::uint32_t> cells;
  cells.reserve(shareable_.size());
  for (std::uint32_t index : shareable_)
  {
    if (with_robots || !fleet_robots_.excludes(index))
    {
      cells.push_back(index);
    }
  }
  if (use_memory && !memory_.empty() && std::isfinite(robot_x) && std::isfinite(robot_y))
  {
    const GridGeometry& g = geometry();
    const double radius_sq = params_.trigger_radius * params_.trigger_radius;
    const double range_sq = params_.limits.obstacle_range * params_.limits.obstacle_range;
    const bool have_origin = std::isfinite(last_origin_x_) && std::isfinite(last_origin_y_);
    for (const auto& entry : memory_)
    {
      const std::uint32_t index = entry.first;
      if ((cell_flags_[index] & kShareableFlag) || insideMonitoredRectangle(index) || static_filter_.isStatic(index) ||
          (!with_robots && fleet_robots_.excludes(index)))
      {
        continue;
      }
      unsigned int mx = 0, my = 0;
      g.indexToCells(index, mx, my);
      double wx = 0.0, wy = 0.0;
      g.mapToWorld(mx, my, wx, wy);
      const double sensor_sq = have_origin ? (wx - last_origin_x_) * (wx - last_origin_x_) +
                                                 (wy - last_origin_y_) * (wy - last_origin_y_)
                                           : kInf;
      if ((wx - robot_x) * (wx - robot_x) + (wy - robot_y) * (wy - robot_y) <= radius_sq && sensor_sq >= range_sq)
      {
        cells.push_back(index);
      }
    }
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}

std::vector<Proposal> SharingCore::group(const std::vector<std::uint32_t>& cells, double robot_x,
                                         double robot_y) const
{
  if (cells.empty())
  {
    return {};
  }
  if (params_.strategy == ProposalStrategy::Clusters)
  {
    return proposeByClusters(geometry(), cells, params_.cluster_gap, params_.min_cluster_cells,
                             params_.rectangle_padding);
  }
  return proposeBySectors(geometry(), cells, robot_x, robot_y, params_.rectangle_padding);
}

std::vector<Proposal> SharingCore::propose(double robot_x, double robot_y, bool use_memory) const
{
  return group(candidates(robot_x, robot_y, use_memory), robot_x, robot_y);
}

namespace
{
/// printf-style formatting of up to two doubles (a format using one ignores the second)
std::string format(const char* fmt, double a, double b)
{
  char buf[256];
  std::snprintf(buf, sizeof(buf), fmt, a, b);
  return buf;
}

std::string describeProposals(const std::vector<Proposal>& proposals)
{
  std::string out = "proposed " + std::to_string(proposals.size()) + " obstacle(s): ";
  for (std::size_t i = 0; i < proposals.size(); ++i)
  {
    out += (i ? "; " : "") + std::to_string(proposals[i].cells.size()) + " cells in " +
           proposals[i].rectangle.describe();
  }
  return out;
}
}  // namespace

void SharingCore::explainNothing(TriggerReport& report, double robot_x, double robot_y, bool use_memory) const
{
  const GridGeometry& g = geometry();
  std::size_t near = 0, near_shared = 0, far = 0;
  double nearest = kInf;
  for (const auto& entry : memory_)
  {
    if (static_filter_.isStatic(entry.first))
    {
      continue;
    }
    unsigned int mx = 0, my = 0;
    g.indexToCells(entry.first, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    const double d = std::hypot(wx - robot_x, wy - robot_y);
    if (d <= params_.trigger_radius)
    {
      ++near;
      near_shared += insideMonitoredRectangle(entry.first);
    }
    else
    {
      ++far;
      nearest = std::min(nearest, d);
    }
  }
  // Cells on fleet robots are neither shareable nor remembered: the last scan's marks on them explain it.
  std::vector<std::uint32_t> with_robots = candidates(robot_x, robot_y, use_memory, true);
  with_robots.insert(with_robots.end(), last_robot_marked_.begin(), last_robot_marked_.end());
  if (!with_robots.empty() && candidates(robot_x, robot_y, use_memory).empty())
  {
    std::vector<std::string> names;
    for (std::uint32_t index : with_robots)
    {
      for (std::string& name : fleet_robots_.robotsAt(index))
      {
        names.push_back(std::move(name));
      }
    }
    std::sort(names.begin(), names.end());
    names.erase(std::unique(names.begin(), names.end()), names.end());
    std::string list;
    for (const std::string& name : names)
    {
      list += (list.empty() ? "" : ", ") + name;
    }
    report.reason = TriggerReason::FleetRobot;
    report.message += "nothing proposed: the cells marked near the robot lie within the footprint of fleet "
                      "robot(s) " + list +
                      format(" (plus robot_exclusion_margin %.2f m)", fleet_robots_.params().margin, 0.0);
  }
  else if (!use_memory && candidates(robot_x, robot_y, true).size() > shareable_.size())
  {
    report.reason = TriggerReason::OutOfRange;
    report.message += format("nothing proposed: the recently marked cells near the robot lie beyond obstacle_range "
                             "%.2f m of the current view, and ",
                             params_.limits.obstacle_range, 0.0);
    report.message += std::string(triggerSourceName(report.source)) +
                      " does not use the trigger memory (memory_on_stuck_feedback)";
  }
  else if (!candidates(robot_x, robot_y, use_memory).empty())
  {
    report.reason = TriggerReason::TooSmall;
    report.message += "nothing proposed: the candidate cells form groups smaller than min_cluster_cells " +
                      std::to_string(params_.min_cluster_cells);
  }
  else if (near_shared > 0)
  {
    report.reason = TriggerReason::AlreadyShared;
    report.message += "nothing proposed: " + std::to_string(near_shared) + " of the " + std::to_string(near) +
                      " recently marked cell(s) near the robot lie in obstacles already shared, the rest were "
                      "seen free since";
  }
  else if (far > 0 && near == 0)
  {
    report.reason = TriggerReason::OutOfRange;
    report.message += "nothing proposed: " + std::to_string(far) + " recently marked cell(s), " +
                      format("the nearest %.2f m away, beyond trigger_radius %.2f m", nearest,
                             params_.trigger_radius);
  }
  else if (near > 0)
  {
    report.reason = TriggerReason::NothingMarked;
    report.message += "nothing proposed: the " + std::to_string(near) +
                      " recently marked cell(s) near the robot were seen free since";
  }
  else if (last_static_marked_ > 0)
  {
    report.reason = TriggerReason::Static;
    report.message += "nothing proposed: the " + std::to_string(last_static_marked_) +
                      " cell(s) the last scan marked are all static (within static_tolerance " +
                      std::to_string(params_.static_tolerance) + " cells of a wall or unknown map area)";
  }
  else
  {
    report.reason = TriggerReason::NothingMarked;
    report.message += format("nothing proposed: no new cell marked within obstacle_range %.2f m in the last "
                             "trigger_memory %.1f s",
                             params_.limits.obstacle_range, params_.trigger_memory);
  }
}

TriggerReport SharingCore::trigger(TriggerSource source, double now_s, double robot_x, double robot_y)
{
  TriggerReport report;
  report.source = source;
  report.log = true;
  report.message = std::string(triggerSourceName(source)) + " trigger at " + format("(%.2f, %.2f): ", robot_x, robot_y);
  if (!std::isfinite(now_s) || !std::isfinite(robot_x) || !std::isfinite(robot_y))
  {
    report.message += "ignored: time or robot pose not finite";
    return report;
  }
  fleet_robots_.expire(now_s);
  if (!trigger_.signal(now_s))
  {
    report.reason = TriggerReason::Debounced;
    report.log = trigger_.burstSignals() == 2;  // once per burst
    report.message += format("debounced: less than trigger_debounce %.1f s after the previous signal (further "
                             "signals of this burst are not logged)",
                             params_.trigger_debounce, 0.0);
    return report;
  }
  const bool use_memory = source == TriggerSource::RecoveryStatus || source == TriggerSource::Manual ||
                          (source == TriggerSource::StuckFeedback && params_.memory_on_stuck_feedback);
  report.proposals = propose(robot_x, robot_y, use_memory);
  if (!report.proposals.empty())
  {
    report.reason = TriggerReason::Proposed;
    report.message += describeProposals(report.proposals);
    return report;
  }
  explainNothing(report, robot_x, robot_y, use_memory);
  return report;
}

void SharingCore::setPlan(const std::vector<std::pair<double, double>>& poses)
{
  plan_.clear();
  plan_.reserve(poses.size());
  for (const auto& pose : poses)
  {
    if (std::isfinite(pose.first) && std::isfinite(pose.second))
    {
      plan_.push_back(pose);
    }
  }
  if (plan_.empty())
  {
    last_new_marked_.clear();
    last_far_hits_.clear();
  }
}

std::vector<std::size_t> SharingCore::planAhead(double robot_x, double robot_y, double reach) const
{
  std::size_t nearest = 0;
  double best = kInf;
  for (std::size_t i = 0; i < plan_.size(); ++i)
  {
    const double d = (plan_[i].first - robot_x) * (plan_[i].first - robot_x) +
                     (plan_[i].second - robot_y) * (plan_[i].second - robot_y);
    if (d < best)
    {
      best = d;
      nearest = i;
    }
  }
  std::vector<std::size_t> ahead;
  const double reach_sq = reach * reach;
  for (std::size_t i = nearest; i < plan_.size(); ++i)
  {
    const double d = (plan_[i].first - robot_x) * (plan_[i].first - robot_x) +
                     (plan_[i].second - robot_y) * (plan_[i].second - robot_y);
    // A segment is kept when either end is in reach, so a sparse plan keeps its segments near the robot.
    const bool next_in_reach =
        i + 1 < plan_.size() && (plan_[i + 1].first - robot_x) * (plan_[i + 1].first - robot_x) +
                                        (plan_[i + 1].second - robot_y) * (plan_[i + 1].second - robot_y) <=
                                    reach_sq;
    if (d <= reach_sq || next_in_reach)
    {
      ahead.push_back(i);
    }
  }
  return ahead;
}

bool SharingCore::nearPlan(std::uint32_t index, const std::vector<std::size_t>& ahead) const
{
  const GridGeometry& g = geometry();
  unsigned int mx = 0, my = 0;
  g.indexToCells(index, mx, my);
  double px = 0.0, py = 0.0;
  g.mapToWorld(mx, my, px, py);
  const double r_sq = params_.inscribed_radius * params_.inscribed_radius;
  for (std::size_t i : ahead)
  {
    const double ax = plan_[i].first, ay = plan_[i].second;
    double bx = ax, by = ay;
    if (i + 1 < plan_.size())
    {
      bx = plan_[i + 1].first;
      by = plan_[i + 1].second;
    }
    // Distance from the cell centre to the segment between this pose and the next.
    const double vx = bx - ax, vy = by - ay;
    const double len_sq = vx * vx + vy * vy;
    double t = len_sq > 0.0 ? ((px - ax) * vx + (py - ay) * vy) / len_sq : 0.0;
    t = std::min(1.0, std::max(0.0, t));
    const double dx = ax + t * vx - px, dy = ay + t * vy - py;
    if (dx * dx + dy * dy <= r_sq)
    {
      return true;
    }
  }
  return false;
}

TriggerReport SharingCore::checkPlan(double robot_x, double robot_y, double now_s)
{
  TriggerReport report;
  report.source = TriggerSource::PlanBlocked;
  if (plan_.empty() || last_new_marked_.empty() || !std::isfinite(robot_x) || !std::isfinite(robot_y) ||
      !std::isfinite(now_s))
  {
    return report;
  }
  fleet_robots_.expire(now_s);
  const std::vector<std::size_t> ahead =
      planAhead(robot_x, robot_y, params_.limits.obstacle_range + params_.inscribed_radius);
  if (ahead.empty())
  {
    return report;
  }
  const GridGeometry& g = geometry();
  // obstacle_range counts from the laser that marked the cells: a laser ahead of the robot's centre
  // marks a cell first at obstacle_range from itself, and once marked the cell is no longer new.
  const bool laser_known = std::isfinite(last_origin_x_) && std::isfinite(last_origin_y_);
  const double from_x = laser_known ? last_origin_x_ : robot_x;
  const double from_y = laser_known ? last_origin_y_ : robot_y;
  const double reach = params_.limits.obstacle_range + 0.5 * g.resolution * std::sqrt(2.0);
  const double range_sq = reach * reach;
  std::size_t blocking = 0, blocking_shared = 0;
  for (std::uint32_t index : last_new_marked_)
  {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    if ((wx - from_x) * (wx - from_x) + (wy - from_y) * (wy - from_y) > range_sq || !nearPlan(index, ahead) ||
        fleet_robots_.excludes(index))  // a fleet robot on the plan is not an obstacle to share
    {
      continue;
    }
    ++blocking;
    blocking_shared += insideMonitoredRectangle(index);
  }
  if (blocking == 0)
  {
    return report;
  }
  report.log = true;
  report.message = "plan_blocked trigger at " + format("(%.2f, %.2f): ", robot_x, robot_y) +
                   std::to_string(blocking) + " newly marked cell(s) on the plan ahead; ";
  if (!plan_trigger_.signal(now_s))
  {
    report.reason = TriggerReason::Debounced;
    report.log = plan_trigger_.burstSignals() == 2;
    report.message += format("debounced: less than trigger_debounce %.1f s after the previous one (further ones of "
                             "this burst are not logged)",
                             params_.trigger_debounce, 0.0);
    return report;
  }
  if (blocking_shared == blocking)
  {
    report.reason = TriggerReason::AlreadyShared;
    report.message += "nothing proposed: they lie in obstacles already shared";
    return report;
  }
  // The clusters of candidate cells that touch the plan ahead. The trigger fires on the first cells of a block
  // within obstacle_range, and navfn's detour may keep the robot from ever marking the rest of its face: the
  // endpoints the same scan saw beyond obstacle_range (within raytrace_range) join the clusters they touch,
  // so a corridor the block closes is closed for the peers too. Walls, unknown map cells, shared obstacles and
  // fleet robots stay out, as for marked cells.
  std::vector<std::uint32_t> cells = candidates(robot_x, robot_y, true);
  for (std::uint32_t index : last_far_hits_)
  {
    if (!static_filter_.isStatic(index) && !insideMonitoredRectangle(index) && !fleet_robots_.excludes(index))
    {
      cells.push_back(index);
    }
  }
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  for (Proposal& proposal : proposeByClusters(g, cells, params_.cluster_gap, params_.min_cluster_cells,
                                              params_.rectangle_padding))
  {
    if (std::any_of(proposal.cells.begin(), proposal.cells.end(),
                    [&](std::uint32_t index) { return nearPlan(index, ahead); }))
    {
      report.proposals.push_back(std::move(proposal));
    }
  }
  if (!report.proposals.empty())
  {
    report.reason = TriggerReason::Proposed;
    report.message += describeProposals(report.proposals);
    return report;
  }
  report.reason = TriggerReason::TooSmall;
  report.message += "nothing proposed: the cells on the plan form groups smaller than min_cluster_cells " +
                    std::to_string(params_.min_cluster_cells);
  return report;
}

void SharingCore::setInscribedRadius(double radius_m)
{
  LayerParams changed = params_;
  changed.inscribed_radius = radius_m;
  changed.validate();
  params_ = changed;
}

std::vector<std::uint32_t> SharingCore::rememberedCells() const
{
  std::vector<std::uint32_t> cells;
  cells.reserve(memory_.size());
  for (const auto& entry : memory_)
  {
    cells.push_back(entry.first);
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}

ApplyResult SharingCore::applyShared(const ObstacleUpdate& update, double now_s)
{
  ApplyResult result;
  const GridGeometry& g = geometry();
  if (update.uuid.empty())
  {
    result.error = "empty uuid";
    return result;
  }
  if (update.source.empty())
  {
    result.error = "obstacle " + update.uuid + ": empty source";
    return result;
  }
  if (!update.geometry.sameAs(g))
  {
    result.error = "obstacle " + update.uuid + " from " + update.source + ": grid " + update.geometry.describe() +
                   " differs from ours, " + g.describe();
    return result;
  }
  if (update.marked.size() + update.cleared.size() > params_.max_update_cells)
  {
    result.error = "obstacle " + update.uuid + " from " + update.source + ": " +
                   std::to_string(update.marked.size() + update.cleared.size()) + " cells exceed max_update_cells " +
                   std::to_string(params_.max_update_cells);
    return result;
  }
  for (const auto* list : { &update.marked, &update.cleared })
  {
    for (std::uint32_t index : *list)
    {
      if (!g.containsIndex(index))
      {
        result.error = "obstacle " + update.uuid + " from " + update.source + ": index " + std::to_string(index) +
                       " outside the " + std::to_string(g.cellCount()) + "-cell grid";
        return result;
      }
    }
  }
  if (update.version == 0)
  {
    result.error = "obstacle " + update.uuid + " from " + update.source + ": version 0 (a proposal, not authorised)";
    return result;
  }
  // Re-validate the rectangle: a value built without the checking constructor could still be bad.
  try
  {
    Subsection(update.rectangle.min_x, update.rectangle.min_y, update.rectangle.max_x, update.rectangle.max_y);
  }
  catch (const std::invalid_argument& e)
  {
    result.error = "obstacle " + update.uuid + " from " + update.source + ": " + e.what();
    return result;
  }

  auto found = shared_.find(update.uuid);
  if (found == shared_.end())
  {
    if (update.deadline == 0)
    {
      result.error = "obstacle " + update.uuid + " from " + update.source + ": deadline 0";
      return result;
    }
    SharedObstacle obstacle;
    obstacle.uuid = update.uuid;
    obstacle.rectangle = update.rectangle;
    obstacle.rectangle_cells = update.rectangle.cells(g);
    obstacle.deadline = update.deadline;
    obstacle.creator = update.source;
    obstacle.arrival_time = now_s;
    obstacle.last_observation = now_s;
    found = shared_.emplace(update.uuid, std::move(obstacle)).first;
    result.added = true;
    view_index_stale_ = true;
    markMonitored(found->second.rectangle_cells, true);
    dropShareableInside(found->second.rectangle_cells);
  }
  SharedObstacle& obstacle = found->second;
  growRectangle(obstacle, update.rectangle);
  if (!update.marked.empty())
  {
    obstacle.last_observation = now_s;
  }
  obstacle.max_version = std::max(obstacle.max_version, update.version);
  result.changed = obstacle.cells.apply(update.marked, update.cleared, update.version, update.source);
  shared_flags_stale_ |= result.changed != 0;
  for (std::uint32_t index : update.marked)
  {
    obstacle.free_streaks.erase(index);  // a robot saw it occupied: evidence of free space starts again
  }
  markDirty(update.marked);
  markDirty(update.cleared);
  result.ok = true;
  return result;
}

void SharingCore::refreshViewIndex()
{
  if (!view_index_stale_)
  {
    return;
  }
  view_index_.clear();
  for (auto& entry : shared_)
  {
    SharedObstacle& obstacle = entry.second;
    if (!obstacle.rectangle_cells.empty())
    {
      view_index_.push_back(ViewEntry{ obstacle.rectangle, &obstacle });
    }
  }
  view_index_stale_ = false;
}

void SharingCore::refreshSharedFlags()
{
  static_assert(((kSteadyFlag | kRememberedFlag | kShareableFlag) & ~ScanWatch::kOwnerBits) == 0,
                "the core's own cell flags must be owner bits of the scan's scratch");
  if (!shared_flags_stale_)
  {
    return;
  }
  for (std::uint32_t index : flagged_cells_)
  {
    cell_flags_[index] &= ~ScanWatch::kFlaggedWatched;
  }
  flagged_cells_.clear();
  const GridGeometry& g = geometry();
  for (auto& entry : shared_)
  {
    SharedObstacle& obstacle = entry.second;
    const std::vector<std::uint32_t>& present = obstacle.cells.present();
    obstacle.present_box = CellRect{ 0, 0, -1, -1 };
    if (present.empty())
    {
      continue;
    }
    // Sorted: the first and last cells give the rows.
    CellRect box{ std::numeric_limits<int>::max(), static_cast<int>(present.front() / g.size_x),
                  std::numeric_limits<int>::min(), static_cast<int>(present.back() / g.size_x) };
    for (std::uint32_t index : present)
    {
      const int x = static_cast<int>(index % g.size_x);
      box.min_x = std::min(box.min_x, x);
      box.max_x = std::max(box.max_x, x);
      cell_flags_[index] |= ScanWatch::kFlaggedWatched;
    }
    flagged_cells_.insert(flagged_cells_.end(), present.begin(), present.end());
    obstacle.present_box = box;
  }
  shared_flags_stale_ = false;
}

void SharingCore::steadyShareable(std::vector<std::uint32_t>& steady)
{
  steady.clear();
  for (std::uint32_t index : shareable_)
  {
    const auto found = findRemembered(index);
    if (found != memory_.end() && found->second.marks >= params_.clearing_scans &&
        found->second.time - found->second.marked_since >= params_.clearing_time)
    {
      steady.push_back(index);
      cell_flags_[index] |= kSteadyFlag;
    }
  }
}

bool SharingCore::steadyInRing(const CellRect& r, int gap) const
{
  const GridGeometry& g = geometry();
  const int x0 = std::max(0, r.min_x - gap), x1 = std::min(static_cast<int>(g.size_x) - 1, r.max_x + gap);
  const int y0 = std::max(0, r.min_y - gap), y1 = std::min(static_cast<int>(g.size_y) - 1, r.max_y + gap);
  for (int y = y0; y <= y1; ++y)
  {
    const std::uint8_t* row = cell_flags_.data() + static_cast<std::size_t>(y) * g.size_x;
    auto any = [&](int from, int to) {
      return std::any_of(row + from, row + to + 1, [](std::uint8_t f) { return (f & kSteadyFlag) != 0; });
    };
    if (y < r.min_y || y > r.max_y ? any(x0, x1)
                                   : (x0 <= r.min_x - 1 && any(x0, r.min_x - 1)) || (r.max_x + 1 <= x1 && any(r.max_x + 1, x1)))
    {
      return true;
    }
  }
  return false;
}

void SharingCore::growInto(SharedObstacle& obstacle, std::vector<std::uint32_t>& steady,
                           std::vector<std::uint32_t>& marked)
{
  if (steady.empty() || obstacle.cells.presentCount() == 0)
  {
    return;
  }
  const GridGeometry& g = geometry();
  const int gap = static_cast<int>(params_.cluster_gap);
  // A candidate touching the obstacle lies in the ring of width cluster_gap around its rectangle (cells inside
  // are monitored, never shareable): most obstacles in view have none there.
  if (!steadyInRing(obstacle.rectangle_cells, gap))
  {
    return;
  }
  std::unordered_set<std::uint32_t> grown_set;
  std::vector<std::uint32_t> grown;
  auto touches = [&](std::uint32_t index) {
    const long mx = static_cast<long>(index % g.size_x), my = static_cast<long>(index / g.size_x);
    for (int dy = -gap; dy <= gap; ++dy)
    {
      for (int dx = -gap; dx <= gap; ++dx)
      {
        const long x = mx + dx, y = my + dy;
        if ((dx == 0 && dy == 0) || x < 0 || y < 0 || x >= static_cast<long>(g.size_x) ||
            y >= static_cast<long>(g.size_y))
        {
          continue;
        }
        const std::uint32_t n = g.getIndex(static_cast<unsigned int>(x), static_cast<unsigned int>(y));
        if (obstacle.cells.isPresent(n) || grown_set.count(n) != 0)
        {
          return true;
        }
      }
    }
    return false;
  };
  // Chains: a cell touching one just taken is taken too, until nothing more touches. A cell taken here is
  // this obstacle's: it leaves `steady` for the obstacles after it.
  for (bool taken = true; taken;)
  {
    taken = false;
    for (auto it = steady.begin(); it != steady.end();)
    {
      if (touches(*it))
      {
        grown.push_back(*it);
        grown_set.insert(*it);
        it = steady.erase(it);
        taken = true;
      }
      else
      {
        ++it;
      }
    }
  }
  if (grown.empty())
  {
    return;
  }
  double min_x = obstacle.rectangle.min_x, min_y = obstacle.rectangle.min_y;
  double max_x = obstacle.rectangle.max_x, max_y = obstacle.rectangle.max_y;
  for (std::uint32_t index : grown)
  {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double cx = 0.0, cy = 0.0;
    g.mapToWorld(mx, my, cx, cy);
    const double half = 0.5 * g.resolution;
    min_x = std::min(min_x, cx - half);
    min_y = std::min(min_y, cy - half);
    max_x = std::max(max_x, cx + half);
    max_y = std::max(max_y, cy + half);
  }
  growRectangle(obstacle, Subsection(min_x, min_y, max_x, max_y));
  marked.insert(marked.end(), grown.begin(), grown.end());
  std::sort(marked.begin(), marked.end());
  marked.erase(std::unique(marked.begin(), marked.end()), marked.end());
}

void SharingCore::growRectangle(SharedObstacle& obstacle, const Subsection& rectangle)
{
  const Subsection& r = obstacle.rectangle;
  if (rectangle.min_x >= r.min_x && rectangle.min_y >= r.min_y && rectangle.max_x <= r.max_x &&
      rectangle.max_y <= r.max_y)
  {
    return;
  }
  obstacle.rectangle = Subsection(std::min(r.min_x, rectangle.min_x), std::min(r.min_y, rectangle.min_y),
                                  std::max(r.max_x, rectangle.max_x), std::max(r.max_y, rectangle.max_y));
  obstacle.rectangle_cells = obstacle.rectangle.cells(geometry());
  markMonitored(obstacle.rectangle_cells, true);  // the grown rectangle holds the old one
  dropShareableInside(obstacle.rectangle_cells);
  view_index_stale_ = true;
}

void SharingCore::dropShareableInside(const CellRect& rect)
{
  const GridGeometry& g = geometry();
  shareable_.erase(std::remove_if(shareable_.begin(), shareable_.end(),
                                  [&](std::uint32_t index) {
                                    unsigned int mx = 0, my = 0;
                                    g.indexToCells(index, mx, my);
                                    const bool inside = rect.contains(static_cast<int>(mx), static_cast<int>(my));
                                    if (inside)
                                    {
                                      cell_flags_[index] &= ~kShareableFlag;
                                    }
                                    return inside;
                                  }),
                   shareable_.end());
}

bool SharingCore::expire(const std::string& uuid)
{
  const auto found = shared_.find(uuid);
  if (found == shared_.end())
  {
    return false;
  }
  markDirty(found->second.cells.present());
  const CellRect rectangle = found->second.rectangle_cells;
  shared_.erase(found);
  unmarkMonitored(rectangle);
  shared_flags_stale_ = true;
  view_index_stale_ = true;
  return true;
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

void SharingCore::useObstacleGrid(std::uint8_t* costs, std::uint8_t default_value)
{
  if (costs == nullptr)
  {
    throw std::invalid_argument("SharingCore::useObstacleGrid: no buffer for " + geometry().describe());
  }
  obstacles_ = CostGrid::view(geometry(), costs, default_value);
}

MoveReport SharingCore::moveTo(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                               std::uint8_t default_value)
{
  if (costs == nullptr)
  {
    throw std::invalid_argument("SharingCore::moveTo: no buffer for " + geometry.describe());
  }
  return moveGrid(geometry, keep_observations, costs, default_value);
}

MoveReport SharingCore::moveTo(const GridGeometry& geometry, bool keep_observations)
{
  return moveGrid(geometry, keep_observations, nullptr, FREE_SPACE);
}

MoveReport SharingCore::moveGrid(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                                 std::uint8_t default_value)
{
  const GridGeometry old = this->geometry();
  MoveReport report;
  // Where an old cell's centre lies on the new grid.
  const auto to_new = [&old, &geometry](std::uint32_t index, std::uint32_t& moved) {
    unsigned int mx = 0, my = 0;
    old.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    old.mapToWorld(mx, my, wx, wy);
    unsigned int nx = 0, ny = 0;
    if (!geometry.worldToMap(wx, wy, nx, ny))
    {
      return false;
    }
    moved = geometry.getIndex(nx, ny);
    return true;
  };

  // Allocate first: nothing changes when the new grid cannot be had. A caller's buffer holds the moved grid
  // already (the old one may be gone).
  CostGrid obstacles = costs != nullptr ? CostGrid::view(geometry, costs, default_value) : CostGrid(geometry, FREE_SPACE);
  std::vector<std::uint8_t> cell_flags(geometry.cellCount(), 0);

  std::vector<std::uint32_t> shareable;
  if (keep_observations)
  {
    if (costs != nullptr)
    {
      report.obstacle_cells_kept = static_cast<std::size_t>(
          std::count(obstacles.data(), obstacles.data() + geometry.cellCount(), LETHAL_OBSTACLE));
    }
    else
    {
      for (std::uint32_t index = 0; index < old.cellCount(); ++index)
      {
        std::uint32_t moved = 0;
        if (obstacles_.at(index) != FREE_SPACE && to_new(index, moved))
        {
          obstacles.set(moved, obstacles_.at(index));
          report.obstacle_cells_kept += obstacles_.at(index) == LETHAL_OBSTACLE;
        }
      }
    }
    for (std::uint32_t index : shareable_)
    {
      std::uint32_t moved = 0;
      if (to_new(index, moved) && !(cell_flags[moved] & kShareableFlag))
      {
        cell_flags[moved] |= kShareableFlag;
        shareable.push_back(moved);
      }
    }
    std::sort(shareable.begin(), shareable.end());
  }
  std::unordered_map<std::uint32_t, RememberedCell> memory;
  for (const auto& entry : memory_)
  {
    std::uint32_t moved = 0;
    if (to_new(entry.first, moved))
    {
      const auto found = memory.find(moved);
      if (found == memory.end() || found->second.time < entry.second.time)
      {
        memory[moved] = entry.second;
      }
    }
  }

  obstacles_ = std::move(obstacles);
  shareable_.swap(shareable);
  monitored_.assign(geometry.cellCount());  // marked below
  static_occupied_.release();                 // no static sources on the new grid (set again)
  static_unknown_.release();
  cell_flags_.swap(cell_flags);  // a fresh scratch: every present cell is flagged again at the next scan
  flagged_cells_.clear();
  shared_flags_stale_ = true;
  view_index_stale_ = true;
  memory_.swap(memory);
  for (const auto& entry : memory_)
  {
    cell_flags_[entry.first] |= kRememberedFlag;
  }
  static_source_bits_ = 0;
  static_filter_ = StaticMapFilter();
  fleet_robots_.setGeometry(geometry);
  last_new_marked_.clear();
  last_far_hits_.clear();
  last_robot_marked_.clear();
  last_static_marked_ = 0;
  dirty_ = emptyBounds();

  for (auto& entry : shared_)
  {
    SharedObstacle& obstacle = entry.second;
    report.shared_cells_dropped += obstacle.cells.remap(to_new);
    std::unordered_map<std::uint32_t, FreeStreak> streaks;
    for (const auto& streak : obstacle.free_streaks)
    {
      std::uint32_t moved = 0;
      if (to_new(streak.first, moved) && obstacle.cells.isPresent(moved))
      {
        streaks[moved] = streak.second;
      }
    }
    obstacle.free_streaks.swap(streaks);
    obstacle.rectangle_cells = obstacle.rectangle.cells(geometry);
    if (!obstacle.rectangle_cells.empty())
    {
      markMonitored(obstacle.rectangle_cells, true);
      dropShareableInside(obstacle.rectangle_cells);
    }
    report.obstacles_out_of_grid += obstacle.cells.presentCount() == 0;
    markDirty(obstacle.cells.present());
  }
  return report;
}

void SharingCore::resetObstacleLayer()
{
  obstacles_.reset();
  for (std::uint32_t index : shareable_)
  {
    cell_flags_[index] &= ~kShareableFlag;
  }
  shareable_.clear();
  // What the robot saw before the reset is forgotten with it (the trigger memory and the plan trigger's
  // newly marked cells); shared obstacles and their monitoring state stay.
  for (const auto& entry : memory_)
  {
    cell_flags_[entry.first] &= ~kRememberedFlag;
  }
  memory_.clear();
  last_new_marked_.clear();
  last_far_hits_.clear();
  last_static_marked_ = 0;
  last_robot_marked_.clear();
  last_origin_x_ = last_origin_y_ = std::numeric_limits<double>::quiet_NaN();
}

std::size_t SharingCore::clearObstaclesOutside(int x0, int y0, int x1, int y1)
{
  const GridGeometry& g = geometry();
  const std::uint8_t cleared_value = obstacles_.defaultValue();
  // The window is open on every side, as in costmap_2d: clearArea keeps x0 < x < x1, y0 < y < y1.
  auto inside = [&](unsigned int mx, unsigned int my) {
    return static_cast<long>(mx) > x0 && static_cast<long>(mx) < x1 && static_cast<long>(my) > y0 &&
           static_cast<long>(my) < y1;
  };
  std::size_t cleared = 0;
  for (unsigned int my = 0; my < g.size_y; ++my)
  {
    for (unsigned int mx = 0; mx < g.size_x; ++mx)
    {
      if (inside(mx, my))
      {
        continue;
      }
      const std::uint32_t index = g.getIndex(mx, my);
      if (obstacles_.at(index) != cleared_value)
      {
        cleared += obstacles_.at(index) == LETHAL_OBSTACLE ? 1 : 0;
        obstacles_.set(index, cleared_value);
      }
    }
  }
  std::vector<std::uint32_t> kept;
  kept.reserve(shareable_.size());
  for (std::uint32_t index : shareable_)
  {
    unsigned int mx, my;
    g.indexToCells(index, mx, my);
    if (inside(mx, my))
    {
      kept.push_back(index);
    }
    else
    {
      cell_flags_[index] &= ~kShareableFlag;
    }
  }
  shareable_.swap(kept);
  return cleared;
}

void SharingCore::drawShared(std::uint8_t* master, std::size_t cell_count) const
{
  if (cell_count != geometry().cellCount())
  {
    throw std::invalid_argument("drawShared: master grid has " + std::to_string(cell_count) + " cells, layer " +
                                geometry().describe());
  }
  for (const auto& entry : shared_)
  {
    for (std::uint32_t index : entry.second.cells.present())
    {
      master[index] = LETHAL_OBSTACLE;
    }
  }
}

WorldBounds SharingCore::takeDirtyBounds()
{
  const WorldBounds bounds = dirty_;
  dirty_ = emptyBounds();
  return bounds;
}

void SharingCore::markDirty(const std::vector<std::uint32_t>& cells)
{
  const GridGeometry& g = geometry();
  for (std::uint32_t index : cells)
  {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    dirty_.min_x = std::min(dirty_.min_x, g.origin_x + mx * g.resolution);
    dirty_.min_y = std::min(dirty_.min_y, g.origin_y + my * g.resolution);
    dirty_.max_x = std::max(dirty_.max_x, g.origin_x + (mx + 1) * g.resolution);
    dirty_.max_y = std::max(dirty_.max_y, g.origin_y + (my + 1) * g.resolution);
  }
}

std::vector<std::uint32_t> SharingCore::shareableCells() const
{
  std::vector<std::uint32_t> cells(shareable_);
  std::sort(cells.begin(), cells.end());
  return cells;
}

std::vector<std::uint32_t> SharingCore::sharedCells(const std::string& uuid) const
{
  const auto found = shared_.find(uuid);
  return found == shared_.end() ? std::vector<std::uint32_t>{} : found->second.cells.present();
}

}  // namespace sharing_layer
