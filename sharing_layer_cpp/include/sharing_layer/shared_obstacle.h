#ifndef SHARING_LAYER_SHARED_OBSTACLE_H
#define SHARING_LAYER_SHARED_OBSTACLE_H

#include <cstdint>
#include <functional>
#include <string>
#include <unordered_map>
#include <vector>

#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/subsection.h"

namespace sharing_layer
{
/// @brief The value of one sharing_msgs/SharedObstacle: a first share or an update of an obstacle.
struct ObstacleUpdate
{
  std::string uuid;
  std::vector<std::uint32_t> marked;   ///< cells seen occupied
  std::vector<std::uint32_t> cleared;  ///< cells seen free by raytracing
  std::uint32_t deadline = 0;          ///< seconds the obstacle lives after arriving at a robot
  Subsection rectangle;                ///< monitored subsection; only grows (union), when obstacles merge
  std::string source;                  ///< robot that made this update
  GridGeometry geometry;               ///< grid the indexes refer to
  std::uint64_t version = 0;           ///< Lamport version of this update for this uuid
  double stamp = 0.0;                  ///< when the update was made, seconds
};

/**
 * @brief Cells of one obstacle as a last-writer-wins set, so that applying the same updates
 * in any order, any number of times, gives the same cells.
 *
 * Every cell remembers the (version, source) of the update that last set it and whether that
 * update marked or cleared it; a greater pair wins. Within one update marked cells are applied
 * first and cleared cells second, and on an exact tie a clear wins, so "add marked, then
 * remove cleared" holds for each update on its own. Cleared cells stay as tombstones.
 */
class VersionedCellSet
{
public:
  /// @brief Applies one update; @return number of cells whose presence changed
  std::size_t apply(const std::vector<std::uint32_t>& marked, const std::vector<std::uint32_t>& cleared,
                    std::uint64_t version, const std::string& source);
  bool isPresent(std::uint32_t index) const;
  /// @return the present cells, sorted (kept between changes: a scan asks for them every time)
  const std::vector<std::uint32_t>& present() const;
  std::size_t presentCount() const { return present_count_; }
  /// @return cells with any stamp, tombstones included
  std::size_t trackedCount() const { return cells_.size(); }
  /**
   * @brief Moves every cell, tombstones included, with its stamp, to the index `to_new` gives it (another
   * grid); cells it refuses (returns false for) are dropped. Cells landing on one index keep the greatest
   * stamp, a clear winning a tie, as apply() would. @return present cells dropped
   */
  std::size_t remap(const std::function<bool(std::uint32_t, std::uint32_t&)>& to_new);

private:
  struct CellState
  {
    std::uint64_t version;
    std::uint32_t source;  ///< index into sources_
    bool present;
  };
  std::uint32_t sourceId(const std::string& source);
  /// @return whether (version, source) is greater than the cell's stamp (or equal, when or_equal)
  bool newer(const CellState& cell, std::uint64_t version, std::uint32_t source, bool or_equal) const;

  std::unordered_map<std::uint32_t, CellState> cells_;
  std::vector<std::string> sources_;
  std::size_t present_count_ = 0;
  mutable std::vector<std::uint32_t> present_cache_;
  mutable bool present_cache_valid_ = true;  ///< an empty set's cache is right
};

/// @brief Uninterrupted evidence of free space for one cell: scans that saw it free, and since when.
struct FreeStreak
{
  std::uint16_t scans = 0;
  double since = 0.0;  ///< time of the first scan of the streak, seconds

  /// @brief Adds a scan that saw the cell free; @return whether the streak now clears it
  bool add(double now_s, unsigned int min_scans, double min_time)
  {
    if (scans == 0)
    {
      since = now_s;
    }
    if (scans < 0xFFFF)
    {
      ++scans;
    }
    return scans >= min_scans && now_s - since >= min_time;
  }
  void reset() { scans = 0; }
};

/// @brief A shared obstacle as one robot holds it.
struct SharedObstacle
{
  std::string uuid;
  Subsection rectangle;
  CellRect rectangle_cells;      ///< cells whose centres lie in the rectangle
  std::uint32_t deadline = 0;
  std::string creator;           ///< source of the first update seen
  double arrival_time = 0.0;     ///< local time of the first update seen
  std::uint64_t max_version = 0; ///< highest version seen
  double last_observation = 0.0; ///< local time of the last update with marked cells (any robot's), or arrival
  VersionedCellSet cells;
  CellRect present_box{ 0, 0, -1, -1 };  ///< bounding box of the present cells (kept by SharingCore; empty: none)
  /// Per present cell: this robot's current streak of evidence of free space (local monitoring state,
  /// never sent).
  std::unordered_map<std::uint32_t, FreeStreak> free_streaks;
  // Kept by ObstacleIndex:
  std::size_t index_slot = 0;            ///< its entry in the index
  std::vector<std::uint32_t> flagged;    ///< its present cells when their watch flags were last set (sorted)
  bool watch_pending = false;            ///< its flags wait for the next refresh
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SHARED_OBSTACLE_H
