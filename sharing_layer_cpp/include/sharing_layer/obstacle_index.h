#ifndef SHARING_LAYER_OBSTACLE_INDEX_H
#define SHARING_LAYER_OBSTACLE_INDEX_H

#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "sharing_layer/cell_flags.h"
#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/subsection.h"

namespace sharing_layer
{
/**
 * @brief The obstacles FleetObstacles holds, side by side for the passes that look at every one of them (drawing into
 * the master, the in-view test of each scan, the rectangles still covering a cell), and the present cells' watch flag
 * (CellFlags::kFlaggedWatched), both kept up to date obstacle by obstacle.
 *
 * Why (issue 48): with 10,000 obstacles held, each cycle walked them all in their std::map to draw the update window,
 * each change rebuilt the in-view list, and each scan after a change cleared and set the flag of every present cell
 * of every obstacle: an update of one obstacle cost the layer as much as the handler's whole processing. Here an
 * update touches its own entry; drawing reads the entries' cell ranges (contiguous, no obstacle is looked at unless
 * its cells reach the window's rows); a refresh of the flags diffs only the obstacles that changed.
 *
 * A cell present in several obstacles keeps its flag until the last of them lets it go (the extra holders are
 * counted, in a map, as overlaps are rare).
 */
class ObstacleIndex
{
public:
  /// @brief One held obstacle, as the passes over all of them read it.
  struct Entry
  {
    Subsection rectangle;
    CellRect rectangle_cells;
    std::uint32_t first = 1, last = 0;  ///< its least and greatest present cell (first > last: none)
    SharedObstacle* obstacle = nullptr;
  };

  /// @brief A new obstacle (its map node stays put until it is removed): its entry, its flags at the next refresh.
  void add(SharedObstacle& obstacle);
  /// @brief Its present cells or its rectangle changed: its entry now, its flags at the next refresh.
  void changed(SharedObstacle& obstacle);
  /// @brief An obstacle that goes: its entry now, its flags at the next refresh. Call before erasing it.
  void remove(SharedObstacle& obstacle);
  /// @brief Brings the watch flags and present boxes of the obstacles that changed, came or went up to date.
  void refreshWatchFlags(const GridGeometry& g, CellFlags& flags);
  /// @brief Onto a new grid with fresh flags: every obstacle's entry again, and its flags at the next refresh.
  void rebuild(std::vector<SharedObstacle*> obstacles);

  const std::vector<Entry>& entries() const { return entries_; }
  /// @return whether a refresh has anything to do
  bool stale() const { return !pending_.empty() || !released_.empty(); }
  /// @return cells held by more than one obstacle beyond the first (for tests)
  std::size_t overlaps() const;

private:
  void update(Entry& entry);
  void acquire(std::uint32_t cell, CellFlags& flags);
  void release(std::uint32_t cell, CellFlags& flags);

  std::vector<Entry> entries_;
  std::vector<SharedObstacle*> pending_;      ///< changed or new since the last refresh (each once)
  std::vector<std::uint32_t> released_;       ///< flagged cells of obstacles removed since the last refresh
  std::unordered_map<std::uint32_t, std::uint32_t> extra_holders_;  ///< flagged cell -> holders beyond the first
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_OBSTACLE_INDEX_H
