#ifndef SHARING_LAYER_SCAN_PASS_H
#define SHARING_LAYER_SCAN_PASS_H

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "sharing_layer/cell_flags.h"
#include "sharing_layer/cost_grid.h"
#include "sharing_layer/fleet_obstacles.h"
#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/layer_params.h"
#include "sharing_layer/observation.h"
#include "sharing_layer/observed_cells.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/static_mask.h"

namespace sharing_layer
{
/// @brief Result of one scan.
struct ScanOutcome
{
  ScanTouch touch;                       ///< what the scan did to the obstacle grid
  std::vector<ObstacleUpdate> updates;   ///< monitoring diffs of shared obstacles, already applied here
};

/// @brief What the triggers read of the last scan (the scan pass writes it).
struct LastScan
{
  std::vector<std::uint32_t> new_marked;    ///< non-static cells it marked that were not lethal before, sorted
  std::vector<std::uint32_t> far_hits;      ///< its endpoints beyond obstacle_range, within raytrace_range
  std::vector<std::uint32_t> robot_marked;  ///< non-static cells it marked on fleet robots
  std::size_t static_marked = 0;            ///< static cells it marked
  double time = 0.0;
  double origin_x = std::numeric_limits<double>::quiet_NaN();  ///< sensor origin (NaN before the first scan)
  double origin_y = std::numeric_limits<double>::quiet_NaN();

  bool originKnown() const;
  /// @brief Forgets what it marked (a new plan-less state, a new grid); the origin stays.
  void forgetMarks();
};

/// @brief The parts of the layer a scan reads and writes, lent by SharingCore for one scan.
struct ScanParts
{
  const LayerParams& params;
  CostGrid& grid;              ///< the obstacle grid: cleared and marked with costmap_2d's rules
  CellFlags& flags;
  const StaticMask& statics;
  FleetRobots& robots;         ///< expired at each scan
  ObservedCells& observed;     ///< shareable cells and trigger memory
  FleetObstacles& fleet;       ///< monitored
  bool plan_set;               ///< whether the plan trigger is on (then the newly marked cells are collected)
};

/**
 * @brief The scan pass: one observation clears and marks the obstacle grid (applyScan, costmap_2d's rules), and the
 * same beams are read as evidence:
 * - shareable cells and the trigger memory follow what was marked and seen free (ObservedCells);
 * - the fleet's obstacles in view are monitored (FleetObstacles::monitor): evidence of free space, cells seen again,
 *   growth over steady cells beside them;
 * - the cells the plan trigger needs (newly marked, far endpoints) are summarised in LastScan.
 * Owns the scan's temporaries (kept so that a scan does not allocate them again) and the last scan's summary.
 */
class ScanPass
{
public:
  /// @throws std::invalid_argument naming the field when `limits` is invalid
  ScanOutcome run(const Observation& observation, double now_s, const ScanLimits& limits, ScanParts& parts);
  const LastScan& last() const { return last_; }
  LastScan& last() { return last_; }

private:
  /// @brief Fills the watch: the present cells of obstacles in view (their boxes), the remembered cells in reach.
  void prepareWatch(const Observation& observation, double now_s, double view_radius, ScanParts& parts);
  /// @brief Each usable point's cell (for applyScan: watch_.point_cells), the cells this scan will mark that are not
  /// lethal yet (not_lethal_before_), and its far endpoints.
  void collectNewMarks(const Observation& observation, const ScanLimits& limits, ScanParts& parts);
  /// @brief Sorts the marked cells once by what they lie on, for the passes after it: walls (counted), fleet robots
  /// (last_.robot_marked), shared obstacles' rectangles or remembered cells (marked_known_); of the cells neither on
  /// a wall nor on a robot (off_walls_), those in a shared obstacle's rectangle (marked_watched_) and the rest
  /// (unclaimed_). Each rule is looked up once per cell, not once per pass.
  void sortMarked(const ScanTouch& touch, ScanParts& parts);
  /// @brief Signs of occupancy among the watched cells (occupied_): marked, an endpoint in it, or a beam that
  /// ended close behind it.
  void collectSigns(const ScanTouch& touch);
  /// @brief The summary the triggers read (last_).
  void summarise(const Observation& observation, double now_s, ScanParts& parts);
  /// @brief Monitors the obstacles in view; their updates into `updates`.
  void monitorInView(const ScanTouch& touch, double now_s, ScanParts& parts, std::vector<ObstacleUpdate>& updates);

  LastScan last_;
  std::vector<SharedObstacle*> in_view_;
  ScanWatch watch_;
  std::vector<std::uint32_t> not_lethal_before_, grazed_, marked_known_, signs_, occupied_, marked_watched_, steady_;
  std::vector<std::uint32_t> unclaimed_, off_walls_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SCAN_PASS_H
