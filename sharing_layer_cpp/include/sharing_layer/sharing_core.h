#ifndef SHARING_LAYER_SHARING_CORE_H
#define SHARING_LAYER_SHARING_CORE_H

#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "sharing_layer/cell_flags.h"
#include "sharing_layer/cost_grid.h"
#include "sharing_layer/fleet_obstacles.h"
#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/grid_frame.h"
#include "sharing_layer/layer_params.h"
#include "sharing_layer/observation.h"
#include "sharing_layer/observed_cells.h"
#include "sharing_layer/proposals.h"
#include "sharing_layer/scan_pass.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/static_mask.h"
#include "sharing_layer/triggers.h"

namespace sharing_layer
{
/**
 * @brief The sharing layer without ROS: an obstacle grid, shareable-cell tracking, proposals on a
 * debounced trigger, shared obstacles with monitoring, and an overlay into a master grid.
 *
 * The costmap_2d plugin and the project's navigation host both drive this class; all times are
 * passed in, in seconds. It owns the parts and lends them to the pass each call belongs to (README, "The units"):
 * ScanPass (scan_pass.h), Triggers (triggers.h), FleetObstacles (fleet_obstacles.h), the grid frame
 * (grid_frame.h); what they share is ObservedCells, StaticMask, FleetRobots and CellFlags (a byte per cell, held
 * only in tiles where a bit is set).
 */
class SharingCore
{
public:
  /// @throws std::invalid_argument on bad parameters
  SharingCore(const GridGeometry& geometry, const LayerParams& params);

  const GridGeometry& geometry() const { return obstacles_.geometry(); }
  const LayerParams& params() const { return params_; }

  /// @brief Sets the static map used by the tolerance filter; @throws std::invalid_argument on a size mismatch
  void setStaticMap(const std::uint8_t* costs, std::size_t cost_count);

  /**
   * @brief Marks where the a-priori map is unknown (non-zero = unknown; e.g. OccupancyGrid value -1, which
   * costmap_2d's static layer turns into FREE_SPACE unless track_unknown_space). Unknown cells count as
   * static, with the same static_tolerance, so they are never shared. nullptr / 0 cells forgets them.
   * @throws std::invalid_argument on a size mismatch
   */
  void setUnknownMap(const std::uint8_t* unknown, std::size_t cell_count);

  /**
   * @brief Clears and marks one observation, updates the shareable cells and the trigger memory, and
   * monitors every shared obstacle in view. Monitoring diffs are applied here and returned for the handler.
   *
   * A shared cell is reported cleared only on evidence of free space: in at least clearing_scans scans
   * spanning at least clearing_time seconds a beam passed through it and ended at least clearing_margin
   * beyond it, and no scan in between showed a sign of occupancy (an endpoint in the cell at any range, or
   * a beam through it ending less than clearing_margin behind it); scans that do not see the cell do not
   * interrupt the streak. Remembered cells leave the trigger memory by the same rule. The obstacle grid
   * itself is cleared and marked with costmap_2d's rules. Shareable cells touching a shared obstacle in view
   * join it (growInto); present cells seen occupied again renew it every lease_renewal_interval.
   */
  ScanOutcome processScan(const Observation& observation, double now_s) { return processScan(observation, now_s, params_.limits); }
  /// @brief The same with one observation source's own limits (costmap_2d's per-source obstacle_range,
  /// raytrace_range, heights, marking and clearing) instead of the layer's.
  /// @throws std::invalid_argument naming the field when `limits` is invalid
  ScanOutcome processScan(const Observation& observation, double now_s, const ScanLimits& limits);

  /// @brief A "cannot get past" signal; @return true when it starts a burst (then call propose)
  bool signalStuck(double now_s) { return triggers_.signalStuck(now_s); }

  /**
   * @brief Groups the current shareable cells into proposals, with the configured strategy (the thesis);
   * with use_memory also the remembered cells within trigger_radius of the robot (marked within
   * trigger_memory seconds of the last scan) that lie beyond obstacle_range of the last scan's origin,
   * where the robot can no longer mark them (within it the current view decides).
   */
  std::vector<Proposal> propose(double robot_x, double robot_y, bool use_memory = false) const;

  /**
   * @brief A stuck trigger (stuck_feedback, recovery_status, manual): debounced like signalStuck (one
   * window for all these sources), then propose(), with the trigger memory for recovery_status and manual
   * (and stuck_feedback when memory_on_stuck_feedback); the report says what was proposed or why nothing.
   */
  TriggerReport trigger(TriggerSource source, double now_s, double robot_x, double robot_y);

  /// @brief The robot's current global plan, world (x, y) poses in the grid's frame, start first.
  /// Non-finite poses are dropped. An empty plan switches the plan trigger off.
  void setPlan(const std::vector<std::pair<double, double>>& poses);
  const std::vector<std::pair<double, double>>& plan() const { return triggers_.plan(); }

  /**
   * @brief The plan-blocked trigger, to call after each processScan: cells the last scan newly marked
   * (not lethal before it), not static, within obstacle_range of the robot and within inscribed_radius of a
   * plan pose ahead of the robot (from the pose nearest to it on) fire it. It is debounced on its own window
   * (trigger_debounce) and proposes the clusters (cluster_gap) of shareable and remembered cells that touch
   * the plan ahead. reason None: nothing new on the plan.
   */
  TriggerReport checkPlan(double robot_x, double robot_y, double now_s);

  /// @brief Sets inscribed_radius (e.g. when the footprint changes); @throws std::invalid_argument when
  /// negative or not finite
  void setInscribedRadius(double radius_m);

  /**
   * @brief New parameters on a running core (dynamic_reconfigure): validated first (@throws std::invalid_argument
   * naming the bad one, and changes nothing), then applied from the next call on. The grids, the shared obstacles,
   * the trigger memory, the plan and the fleet robots stay; a new static_tolerance rebuilds the static mask from the
   * maps already given (shareable cells it now covers are dropped); a new trigger_debounce applies from the next
   * signal. static_occupied_cost applies from the next setStaticMap.
   */
  void setParams(const LayerParams& params);

  /// @return remembered cells (trigger memory), sorted
  std::vector<std::uint32_t> rememberedCells() const;

  /**
   * @brief Applies an obstacle from the handler (authorised proposal, or external add/update).
   * An unknown uuid is added with now_s as its arrival time. Bad input is rejected with a reason and
   * changes nothing.
   */
  ApplyResult applyShared(const ObstacleUpdate& update, double now_s);

  /// @brief Removes an expired obstacle; @return false when the uuid is unknown
  bool expire(const std::string& uuid);

  /**
   * @brief Moves the layer onto another grid: costmap_2d's resize (matchSize, keep_observations false: the
   * layer's own grid starts empty, as Costmap2D::resizeMap leaves it) or a rolling window's origin move
   * (updateOrigin, keep_observations true: what the sensors marked stays where it is in the world, the rest
   * of the new grid is free). Shared obstacles keep their cells by world position: each cell, tombstones
   * and version stamps included, goes to the new cell holding its centre; cells off the new grid are
   * dropped (and counted), and an obstacle with none left is still held, for its updates and expiry. The
   * trigger memory, fleet robots and plan follow by world position; the static and unknown maps must be set
   * again. The new grid's arrays are allocated before anything changes, so a std::bad_alloc leaves the layer
   * as it was. Costs one pass over the old grid when keep_observations (a rolling window's grid is small).
   */
  MoveReport moveTo(const GridGeometry& geometry, bool keep_observations);
  /**
   * @brief The same for a core whose obstacle grid is a caller's buffer (useObstacleGrid): the grid becomes
   * `costs` (geometry.cellCount() cells, contents as they are), which the caller has already resized or moved
   * itself (Costmap2D::resizeMap, updateOrigin). Everything else moves as above.
   * @throws std::invalid_argument when costs is null
   */
  MoveReport moveTo(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                    std::uint8_t default_value);

  /**
   * @brief Makes a caller's buffer of geometry().cellCount() costs the obstacle grid, contents as they are, and
   * frees the core's own: one obstacle grid, not two (the costmap_2d plugin hands the core its layer's costmap_).
   * Clearing and marking write into it; resets and clears restore default_value. The caller keeps the buffer
   * alive and, when it reallocates or moves it, calls moveTo with the new one. A core using a caller's buffer must
   * not be copied.
   * @throws std::invalid_argument when costs is null
   */
  void useObstacleGrid(std::uint8_t* costs, std::uint8_t default_value);

  /// @brief The obstacle-layer reset on reaching a goal: the obstacle grid and the shareable
  /// cells are cleared; shared obstacles stay.
  void resetObstacleLayer();

  /// @brief What move_base's ClearCostmapRecovery does to a layer (CostmapLayer::clearArea with
  /// invert_area false): every obstacle-grid cell outside the open window (x0, x1) x (y0, y1) goes
  /// back to its default value, and stops being shareable. Shared obstacles stay.
  /// @return the number of cells that held an obstacle and were cleared
  std::size_t clearObstaclesOutside(int x0, int y0, int x1, int y1);

  /// @brief Sets every present shared cell to lethal in a master grid of the same geometry,
  /// touching no other cell and never lowering a cost. @throws std::invalid_argument on a size mismatch
  void drawShared(std::uint8_t* master, std::size_t cell_count) const;
  /// @brief The same inside the cell window [min_i, max_i) x [min_j, max_j) only (costmap_2d's updateCosts: a layer
  /// writes the master only inside the update window; cells outside keep what the last cycles left there). The
  /// window is clipped to the grid; an empty or inverted one draws nothing.
  void drawShared(std::uint8_t* master, std::size_t cell_count, int min_i, int min_j, int max_i, int max_j) const;

  /// @brief World bounds of shared cells added or removed since the last call, then forgets them.
  WorldBounds takeDirtyBounds();

  /**
   * @brief The fleet robots this layer knows (footprints at their poses, grid frame). Their cells (footprint
   * plus robot_exclusion_margin) are never shared: not proposed by any trigger, not remembered for one, no
   * plan-blocked trigger, not marked in monitoring updates. Robots not refreshed within robot_timeout are
   * forgotten at the next processScan, trigger or checkPlan.
   */
  FleetRobots& fleetRobots() { return fleet_robots_; }
  const FleetRobots& fleetRobots() const { return fleet_robots_; }

  /// @return bytes kept per grid cell besides the obstacle grid itself, summed over the grid: the per-cell flags,
  /// the monitored rectangles, the static sources and filter, the fleet robots (issue 13: what sharing adds to
  /// ObstacleLayer's one byte per cell)
  std::size_t perCellBytes() const;
  const CostGrid& obstacleGrid() const { return obstacles_; }
  CostGrid& obstacleGrid() { return obstacles_; }
  /// @return the current shareable cells, sorted
  std::vector<std::uint32_t> shareableCells() const;
  const std::map<std::string, SharedObstacle>& sharedObstacles() const { return fleet_.obstacles(); }
  /// @return present cells of one obstacle (empty when unknown)
  std::vector<std::uint32_t> sharedCells(const std::string& uuid) const;

private:
  /// @brief moveTo, onto a caller's buffer when costs is not null.
  MoveReport moveGrid(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                      std::uint8_t default_value);
  ScanParts scanParts() { return ScanParts{ params_, obstacles_, flags_, statics_, fleet_robots_, observed_, fleet_,
                                            !triggers_.plan().empty() }; }
  TriggerInputs triggerInputs() const
  {
    return TriggerInputs{ params_, geometry(), observed_, flags_, fleet_, statics_, fleet_robots_, scan_.last() };
  }

  LayerParams params_;
  Triggers triggers_;          ///< the stuck and plan-blocked triggers, the plan
  CostGrid obstacles_;         ///< the obstacle grid (ObstacleLayer's), the core's own or a caller's buffer
  CellFlags flags_;            ///< a byte per cell of facts the passes share (tiles only where one is set)
  StaticMask statics_;         ///< walls and unknown map areas: never shared
  ObservedCells observed_;     ///< shareable cells and trigger memory
  FleetObstacles fleet_;       ///< the fleet's obstacles, monitored
  FleetRobots fleet_robots_;   ///< fleet robots' footprints: never shared
  ScanPass scan_;              ///< the scan's temporaries and the last scan's summary
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SHARING_CORE_H
