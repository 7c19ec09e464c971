#include "sharing_layer/scan_pass.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
bool LastScan::originKnown() const
{
  return std::isfinite(origin_x) && std::isfinite(origin_y);
}

void LastScan::forgetMarks()
{
  new_marked.clear();
  far_hits.clear();
  robot_marked.clear();
  static_marked = 0;
}

ScanOutcome ScanPass::run(const Observation& observation, double now_s, const ScanLimits& limits, ScanParts& parts)
{
  limits.validate();
  parts.robots.expire(now_s);
  prepareWatch(observation, now_s, std::max(limits.obstacle_range, limits.raytrace_range), parts);
  collectNewMarks(observation, limits, parts);

  ScanOutcome outcome;
  outcome.touch = applyScan(parts.grid, observation, limits, watch_);
  const GridGeometry& g = parts.grid.geometry();
  sortMarked(outcome.touch, parts);
  parts.observed.track(unclaimed_, g, observation.origin.x, observation.origin.y, limits.obstacle_range, parts.grid,
                       parts.flags);
  collectSigns(outcome.touch);
  parts.observed.remember(outcome.touch, off_walls_, occupied_, static_cast<float>(observation.origin.x),
                          static_cast<float>(observation.origin.y), now_s, parts.params.trigger_memory,
                          parts.params.clearing_scans, parts.params.clearing_time, parts.flags);
  summarise(observation, now_s, parts);
  if (!in_view_.empty())
  {
    monitorInView(outcome.touch, now_s, parts, outcome.updates);
  }
  return outcome;
}

void ScanPass::prepareWatch(const Observation& observation, double now_s, double view_radius, ScanParts& parts)
{
  const GridGeometry& g = parts.grid.geometry();
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  const bool origin_finite = std::isfinite(ox) && std::isfinite(oy);
  // Only obstacles this scan can reach are monitored; the rest cost one distance test each. Their present cells
  // and the remembered cells in reach are watched for evidence of free space.
  in_view_.clear();
  watch_.cells.clear();
  watch_.regions.clear();
  watch_.loose_cells.clear();
  watch_.free_margin = parts.params.clearing_margin;
  watch_.free_neighbours = parts.params.clearing_neighbours;
  watch_.scratch = &parts.flags;
  // The present cells stay flagged between scans (refreshed when they change); the boxes of those in view are the
  // watch's regions.
  parts.fleet.refreshWatchFlags(g, parts.flags);
  if (origin_finite)
  {
    parts.fleet.inView(ox, oy, view_radius, in_view_, watch_.regions);
  }
  if (!parts.observed.memory().empty())
  {
    const double reach_sq = (view_radius + g.resolution) * (view_radius + g.resolution);
    parts.observed.watchRemembered(now_s, parts.params.trigger_memory, g, origin_finite, ox, oy, reach_sq,
                                   parts.flags, watch_.loose_cells);
  }
}

void ScanPass::collectNewMarks(const Observation& observation, const ScanLimits& l, ScanParts& parts)
{
  // Cells this scan will mark that are not lethal now: the "newly marked" cells of the plan trigger. Also the
  // endpoints between obstacle_range and raytrace_range: the rest of a face whose middle the plan trigger fires
  // on (see Triggers::checkPlan).
  // Each usable point's cell is looked up here once, for applyScan too (ScanWatch::point_cells).
  not_lethal_before_.clear();
  last_.far_hits.clear();
  const GridGeometry& g = parts.grid.geometry();
  std::vector<ScanWatch::Cell>& cells = watch_.point_cells;
  cells.resize(observation.points.size());
  const bool new_marks = parts.plan_set && l.marking;  // a source that does not mark makes nothing new
  const std::uint8_t* const costs = parts.grid.data();
  for (std::size_t pi = 0; pi < observation.points.size(); ++pi)
  {
    const Point3& p = observation.points[pi];
    ScanWatch::Cell& cell = cells[pi];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || p.z < l.min_obstacle_height ||
        p.z > l.max_obstacle_height || !g.worldToMap(p.x, p.y, cell.x, cell.y))
    {
      cell.x = ScanWatch::kNoCell;
    }
    else if (new_marks)
    {
      // The cost is read in the loop below. Scattered over a 4 MB grid that the last clearing evicted, the reads
      // missed the cache one after the other; asked for here, they arrive together.
      __builtin_prefetch(costs + g.getIndex(cell.x, cell.y));
    }
  }
  if (!new_marks)
  {
    return;
  }
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  const double sq_range = l.obstacle_range * l.obstacle_range;
  const double sq_far = l.raytrace_range * l.raytrace_range;
  for (std::size_t pi = 0; pi < observation.points.size(); ++pi)
  {
    const Point3& p = observation.points[pi];
    const ScanWatch::Cell cell = cells[pi];
    if (cell.x == ScanWatch::kNoCell)
    {
      continue;  // unusable, or off the grid
    }
    const double dz = p.z - observation.origin.z;
    const double d_sq = (p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + dz * dz;
    if (p.z > l.max_marking_height && d_sq < sq_range)
    {
      continue;  // cleared along, not marked
    }
    if (d_sq >= sq_range)
    {
      if (d_sq < sq_far)
      {
        last_.far_hits.push_back(g.getIndex(cell.x, cell.y));
      }
      continue;
    }
    if (costs[g.getIndex(cell.x, cell.y)] != LETHAL_OBSTACLE)
    {
      not_lethal_before_.push_back(g.getIndex(cell.x, cell.y));
    }
  }
}

void ScanPass::sortMarked(const ScanTouch& touch, ScanParts& parts)
{
  last_.static_marked = 0;
  last_.robot_marked.clear();
  marked_watched_.clear();
  marked_known_.clear();
  unclaimed_.clear();
  off_walls_.clear();
  for (std::uint32_t index : touch.marked)
  {
    const bool is_static = parts.statics.isStatic(index);
    const bool monitored = parts.fleet.monitored(index);
    const bool on_robot = parts.robots.excludes(index);
    last_.static_marked += is_static;
    if (on_robot && !is_static)
    {
      last_.robot_marked.push_back(index);
    }
    if (monitored || parts.flags.has(index, CellFlags::kRemembered))
    {
      marked_known_.push_back(index);
    }
    if (!is_static && !on_robot)
    {
      off_walls_.push_back(index);
      (monitored ? marked_watched_ : unclaimed_).push_back(index);
    }
  }
}

void ScanPass::collectSigns(const ScanTouch& t)
{
  // Signs of occupancy among the watched cells: marked, an endpoint in it beyond obstacle_range, or cleared by a
  // beam that ended close behind it (the face it hit, or a neighbour it grazed). Every list is sorted: merged, not
  // sorted again.
  occupied_.clear();
  grazed_.clear();
  std::set_difference(t.watched_cleared.begin(), t.watched_cleared.end(), t.watched_free.begin(),
                      t.watched_free.end(), std::back_inserter(grazed_));
  signs_.clear();
  std::set_union(grazed_.begin(), grazed_.end(), t.watched_hit.begin(), t.watched_hit.end(),
                 std::back_inserter(signs_));
  std::set_union(signs_.begin(), signs_.end(), marked_known_.begin(), marked_known_.end(),
                 std::back_inserter(occupied_));
}

void ScanPass::summarise(const Observation& observation, double now_s, ScanParts& parts)
{
  last_.time = now_s;
  if (std::isfinite(observation.origin.x) && std::isfinite(observation.origin.y))
  {
    last_.origin_x = observation.origin.x;
    last_.origin_y = observation.origin.y;
  }
  last_.new_marked.clear();
  for (std::uint32_t index : not_lethal_before_)
  {
    if (!parts.statics.isStatic(index))
    {
      last_.new_marked.push_back(index);
    }
  }
  std::sort(last_.new_marked.begin(), last_.new_marked.end());
  last_.new_marked.erase(std::unique(last_.new_marked.begin(), last_.new_marked.end()), last_.new_marked.end());
}

void ScanPass::monitorInView(const ScanTouch& touch, double now_s, ScanParts& parts,
                             std::vector<ObstacleUpdate>& updates)
{
  const GridGeometry& g = parts.grid.geometry();
  // Growth candidates, computed once per scan. They lie within obstacle_range of the robot, most obstacles in view
  // far beyond: their box rules those out without looking at their rings.
  parts.observed.steadyShareable(parts.params.clearing_scans, parts.params.clearing_time, parts.flags, steady_);
  CellRect steady_box{ std::numeric_limits<int>::max(), std::numeric_limits<int>::max(),
                       std::numeric_limits<int>::min(), std::numeric_limits<int>::min() };
  for (std::uint32_t index : steady_)
  {
    const int x = static_cast<int>(index % g.size_x), y = static_cast<int>(index / g.size_x);
    steady_box = CellRect{ std::min(steady_box.min_x, x), std::min(steady_box.min_y, y),
                           std::max(steady_box.max_x, x), std::max(steady_box.max_y, y) };
  }
  ScanEvidence evidence{ marked_watched_, occupied_, touch.watched_free, steady_, steady_box };
  parts.fleet.monitor(in_view_, evidence, now_s, parts.params, g, parts.observed, parts.flags, updates);
}

}  // namespace sharing_layer
