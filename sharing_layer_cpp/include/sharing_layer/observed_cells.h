#ifndef SHARING_LAYER_OBSERVED_CELLS_H
#define SHARING_LAYER_OBSERVED_CELLS_H

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/cell_flags.h"
#include "sharing_layer/cost_grid.h"
#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/static_mask.h"
#include "sharing_layer/subsection.h"

namespace sharing_layer
{
/// @brief A recently marked non-static cell (trigger memory).
struct RememberedCell
{
  double time = 0.0;            ///< last time a scan marked it, seconds
  float sensor_x = 0.0f;        ///< where the sensor was then (grid frame, m)
  float sensor_y = 0.0f;
  FreeStreak free;              ///< evidence of free space since the last sign of occupancy
  /// Scans in a row that marked it (a scan whose beam passed through it without marking it ends the row), and
  /// the time of the first of them: a shared obstacle grows only over cells marked steadily (growInto), not
  /// over the cells next to a face that localisation noise marks now and then.
  std::uint16_t marks = 0;
  double marked_since = 0.0;
};
/// A remembered cell with its grid index.
using RememberedEntry = std::pair<std::uint32_t, RememberedCell>;

/**
 * @brief What this robot's own scans found that the fleet does not hold yet, the triggers' candidates:
 * - the shareable cells: lethal now, not static, outside every shared obstacle's rectangle, not on a fleet robot,
 *   within obstacle_range of the last scan's origin;
 * - the trigger memory: recently marked non-static cells, kept until evidence of free space (the rule that clears
 *   shared cells) or trigger_memory seconds, for a trigger that comes after the robot backed off.
 * Owns both, and their kShareable / kRemembered bits in CellFlags.
 */
class ObservedCells
{
public:
  const std::vector<std::uint32_t>& shareable() const { return shareable_; }
  /// @return the trigger memory, sorted by cell index
  const std::vector<RememberedEntry>& memory() const { return memory_; }
  /// @return the remembered cell at index, or nullptr. Most cells asked about are not remembered: the flag spares
  /// them the search.
  const RememberedCell* findRemembered(std::uint32_t index, const CellFlags& flags) const
  {
    if (!flags.has(index, CellFlags::kRemembered))
    {
      return nullptr;
    }
    const auto found = lowerBound(memory_.cbegin(), memory_.cend(), index);
    return found != memory_.end() && found->first == index ? &found->second : nullptr;
  }
  /// @return the shareable cells, sorted
  std::vector<std::uint32_t> shareableSorted() const;
  /// @return the remembered cells, sorted
  std::vector<std::uint32_t> rememberedSorted() const;

  // The scan pass.
  /**
   * @brief Forgets remembered cells older than trigger_memory (or from the future: a restart), and lists those
   * within reach_sq of the scan's origin (when it is finite) in `in_reach`, to be watched for evidence.
   */
  void watchRemembered(double now_s, double trigger_memory, const GridGeometry& g, bool origin_finite, double ox,
                       double oy, double reach_sq, CellFlags& flags, std::vector<std::uint32_t>& in_reach);
  /// @brief The scan's marked cells that the rules leave to this robot (not static, not in a shared obstacle's
  /// rectangle, not on a fleet robot: `unclaimed`, sorted out by the caller) become shareable; cells cleared on the
  /// grid or beyond obstacle_range of the origin stop being shareable.
  void track(const std::vector<std::uint32_t>& unclaimed, const GridGeometry& g, double ox, double oy,
             double obstacle_range, const CostGrid& grid, CellFlags& flags);
  /**
   * @brief The trigger memory after a scan: `occupied` (signs of occupancy) restarts a cell's evidence of free
   * space, watched_free adds to it (enough of it forgets the cell), watched_cleared ends its row of marks, and
   * `off_walls` (the marked cells neither static nor on a fleet robot, sorted out by the caller) are remembered, with
   * the sensor position.
   */
  void remember(const ScanTouch& touch, const std::vector<std::uint32_t>& off_walls,
                const std::vector<std::uint32_t>& occupied, float sensor_x, float sensor_y, double now_s,
                double trigger_memory, unsigned int clearing_scans, double clearing_time, CellFlags& flags);
  /// @brief Shareable cells marked steadily (in clearing_scans scans in a row over clearing_time): growth candidates
  /// of shared obstacles, into `steady`.
  void steadyShareable(unsigned int clearing_scans, double clearing_time, const CellFlags& flags,
                       std::vector<std::uint32_t>& steady) const;

  // Changes from the other parts.
  /// @brief Cells inside a new or grown shared rectangle stop being shareable: monitoring has them.
  void dropInside(const CellRect& rect, const GridGeometry& g, CellFlags& flags);
  /// @brief Cells that became static (a new map) leave both lists.
  void dropStatic(const StaticMask& statics, CellFlags& flags);
  /// @brief Forgets everything (the obstacle layer's reset).
  void forget(CellFlags& flags);
  /// @brief Keeps the shareable cells for which keep(mx, my) holds (ClearCostmapRecovery's window).
  template <class Keep>
  void keepShareable(const GridGeometry& g, CellFlags& flags, Keep keep)
  {
    std::vector<std::uint32_t> kept;
    kept.reserve(shareable_.size());
    for (std::uint32_t index : shareable_)
    {
      unsigned int mx = 0, my = 0;
      g.indexToCells(index, mx, my);
      if (keep(mx, my))
      {
        kept.push_back(index);
      }
      else
      {
        flags.clear(index, CellFlags::kShareable);
      }
    }
    shareable_.swap(kept);
  }
  /**
   * @brief Onto another grid: each cell goes where mover puts it (the cell holding its centre), into new_flags;
   * the shareable cells only when keep_observations (a rolling window), the memory always (the newest time wins
   * where two land on one cell).
   */
  template <class Mover>
  void moveTo(const Mover& mover, bool keep_observations, CellFlags& new_flags);

private:
  using MemoryIt = std::vector<RememberedEntry>::iterator;
  /// @return the first entry of [from, end) whose index is not below index
  template <class It>
  static It lowerBound(It from, It end, std::uint32_t index)
  {
    return std::lower_bound(from, end, index,
                            [](const RememberedEntry& entry, std::uint32_t i) { return entry.first < i; });
  }
  /**
   * @brief Calls f(cell) for the remembered cells of `cells` (sorted), walking memory_ forward once. f returns
   * whether the cell stays; one that does not is forgotten (its flag cleared) once the walk ends.
   */
  template <class F>
  void forEachRemembered(const std::vector<std::uint32_t>& cells, CellFlags& flags, F f);

  std::vector<std::uint32_t> shareable_;
  /// Sorted by cell index. Flat and sorted rather than hashed: each scan's lists of cells come sorted, so a scan
  /// updates the memory in one forward walk, without a hash and a scattered node per cell (issue 29).
  std::vector<RememberedEntry> memory_;
};

template <class F>
void ObservedCells::forEachRemembered(const std::vector<std::uint32_t>& cells, CellFlags& flags, F f)
{
  bool forgot = false;
  MemoryIt at = memory_.begin();
  for (std::uint32_t index : cells)
  {
    if (!flags.has(index, CellFlags::kRemembered))
    {
      continue;
    }
    at = lowerBound(at, memory_.end(), index);
    if (at == memory_.end())
    {
      break;
    }
    if (at->first == index && !f(at->second))
    {
      flags.clear(index, CellFlags::kRemembered);
      forgot = true;
    }
  }
  if (forgot)  // (the entries forgotten are those whose flag went: memory_ and the flags hold the same cells)
  {
    memory_.erase(std::remove_if(memory_.begin(), memory_.end(),
                                 [&](const RememberedEntry& entry) {
                                   return !flags.has(entry.first, CellFlags::kRemembered);
                                 }),
                  memory_.end());
  }
}

template <class Mover>
void ObservedCells::moveTo(const Mover& mover, bool keep_observations, CellFlags& new_flags)
{
  std::vector<std::uint32_t> shareable;
  if (keep_observations)
  {
    for (std::uint32_t index : shareable_)
    {
      std::uint32_t moved = 0;
      if (mover(index, moved) && !new_flags.has(moved, CellFlags::kShareable))
      {
        new_flags.set(moved, CellFlags::kShareable);
        shareable.push_back(moved);
      }
    }
    std::sort(shareable.begin(), shareable.end());
  }
  std::vector<RememberedEntry> memory;
  memory.reserve(memory_.size());
  for (const RememberedEntry& entry : memory_)
  {
    std::uint32_t moved = 0;
    if (mover(entry.first, moved))
    {
      memory.emplace_back(moved, entry.second);
    }
  }
  // Where two land on one cell the newest time wins: sorted newest first within a cell, the first of each is kept.
  std::sort(memory.begin(), memory.end(), [](const RememberedEntry& a, const RememberedEntry& b) {
    return a.first != b.first ? a.first < b.first : a.second.time > b.second.time;
  });
  memory.erase(std::unique(memory.begin(), memory.end(),
                           [](const RememberedEntry& a, const RememberedEntry& b) { return a.first == b.first; }),
               memory.end());
  for (const RememberedEntry& entry : memory)
  {
    new_flags.set(entry.first, CellFlags::kRemembered);
  }
  shareable_.swap(shareable);
  memory_.swap(memory);
}

}  // namespace sharing_layer

#endif  // SHARING_LAYER_OBSERVED_CELLS_H
