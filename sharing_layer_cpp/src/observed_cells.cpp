#include "sharing_layer/observed_cells.h"

#include <algorithm>
#include <cmath>

#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
std::vector<std::uint32_t> ObservedCells::shareableSorted() const
{
  std::vector<std::uint32_t> cells(shareable_);
  std::sort(cells.begin(), cells.end());
  return cells;
}

std::vector<std::uint32_t> ObservedCells::rememberedSorted() const
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

void ObservedCells::watchRemembered(double now_s, double trigger_memory, const GridGeometry& g, bool origin_finite,
                                    double ox, double oy, double reach_sq, CellFlags& flags,
                                    std::vector<std::uint32_t>& in_reach)
{
  for (auto it = memory_.begin(); it != memory_.end();)
  {
    const double age = now_s - it->second.time;
    if (!(age <= trigger_memory) || age < 0.0)  // forgotten, or time went backwards (a restart)
    {
      flags.clear(it->first, CellFlags::kRemembered);
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
        in_reach.push_back(it->first);
      }
    }
    ++it;
  }
}

void ObservedCells::track(const std::vector<std::uint32_t>& unclaimed, const GridGeometry& g, double ox, double oy,
                          double obstacle_range, const CostGrid& grid, CellFlags& flags)
{
  // (`unclaimed` holds no cell marked on a fleet robot, so a robot's trail does not become shareable; an obstacle
  // beside it becomes shareable with the next scan that marks it after the robot left.)
  for (std::uint32_t index : unclaimed)
  {
    if (!flags.has(index, CellFlags::kShareable))
    {
      flags.set(index, CellFlags::kShareable);
      shareable_.push_back(index);
    }
  }
  const double range_sq = obstacle_range * obstacle_range;
  const bool origin_finite = std::isfinite(ox) && std::isfinite(oy);
  const std::uint8_t* costs = grid.data();
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
      flags.clear(index, CellFlags::kShareable);
    }
    return drop;
  });
  shareable_.erase(keep_end, shareable_.end());
}

void ObservedCells::remember(const ScanTouch& touch, const std::vector<std::uint32_t>& off_walls,
                             const std::vector<std::uint32_t>& occupied, float sensor_x, float sensor_y, double now_s,
                             double trigger_memory, unsigned int clearing_scans, double clearing_time, CellFlags& flags)
{
  if (trigger_memory <= 0.0 || !std::isfinite(now_s))
  {
    return;
  }
  const auto find = [&](std::uint32_t index) {
    return flags.has(index, CellFlags::kRemembered) ? memory_.find(index) : memory_.end();
  };
  // Remembered cells leave on the same evidence as shared ones, not on costmap clearing: a robot backing off
  // clears a block's face with beams that end on it past obstacle_range.
  for (std::uint32_t index : occupied)
  {
    const auto found = find(index);
    if (found != memory_.end())
    {
      found->second.free.reset();
    }
  }
  for (std::uint32_t index : touch.watched_free)
  {
    const auto found = find(index);
    if (found != memory_.end() && found->second.free.add(now_s, clearing_scans, clearing_time))
    {
      flags.clear(index, CellFlags::kRemembered);
      memory_.erase(found);
    }
  }
  for (std::uint32_t index : touch.watched_cleared)
  {
    const auto found = find(index);
    if (found != memory_.end())
    {
      found->second.marks = 0;  // a beam passed through it: not marked steadily
    }
  }
  // (A cell marked on a fleet robot is not remembered: its trail must not be proposed once it drove on.)
  for (std::uint32_t index : off_walls)
  {
    RememberedCell& cell = memory_[index];
    flags.set(index, CellFlags::kRemembered);
    if (cell.marks == 0)
    {
      cell.marked_since = now_s;
    }
    cell.marks = static_cast<std::uint16_t>(std::min<int>(cell.marks + 1, 0xFFFF));
    cell.time = now_s;
    cell.sensor_x = sensor_x;
    cell.sensor_y = sensor_y;
    cell.free.reset();
  }
}

void ObservedCells::steadyShareable(unsigned int clearing_scans, double clearing_time, const CellFlags& flags,
                                    std::vector<std::uint32_t>& steady) const
{
  steady.clear();
  for (std::uint32_t index : shareable_)
  {
    const RememberedCell* cell = findRemembered(index, flags);
    if (cell != nullptr && cell->marks >= clearing_scans && cell->time - cell->marked_since >= clearing_time)
    {
      steady.push_back(index);
    }
  }
}

void ObservedCells::dropInside(const CellRect& rect, const GridGeometry& g, CellFlags& flags)
{
  shareable_.erase(std::remove_if(shareable_.begin(), shareable_.end(),
                                  [&](std::uint32_t index) {
                                    unsigned int mx = 0, my = 0;
                                    g.indexToCells(index, mx, my);
                                    const bool inside = rect.contains(static_cast<int>(mx), static_cast<int>(my));
                                    if (inside)
                                    {
                                      flags.clear(index, CellFlags::kShareable);
                                    }
                                    return inside;
                                  }),
                   shareable_.end());
}

void ObservedCells::dropStatic(const StaticMask& statics, CellFlags& flags)
{
  shareable_.erase(std::remove_if(shareable_.begin(), shareable_.end(),
                                  [&](std::uint32_t index) {
                                    const bool drop = statics.isStatic(index);
                                    if (drop)
                                    {
                                      flags.clear(index, CellFlags::kShareable);
                                    }
                                    return drop;
                                  }),
                   shareable_.end());
  for (auto it = memory_.begin(); it != memory_.end();)
  {
    if (statics.isStatic(it->first))
    {
      flags.clear(it->first, CellFlags::kRemembered);
      it = memory_.erase(it);
    }
    else
    {
      ++it;
    }
  }
}

void ObservedCells::forget(CellFlags& flags)
{
  for (std::uint32_t index : shareable_)
  {
    flags.clear(index, CellFlags::kShareable);
  }
  shareable_.clear();
  for (const auto& entry : memory_)
  {
    flags.clear(entry.first, CellFlags::kRemembered);
  }
  memory_.clear();
}

}  // namespace sharing_layer
