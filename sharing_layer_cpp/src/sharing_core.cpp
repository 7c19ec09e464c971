#include "sharing_layer/sharing_core.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

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
}

SharingCore::SharingCore(const GridGeometry& geometry, const LayerParams& params)
  : params_(params), trigger_(params.trigger_debounce), dirty_(emptyBounds())
{
  params_.validate();
  obstacles_ = CostGrid(GridGeometry(geometry.resolution, geometry.origin_x, geometry.origin_y, geometry.size_x,
                                     geometry.size_y),
                        FREE_SPACE);
  is_shareable_.assign(geometry.cellCount(), 0);
  monitored_.assign(geometry.cellCount(), 0);
}

void SharingCore::setStaticMap(const std::uint8_t* costs, std::size_t cost_count)
{
  static_filter_ = StaticMapFilter(geometry(), costs, cost_count, params_.static_tolerance,
                                   params_.static_occupied_cost);
}

void SharingCore::countRectangle(const CellRect& rect, int delta)
{
  const GridGeometry& g = geometry();
  for (int y = rect.min_y; y <= rect.max_y; ++y)
  {
    std::uint16_t* row = monitored_.data() + static_cast<std::size_t>(y) * g.size_x;
    for (int x = rect.min_x; x <= rect.max_x; ++x)
    {
      row[x] = static_cast<std::uint16_t>(row[x] + delta);
    }
  }
}

ScanOutcome SharingCore::processScan(const Observation& observation, double now_s)
{
  const GridGeometry& g = geometry();
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  const double view_radius = std::max(params_.limits.obstacle_range, params_.limits.raytrace_range);

  // Only obstacles this scan can reach are monitored; the rest cost one distance test each.
  std::vector<SharedObstacle*> in_view;
  ScanWatch watch;
  if (std::isfinite(ox) && std::isfinite(oy))
  {
    for (auto& entry : shared_)
    {
      SharedObstacle& obstacle = entry.second;
      if (!obstacle.rectangle_cells.empty() && obstacle.rectangle.withinRadius(ox, oy, view_radius))
      {
        in_view.push_back(&obstacle);
        const std::vector<std::uint32_t>& present = obstacle.cells.present();
        watch.cells.insert(watch.cells.end(), present.begin(), present.end());
      }
    }
  }

  ScanOutcome outcome;
  outcome.touch = applyScan(obstacles_, observation, params_.limits, watch);
  trackShareable(outcome.touch, observation);

  if (in_view.empty())
  {
    return outcome;
  }
  std::vector<std::uint32_t> marked_watched;
  for (std::uint32_t index : outcome.touch.marked)
  {
    if (monitored_[index] != 0)
    {
      marked_watched.push_back(index);
    }
  }
  for (SharedObstacle* obstacle : in_view)
  {
    const CellRect& r = obstacle->rectangle_cells;
    ObstacleUpdate update;
    // Both lists are sorted: each row of the rectangle is one contiguous index range in them.
    for (int y = r.min_y; y <= r.max_y; ++y)
    {
      const std::uint32_t row_first = g.getIndex(static_cast<unsigned int>(r.min_x), static_cast<unsigned int>(y));
      const std::uint32_t row_last = g.getIndex(static_cast<unsigned int>(r.max_x), static_cast<unsigned int>(y));
      for (auto it = std::lower_bound(marked_watched.begin(), marked_watched.end(), row_first);
           it != marked_watched.end() && *it <= row_last; ++it)
      {
        if (!obstacle->cells.isPresent(*it) && !static_filter_.isStatic(*it))
        {
          update.marked.push_back(*it);
        }
      }
      for (auto it = std::lower_bound(outcome.touch.watched_cleared.begin(), outcome.touch.watched_cleared.end(),
                                      row_first);
           it != outcome.touch.watched_cleared.end() && *it <= row_last; ++it)
      {
        if (obstacle->cells.isPresent(*it))
        {
          update.cleared.push_back(*it);
        }
      }
    }
    if (update.marked.empty() && update.cleared.empty())
    {
      continue;
    }
    update.uuid = obstacle->uuid;
    update.deadline = obstacle->deadline;
    update.rectangle = obstacle->rectangle;
    update.source = params_.robot_name;
    update.geometry = g;
    update.version = obstacle->max_version + 1;
    update.stamp = now_s;
    obstacle->max_version = update.version;
    obstacle->cells.apply(update.marked, update.cleared, update.version, update.source);
    markDirty(update.marked);
    markDirty(update.cleared);
    outcome.updates.push_back(std::move(update));
  }
  return outcome;
}

void SharingCore::trackShareable(const ScanTouch& touch, const Observation& observation)
{
  for (std::uint32_t index : touch.marked)
  {
    if (!is_shareable_[index] && !static_filter_.isStatic(index) && !insideMonitoredRectangle(index))
    {
      is_shareable_[index] = 1;
      shareable_.push_back(index);
    }
  }
  const GridGeometry& g = geometry();
  const double ox = observation.origin.x;
  const double oy = observation.origin.y;
  const double range_sq = params_.limits.obstacle_range * params_.limits.obstacle_range;
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
      is_shareable_[index] = 0;
    }
    return drop;
  });
  shareable_.erase(keep_end, shareable_.end());
}

std::vector<Proposal> SharingCore::propose(double robot_x, double robot_y) const
{
  const std::vector<std::uint32_t> cells = shareableCells();
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
    found = shared_.emplace(update.uuid, std::move(obstacle)).first;
    result.added = true;
    countRectangle(found->second.rectangle_cells, +1);
    // Cells of a new obstacle are not this robot's candidates any more: monitoring takes them over.
    const CellRect& r = found->second.rectangle_cells;
    shareable_.erase(std::remove_if(shareable_.begin(), shareable_.end(),
                                    [&](std::uint32_t index) {
                                      unsigned int mx = 0, my = 0;
                                      g.indexToCells(index, mx, my);
                                      const bool inside = r.contains(static_cast<int>(mx), static_cast<int>(my));
                                      if (inside)
                                      {
                                        is_shareable_[index] = 0;
                                      }
                                      return inside;
                                    }),
                     shareable_.end());
  }
  SharedObstacle& obstacle = found->second;
  obstacle.max_version = std::max(obstacle.max_version, update.version);
  result.changed = obstacle.cells.apply(update.marked, update.cleared, update.version, update.source);
  markDirty(update.marked);
  markDirty(update.cleared);
  result.ok = true;
  return result;
}

bool SharingCore::expire(const std::string& uuid)
{
  const auto found = shared_.find(uuid);
  if (found == shared_.end())
  {
    return false;
  }
  markDirty(found->second.cells.present());
  countRectangle(found->second.rectangle_cells, -1);
  shared_.erase(found);
  return true;
}

void SharingCore::resetObstacleLayer()
{
  obstacles_.reset();
  for (std::uint32_t index : shareable_)
  {
    is_shareable_[index] = 0;
  }
  shareable_.clear();
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
      is_shareable_[index] = 0;
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
