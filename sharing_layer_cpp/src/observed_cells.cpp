#include "sharing_layer/observed_cells.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

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
  for (const RememberedEntry& entry : memory_)
  {
    cells.push_back(entry.first);
  }
  return cells;  // (memory_ is sorted)
}

void ObservedCells::watchRemembered(double now_s, double trigger_memory, const GridGeometry& g, bool origin_finite,
                                    double ox, double oy, double reach_sq, CellFlags& flags,
                                    std::vector<std::uint32_t>& in_reach)
{
  std::size_t out = 0;
  for (std::size_t in = 0; in < memory_.size(); ++in)
  {
    const RememberedEntry& entry = memory_[in];
    const double age = now_s - entry.second.time;
    if (!(age <= trigger_memory) || age < 0.0)  // forgotten, or time went backwards (a restart)
    {
      flags.clear(entry.first, CellFlags::kRemembered);
      continue;
    }
    if (origin_finite)
    {
      unsigned int mx = 0, my = 0;
      g.indexToCells(entry.first, mx, my);
      double wx = 0.0, wy = 0.0;
      g.mapToWorld(mx, my, wx, wy);
      if ((wx - ox) * (wx - ox) + (wy - oy) * (wy - oy) <= reach_sq)
      {
        // Scattered cells, mostly marked again by this very scan: walked one by one, and only if not.
        in_reach.push_back(entry.first);
      }
    }
    if (out != in)
    {
      memory_[out] = entry;
    }
    ++out;
  }
  memory_.resize(out);
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
  // Remembered cells leave on the same evidence as shared ones, not on costmap clearing: a robot backing off
  // clears a block's face with beams that end on it past obstacle_range. Every list is sorted, as the memory is.
  forEachRemembered(occupied, flags, [](RememberedCell& cell) {
    cell.free.reset();
    return true;
  });
  forEachRemembered(touch.watched_free, flags, [&](RememberedCell& cell) {
    return !cell.free.add(now_s, clearing_scans, clearing_time);
  });
  forEachRemembered(touch.watched_cleared, flags, [](RememberedCell& cell) {
    cell.marks = 0;  // a beam passed through it: not marked steadily
    return true;
  });
  // (A cell marked on a fleet robot is not remembered: its trail must not be proposed once it drove on.)
  const auto mark = [&](RememberedCell& cell) {
    if (cell.marks == 0)
    {
      cell.marked_since = now_s;
    }
    cell.marks = static_cast<std::uint16_t>(std::min<int>(cell.marks + 1, 0xFFFF));
    cell.time = now_s;
    cell.sensor_x = sensor_x;
    cell.sensor_y = sensor_y;
    cell.free.reset();
  };
  // (A local: cells new to the memory are few after the first scans, and a member would keep the first scan's
  // thousand entries on the heap for good.)
  std::vector<RememberedEntry> added;
  MemoryIt at = memory_.begin();
  for (std::uint32_t index : off_walls)
  {
    if (flags.has(index, CellFlags::kRemembered))
    {
      at = lowerBound(at, memory_.end(), index);
      if (at != memory_.end() && at->first == index)
      {
        mark(at->second);
        continue;
      }
    }
    added.emplace_back(index, RememberedCell{});
    mark(added.back().second);
    flags.set(index, CellFlags::kRemembered);
  }
  if (!added.empty())
  {
    const std::size_t before = memory_.size();
    memory_.insert(memory_.end(), added.begin(), added.end());
    std::inplace_merge(memory_.begin(), memory_.begin() + static_cast<std::ptrdiff_t>(before), memory_.end(),
                       [](const RememberedEntry& a, const RememberedEntry& b) { return a.first < b.first; });
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
  memory_.erase(std::remove_if(memory_.begin(), memory_.end(),
                               [&](const RememberedEntry& entry) {
                                 const bool drop = statics.isStatic(entry.first);
                                 if (drop)
                                 {
                                   flags.clear(entry.first, CellFlags::kRemembered);
                                 }
                                 return drop;
                               }),
                memory_.end());
}

void ObservedCells::forget(CellFlags& flags)
{
  for (std::uint32_t index : shareable_)
  {
    flags.clear(index, CellFlags::kShareable);
  }
  shareable_.clear();
  for (const RememberedEntry& entry : memory_)
  {
    flags.clear(entry.first, CellFlags::kRemembered);
  }
  memory_.clear();
}

}  // namespace sharing_layer
