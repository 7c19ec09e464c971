#include "sharing_layer/fleet_obstacles.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <unordered_set>

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
namespace
{
/// @return why an update cannot be applied to a grid g, or "" when it can
std::string rejectReason(const ObstacleUpdate& update, const GridGeometry& g, std::size_t max_update_cells)
{
  if (update.uuid.empty())
  {
    return "empty uuid";
  }
  const std::string who = "obstacle " + update.uuid + " from " + update.source + ": ";
  if (update.source.empty())
  {
    return "obstacle " + update.uuid + ": empty source";
  }
  if (!update.geometry.sameAs(g))
  {
    return who + "grid " + update.geometry.describe() + " differs from ours, " + g.describe();
  }
  if (update.marked.size() + update.cleared.size() > max_update_cells)
  {
    return who + std::to_string(update.marked.size() + update.cleared.size()) + " cells exceed max_update_cells " +
           std::to_string(max_update_cells);
  }
  for (const auto* list : { &update.marked, &update.cleared })
  {
    for (std::uint32_t index : *list)
    {
      if (!g.containsIndex(index))
      {
        return who + "index " + std::to_string(index) + " outside the " + std::to_string(g.cellCount()) +
               "-cell grid";
      }
    }
  }
  if (update.version == 0)
  {
    return who + "version 0 (a proposal, not authorised)";
  }
  // Re-validate the rectangle: a value built without the checking constructor could still be bad.
  try
  {
    Subsection(update.rectangle.min_x, update.rectangle.min_y, update.rectangle.max_x, update.rectangle.max_y);
  }
  catch (const std::invalid_argument& e)
  {
    return who + e.what();
  }
  return "";
}

/// std::lower_bound without a branch per halving (conditional moves): monitoring searches every list of evidence
/// once per obstacle in view, and std::lower_bound's branches mispredict about every other step (issue 29).
std::vector<std::uint32_t>::const_iterator lowerBound(std::vector<std::uint32_t>::const_iterator first,
                                                      std::vector<std::uint32_t>::const_iterator last,
                                                      std::uint32_t value)
{
  std::size_t n = static_cast<std::size_t>(last - first);
  if (n == 0)
  {
    return first;
  }
  const std::uint32_t* base = &*first;
  while (n > 1)
  {
    const std::size_t half = n / 2;
    base = base[half] < value ? base + half : base;
    n -= half;
  }
  return first + ((base - &*first) + (*base < value));
}

/// Calls f(index) for the cells of a sorted list inside rectangle r, in order. One search per list and rectangle:
/// the cells between its first and last row that lie outside its columns are few (the lists hold one scan's events,
/// not the grid).
template <class F>
void forEachIn(const std::vector<std::uint32_t>& sorted, const CellRect& r, const GridGeometry& g, F f)
{
  const std::uint32_t first = g.getIndex(static_cast<unsigned int>(r.min_x), static_cast<unsigned int>(r.min_y));
  const std::uint32_t last = g.getIndex(static_cast<unsigned int>(r.max_x), static_cast<unsigned int>(r.max_y));
  // The row's columns in index terms, moved on row by row as the sorted cells pass them (no division per cell).
  std::uint32_t row_first = first, row_last = g.getIndex(static_cast<unsigned int>(r.max_x),
                                                          static_cast<unsigned int>(r.min_y));
  for (auto it = lowerBound(sorted.begin(), sorted.end(), first); it != sorted.end() && *it <= last; ++it)
  {
    while (*it > row_last)
    {
      row_first += g.size_x;
      row_last += g.size_x;
    }
    if (*it >= row_first)
    {
      f(*it);
    }
  }
}
}  // namespace

WorldBounds WorldBounds::none()
{
  constexpr double inf = std::numeric_limits<double>::infinity();
  return WorldBounds{ inf, inf, -inf, -inf };
}

FleetObstacles::FleetObstacles(std::size_t cell_count)
{
  monitored_.assign(cell_count);
}

std::vector<std::uint32_t> FleetObstacles::presentCells(const std::string& uuid) const
{
  const auto found = shared_.find(uuid);
  return found == shared_.end() ? std::vector<std::uint32_t>{} : found->second.cells.present();
}

ApplyResult FleetObstacles::apply(const ObstacleUpdate& update, double now_s, const GridGeometry& g,
                                  std::size_t max_update_cells, ObservedCells& observed, CellFlags& flags)
{
  ApplyResult result;
  result.error = rejectReason(update, g, max_update_cells);
  if (!result.error.empty())
  {
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
    index_.add(found->second);
    markMonitored(found->second.rectangle_cells, true, g);
    observed.dropInside(found->second.rectangle_cells, g, flags);
  }
  SharedObstacle& obstacle = found->second;
  const bool grown = growRectangle(obstacle, update.rectangle, g, observed, flags);
  if (!update.marked.empty())
  {
    obstacle.last_observation = now_s;
  }
  obstacle.max_version = std::max(obstacle.max_version, update.version);
  result.changed = obstacle.cells.apply(update.marked, update.cleared, update.version, update.source);
  for (std::uint32_t index : update.marked)
  {
    obstacle.free_streaks.erase(index);  // a robot saw it occupied: evidence of free space starts again
  }
  if (result.changed != 0 || grown)
  {
    index_.changed(obstacle);
  }
  // Only a change of what is drawn dirties the master: a renewal (cells present already) redraws nothing, and with
  // many obstacles held the bounds of unchanged ones far apart made every cycle redraw most of the map (issue 48).
  if (result.changed != 0)
  {
    markDirty(update.marked, g);
    markDirty(update.cleared, g);
  }
  result.ok = true;
  return result;
}

bool FleetObstacles::expire(const std::string& uuid, const GridGeometry& g)
{
  const auto found = shared_.find(uuid);
  if (found == shared_.end())
  {
    return false;
  }
  markDirty(found->second.cells.present(), g);
  const CellRect rectangle = found->second.rectangle_cells;
  index_.remove(found->second);
  shared_.erase(found);
  unmarkMonitored(rectangle, g);
  return true;
}

void FleetObstacles::refreshWatchFlags(const GridGeometry& g, CellFlags& flags)
{
  index_.refreshWatchFlags(g, flags);
}

void FleetObstacles::inView(double x, double y, double radius, std::vector<SharedObstacle*>& in_view,
                            std::vector<CellRect>& present_boxes)
{
  for (const ObstacleIndex::Entry& entry : index_.entries())  // contiguous: no walk through the map's nodes
  {
    if (!entry.rectangle_cells.empty() && entry.rectangle.withinRadius(x, y, radius))
    {
      in_view.push_back(entry.obstacle);
      if (!entry.obstacle->present_box.empty())
      {
        present_boxes.push_back(entry.obstacle->present_box);
      }
    }
  }
}

void FleetObstacles::monitor(const std::vector<SharedObstacle*>& in_view, ScanEvidence& evidence, double now_s,
                             const LayerParams& params, const GridGeometry& g, ObservedCells& observed,
                             CellFlags& flags, std::vector<ObstacleUpdate>& updates)
{
  for (SharedObstacle* obstacle : in_view)
  {
    if (!monitorOne(*obstacle, evidence, now_s, params, g, observed, flags))
    {
      continue;
    }
    if (!marked_.empty())
    {
      obstacle->last_observation = now_s;
    }
    ObstacleUpdate update;
    update.marked = std::move(marked_);  // (cleared again for the next obstacle)
    update.cleared = std::move(cleared_);
    update.uuid = obstacle->uuid;
    update.deadline = obstacle->deadline;
    update.rectangle = obstacle->rectangle;
    update.source = params.robot_name;
    update.geometry = g;
    update.version = obstacle->max_version + 1;
    update.stamp = now_s;
    obstacle->max_version = update.version;
    if (obstacle->cells.apply(update.marked, update.cleared, update.version, update.source) != 0)
    {
      index_.changed(*obstacle);
      markDirty(update.marked, g);
      markDirty(update.cleared, g);
    }
    updates.push_back(std::move(update));
  }
}

bool FleetObstacles::monitorOne(SharedObstacle& obstacle, ScanEvidence& evidence, double now_s,
                                const LayerParams& params, const GridGeometry& g, ObservedCells& observed,
                                CellFlags& flags)
{
  const CellRect& r = obstacle.rectangle_cells;
  marked_.clear();
  cleared_.clear();
  seen_again_.clear();
  // The evidence comes in index order, so the obstacle's present cells (sorted too) are looked up by a cursor moving
  // forward with it: with obstacle_range as long as raytrace_range, every face in view is marked again on every
  // scan, and a hash lookup per cell took about 4 % of upstream's whole 30 m scan pass (perf, -O2; issue 29).
  // (fetched when first needed: most obstacles in view get no evidence from a scan)
  const std::vector<std::uint32_t>* present = nullptr;
  std::vector<std::uint32_t>::const_iterator next_present;
  const auto is_present = [&](std::uint32_t index) {
    if (present == nullptr)
    {
      present = &obstacle.cells.present();
      next_present = present->begin();
    }
    next_present = lowerBound(next_present, present->end(), index);
    return next_present != present->end() && *next_present == index;
  };
  forEachIn(evidence.marked_watched, r, g,
            [&](std::uint32_t index) { (is_present(index) ? seen_again_ : marked_).push_back(index); });
  // A sign of occupancy: the evidence of free space starts again.
  if (!obstacle.free_streaks.empty())
  {
    forEachIn(evidence.occupied, r, g, [&](std::uint32_t index) { obstacle.free_streaks.erase(index); });
  }
  // Evidence of free space: a beam through the cell ending well beyond it. One scan is not enough (a beam grazing
  // along a face through the free part of its cells, localisation jitter): an unbroken streak of clearing_scans
  // scans over clearing_time clears the cell. (occupied and seen_free share no cell.)
  if (present != nullptr)
  {
    next_present = present->begin();
  }
  forEachIn(evidence.seen_free, r, g, [&](std::uint32_t index) {
    if (is_present(index) &&
        obstacle.free_streaks[index].add(now_s, params.clearing_scans, params.clearing_time))
    {
      obstacle.free_streaks.erase(index);
      cleared_.push_back(index);
    }
  });
  const int gap = static_cast<int>(params.cluster_gap);
  const CellRect& s = evidence.steady_box;
  if (!evidence.steady.empty() && r.min_x - gap <= s.max_x && s.min_x <= r.max_x + gap && r.min_y - gap <= s.max_y &&
      s.min_y <= r.max_y + gap)
  {
    growInto(obstacle, evidence.steady, marked_, gap, g, observed, flags);
  }
  // Lease: cells seen occupied again renew the obstacle; sent when nobody renewed it for a while.
  if (marked_.empty() && !seen_again_.empty() &&
      !(now_s - obstacle.last_observation < params.lease_renewal_interval))
  {
    marked_ = seen_again_;
  }
  return !marked_.empty() || !cleared_.empty();
}

bool FleetObstacles::steadyInRing(const CellRect& r, int gap, const GridGeometry& g,
                                  const std::vector<std::uint32_t>& steady)
{
  const CellRect ring{ r.min_x - gap, r.min_y - gap, r.max_x + gap, r.max_y + gap };
  return std::any_of(steady.begin(), steady.end(), [&](std::uint32_t index) {
    const int x = static_cast<int>(index % g.size_x), y = static_cast<int>(index / g.size_x);
    return ring.contains(x, y) && !r.contains(x, y);
  });
}

void FleetObstacles::growInto(SharedObstacle& obstacle, std::vector<std::uint32_t>& steady,
                              std::vector<std::uint32_t>& marked, int gap, const GridGeometry& g,
                              ObservedCells& observed, CellFlags& flags)
{
  // A candidate touching the obstacle lies in the ring of width cluster_gap around its rectangle (cells inside are
  // monitored, never shareable): most obstacles in view have none there.
  if (steady.empty() || obstacle.cells.presentCount() == 0 || !steadyInRing(obstacle.rectangle_cells, gap, g, steady))
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
  // Chains: a cell touching one just taken is taken too, until nothing more touches. A cell taken here is this
  // obstacle's: it leaves `steady` for the obstacles after it.
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
  if (growRectangle(obstacle, Subsection(min_x, min_y, max_x, max_y), g, observed, flags))
  {
    index_.changed(obstacle);
  }
  marked.insert(marked.end(), grown.begin(), grown.end());
  std::sort(marked.begin(), marked.end());
  marked.erase(std::unique(marked.begin(), marked.end()), marked.end());
}

bool FleetObstacles::growRectangle(SharedObstacle& obstacle, const Subsection& rectangle, const GridGeometry& g,
                                   ObservedCells& observed, CellFlags& flags)
{
  const Subsection& r = obstacle.rectangle;
  if (rectangle.min_x >= r.min_x && rectangle.min_y >= r.min_y && rectangle.max_x <= r.max_x &&
      rectangle.max_y <= r.max_y)
  {
    return false;
  }
  obstacle.rectangle = Subsection(std::min(r.min_x, rectangle.min_x), std::min(r.min_y, rectangle.min_y),
                                  std::max(r.max_x, rectangle.max_x), std::max(r.max_y, rectangle.max_y));
  obstacle.rectangle_cells = obstacle.rectangle.cells(g);
  markMonitored(obstacle.rectangle_cells, true, g);  // the grown rectangle holds the old one
  observed.dropInside(obstacle.rectangle_cells, g, flags);
  return true;
}

void FleetObstacles::markMonitored(const CellRect& rect, bool monitored, const GridGeometry& g)
{
  for (int y = rect.min_y; y <= rect.max_y; ++y)
  {
    const std::size_t row = static_cast<std::size_t>(y) * g.size_x;
    for (int x = rect.min_x; x <= rect.max_x; ++x)
    {
      monitored_.set(row + static_cast<std::size_t>(x), monitored);
    }
  }
}

void FleetObstacles::unmarkMonitored(const CellRect& rect, const GridGeometry& g)
{
  // Rectangles overlap: unmark the area, then mark again what the others still cover of it.
  markMonitored(rect, false, g);
  for (const ObstacleIndex::Entry& entry : index_.entries())
  {
    const CellRect& other = entry.rectangle_cells;
    const CellRect overlap{ std::max(rect.min_x, other.min_x), std::max(rect.min_y, other.min_y),
                            std::min(rect.max_x, other.max_x), std::min(rect.max_y, other.max_y) };
    if (!overlap.empty())
    {
      markMonitored(overlap, true, g);
    }
  }
}

void FleetObstacles::draw(std::uint8_t* master, const GridGeometry& g, int min_i, int min_j, int max_i,
                          int max_j) const
{
  // costmap_2d's layer contract: updateCosts writes the master only inside its window. Present cells are sorted
  // (row-major indexes), so the window's rows are one contiguous run of each obstacle's cells, found by bisection:
  // the cost follows the cells in the window's rows, not every shared cell.
  const int x0 = std::max(min_i, 0), y0 = std::max(min_j, 0);
  const int x1 = std::min(max_i, static_cast<int>(g.size_x)), y1 = std::min(max_j, static_cast<int>(g.size_y));
  if (x0 >= x1 || y0 >= y1)
  {
    return;
  }
  const std::uint32_t first = static_cast<std::uint32_t>(y0) * g.size_x;
  const std::uint32_t end = static_cast<std::uint32_t>(y1) * g.size_x;
  const bool whole_rows = x0 == 0 && x1 == static_cast<int>(g.size_x);
  for (const ObstacleIndex::Entry& entry : index_.entries())
  {
    // The entry's cell range first: most obstacles have no cell in the window's rows, and are not looked at.
    if (entry.first > entry.last || entry.last < first || entry.first >= end)
    {
      continue;
    }
    const std::vector<std::uint32_t>& present = entry.obstacle->cells.present();
    auto it = std::lower_bound(present.begin(), present.end(), first);
    const auto stop = std::lower_bound(it, present.end(), end);
    for (; it != stop; ++it)
    {
      const std::uint32_t index = *it;
      if (whole_rows)
      {
        master[index] = LETHAL_OBSTACLE;
        continue;
      }
      const int x = static_cast<int>(index % g.size_x);
      if (x >= x0 && x < x1)
      {
        master[index] = LETHAL_OBSTACLE;
      }
    }
  }
}

WorldBounds FleetObstacles::takeDirtyBounds()
{
  const WorldBounds bounds = dirty_;
  dirty_ = WorldBounds::none();
  return bounds;
}

void FleetObstacles::markDirty(const std::vector<std::uint32_t>& cells, const GridGeometry& g)
{
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

void FleetObstacles::moveTo(const CellMover& mover, const GridGeometry& geometry, ObservedCells& observed,
                            CellFlags& flags, MoveReport& report)
{
  monitored_.assign(geometry.cellCount());  // marked below
  dirty_ = WorldBounds::none();
  std::vector<SharedObstacle*> all;
  for (auto& entry : shared_)
  {
    all.push_back(&entry.second);
    SharedObstacle& obstacle = entry.second;
    report.shared_cells_dropped += obstacle.cells.remap(mover);
    std::unordered_map<std::uint32_t, FreeStreak> streaks;
    for (const auto& streak : obstacle.free_streaks)
    {
      std::uint32_t moved = 0;
      if (mover(streak.first, moved) && obstacle.cells.isPresent(moved))
      {
        streaks[moved] = streak.second;
      }
    }
    obstacle.free_streaks.swap(streaks);
    obstacle.rectangle_cells = obstacle.rectangle.cells(geometry);
    if (!obstacle.rectangle_cells.empty())
    {
      markMonitored(obstacle.rectangle_cells, true, geometry);
      observed.dropInside(obstacle.rectangle_cells, geometry, flags);
    }
    report.obstacles_out_of_grid += obstacle.cells.presentCount() == 0;
    markDirty(obstacle.cells.present(), geometry);
  }
  index_.rebuild(std::move(all));  // flags is the new grid's: every present cell is flagged again
}

}  // namespace sharing_layer
