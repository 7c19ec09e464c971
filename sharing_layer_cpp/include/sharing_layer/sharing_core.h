#ifndef SHARING_LAYER_SHARING_CORE_H
#define SHARING_LAYER_SHARING_CORE_H

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "sharing_layer/cost_grid.h"
#include "sharing_layer/observation.h"
#include "sharing_layer/proposals.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/static_filter.h"
#include "sharing_layer/trigger.h"

namespace sharing_layer
{
/// @brief Parameters of the sharing layer, with the defaults of the original AGVs.
struct LayerParams
{
  ScanLimits limits;                       ///< obstacle_range 2.5, raytrace_range 3.0, heights 0..2
  int static_tolerance = 2;                ///< cells around the static map that never count as new
  std::uint8_t static_occupied_cost = 254; ///< static costs at or above this are walls
  ProposalStrategy strategy = ProposalStrategy::Sectors;
  double trigger_debounce = 2.0;           ///< seconds without a stuck signal that end a burst
  unsigned int cluster_gap = 1;            ///< Clusters: cells within this Chebyshev distance join
  std::size_t min_cluster_cells = 1;       ///< Clusters: smaller groups are not proposed
  double rectangle_padding = 0.0;          ///< metres added around a proposal's cells
  std::size_t max_update_cells = 1000000;  ///< larger updates are rejected
  std::string robot_name = "robot";        ///< source of this robot's updates

  /// @throws std::invalid_argument naming the parameter and its value
  void validate() const;
};

/// @brief Result of one scan.
struct ScanOutcome
{
  ScanTouch touch;                       ///< what the scan did to the obstacle grid
  std::vector<ObstacleUpdate> updates;   ///< monitoring diffs of shared obstacles, already applied here
};

/// @brief Result of applying an obstacle from the handler.
struct ApplyResult
{
  bool ok = false;
  bool added = false;          ///< the uuid was new
  std::size_t changed = 0;     ///< cells whose presence changed
  std::string error;           ///< why not, when !ok
};

/// @brief Bounds in world coordinates touched since the last call to takeDirtyBounds.
struct WorldBounds
{
  double min_x, min_y, max_x, max_y;
  bool empty() const { return max_x < min_x || max_y < min_y; }
};

/**
 * @brief The sharing layer without ROS: an obstacle grid, shareable-cell tracking, proposals on a
 * debounced trigger, shared obstacles with monitoring, and an overlay into a master grid.
 *
 * The costmap_2d plugin and the project's navigation host both drive this class; all times are
 * passed in, in seconds.
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
   * @brief Clears and marks one observation, updates the shareable cells and monitors every shared
   * obstacle in view. Monitoring diffs are applied here and returned for the handler.
   */
  ScanOutcome processScan(const Observation& observation, double now_s);

  /// @brief A "cannot get past" signal; @return true when it starts a burst (then call propose)
  bool signalStuck(double now_s) { return trigger_.signal(now_s); }

  /// @brief Groups the current shareable cells into proposals, with the configured strategy.
  std::vector<Proposal> propose(double robot_x, double robot_y) const;

  /**
   * @brief Applies an obstacle from the handler (authorised proposal, or external add/update).
   * An unknown uuid is added with now_s as its arrival time. Bad input is rejected with a reason and
   * changes nothing.
   */
  ApplyResult applyShared(const ObstacleUpdate& update, double now_s);

  /// @brief Removes an expired obstacle; @return false when the uuid is unknown
  bool expire(const std::string& uuid);

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

  /// @brief World bounds of shared cells added or removed since the last call, then forgets them.
  WorldBounds takeDirtyBounds();

  const CostGrid& obstacleGrid() const { return obstacles_; }
  CostGrid& obstacleGrid() { return obstacles_; }
  /// @return the current shareable cells, sorted
  std::vector<std::uint32_t> shareableCells() const;
  const std::map<std::string, SharedObstacle>& sharedObstacles() const { return shared_; }
  /// @return present cells of one obstacle (empty when unknown)
  std::vector<std::uint32_t> sharedCells(const std::string& uuid) const;

private:
  void trackShareable(const ScanTouch& touch, const Observation& observation);
  void markDirty(const std::vector<std::uint32_t>& cells);
  bool insideMonitoredRectangle(std::uint32_t index) const { return monitored_[index] != 0; }
  void countRectangle(const CellRect& rect, int delta);

  LayerParams params_;
  CostGrid obstacles_;
  StaticMapFilter static_filter_;
  TriggerDebounce trigger_;
  std::vector<std::uint32_t> shareable_;
  std::vector<std::uint8_t> is_shareable_;
  std::vector<std::uint16_t> monitored_;  ///< per cell: how many monitored rectangles cover it
  std::map<std::string, SharedObstacle> shared_;
  WorldBounds dirty_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SHARING_CORE_H
