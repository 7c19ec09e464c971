#ifndef SHARING_LAYER_FLEET_OBSTACLES_H
#define SHARING_LAYER_FLEET_OBSTACLES_H

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/cell_flags.h"
#include "sharing_layer/grid_frame.h"
#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/layer_params.h"
#include "sharing_layer/obstacle_index.h"
#include "sharing_layer/observed_cells.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/subsection.h"

namespace sharing_layer
{
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
  static WorldBounds none();
};

/// @brief What one scan tells the monitoring of the shared obstacles in view (sorted cell lists of this scan).
struct ScanEvidence
{
  /// cells it marked inside a monitored rectangle, neither static nor on a fleet robot (neither is a new cell nor an
  /// observation of the obstacle)
  const std::vector<std::uint32_t>& marked_watched;
  const std::vector<std::uint32_t>& occupied;        ///< signs of occupancy among the watched cells
  const std::vector<std::uint32_t>& seen_free;       ///< watched cells a beam passed well beyond
  std::vector<std::uint32_t>& steady;                ///< growth candidates; an obstacle that takes one removes it
  CellRect steady_box;                               ///< their bounding box
};

/**
 * @brief The fleet's obstacles as this robot holds them, and what this robot's scans do to them:
 * - apply: an update from the handler (an authorised proposal, a peer's update) joins its obstacle's versioned cells;
 * - monitor: each scan, the obstacles in view gather evidence of free space (a cell clears after clearing_scans
 *   scans over clearing_time), their present cells seen occupied again, and shareable cells marked steadily beside
 *   them (grow); what changed becomes this robot's update for the fleet;
 * - leases: an observation (marked cells, any robot's) renews an obstacle; a scan that sees it again sends one
 *   when nobody did for lease_renewal_interval;
 * - expiry: the handler ends an obstacle (expire).
 * Owns the obstacles, their monitored rectangles (a bit per cell), their index (ObstacleIndex: the in-view test, the
 * draw, the present cells' watch bit in CellFlags) and the bounds dirtied for the master grid.
 */
class FleetObstacles
{
public:
  /// @brief cell_count: the grid's cells (the monitored bits).
  explicit FleetObstacles(std::size_t cell_count);

  const std::map<std::string, SharedObstacle>& obstacles() const { return shared_; }
  /// @return present cells of one obstacle (empty when unknown)
  std::vector<std::uint32_t> presentCells(const std::string& uuid) const;
  /// @brief Whether a shared obstacle's rectangle covers the cell (monitoring has it, this robot does not propose it).
  bool monitored(std::uint32_t index) const { return monitored_.test(index); }
  std::size_t bytes() const { return monitored_.bytes(); }

  /// @brief Applies an update; bad input is rejected with a reason and changes nothing. Cells of a new or grown
  /// rectangle stop being shareable in `observed`.
  ApplyResult apply(const ObstacleUpdate& update, double now_s, const GridGeometry& g, std::size_t max_update_cells,
                    ObservedCells& observed, CellFlags& flags);
  /// @return false when the uuid is unknown
  bool expire(const std::string& uuid, const GridGeometry& g);

  // The scan pass.
  /// @brief Flags every present cell (ScanWatch::kFlaggedWatched) and sets each obstacle's present_box, when the
  /// present cells changed since the last call.
  void refreshWatchFlags(const GridGeometry& g, CellFlags& flags);
  /// @brief The obstacles whose rectangle lies within radius of (x, y), and the boxes of their present cells.
  void inView(double x, double y, double radius, std::vector<SharedObstacle*>& in_view,
              std::vector<CellRect>& present_boxes);
  /// @brief Monitors the obstacles in view with one scan's evidence; their changes are applied here and appended to
  /// `updates`, as this robot's (params.robot_name) updates for the fleet.
  void monitor(const std::vector<SharedObstacle*>& in_view, ScanEvidence& evidence, double now_s,
               const LayerParams& params, const GridGeometry& g, ObservedCells& observed, CellFlags& flags,
               std::vector<ObstacleUpdate>& updates);

  // The master grid.
  /// @brief Sets every present cell inside the cell window [min_i, max_i) x [min_j, max_j) (clipped to g) to lethal
  /// in a master grid of g's size; touches nothing outside the window and never lowers a cost.
  void draw(std::uint8_t* master, const GridGeometry& g, int min_i, int min_j, int max_i, int max_j) const;
  WorldBounds takeDirtyBounds();

  /**
   * @brief Onto another grid (the grid frame): every obstacle's cells, tombstones and version stamps included, move
   * where mover puts them (off the grid: dropped and counted); an obstacle with none left is still held, for its
   * updates and expiry. Rectangles are recomputed and monitored again; the watch flags start anew (flags is the
   * new grid's).
   */
  void moveTo(const CellMover& mover, const GridGeometry& geometry, ObservedCells& observed, CellFlags& flags,
              MoveReport& report);

private:
  /// @brief Sets (or clears) the monitored bits over a rectangle of cells.
  void markMonitored(const CellRect& rect, bool monitored, const GridGeometry& g);
  /// @brief After an obstacle left: clears the bits over its rectangle but where another still covers it.
  void unmarkMonitored(const CellRect& rect, const GridGeometry& g);
  /// @brief The union of the rectangles: an obstacle's rectangle only grows (merging), here as in the handler, so
  /// its monitoring covers every cell the fleet added to it. @return whether it grew
  bool growRectangle(SharedObstacle& obstacle, const Subsection& rectangle, const GridGeometry& g,
                     ObservedCells& observed, CellFlags& flags);
  /**
   * @brief Growing: steady shareable cells that touch the obstacle's present cells within cluster_gap, directly or
   * through each other, join `marked` and the rectangle grows over them. A block first seen in part (the plan
   * trigger fires on its first cells) ends whole in the fleet as the robot sees more of it, instead of its rest
   * waiting for a trigger that may never come (navfn's detour no longer runs into it).
   */
  void growInto(SharedObstacle& obstacle, std::vector<std::uint32_t>& steady, std::vector<std::uint32_t>& marked,
                int gap, const GridGeometry& g, ObservedCells& observed, CellFlags& flags);
  /// @return whether one of the (growth candidate) cells lies within gap cells around the rectangle, outside it
  static bool steadyInRing(const CellRect& rect, int gap, const GridGeometry& g,
                           const std::vector<std::uint32_t>& steady);
  /// @brief One obstacle in view: its evidence into marked/cleared cells; @return whether it has an update
  bool monitorOne(SharedObstacle& obstacle, ScanEvidence& evidence, double now_s, const LayerParams& params,
                  const GridGeometry& g, ObservedCells& observed, CellFlags& flags);
  void markDirty(const std::vector<std::uint32_t>& cells, const GridGeometry& g);

  std::map<std::string, SharedObstacle> shared_;
  BitGrid monitored_;  ///< a bit per cell (in tiles): a shared obstacle's rectangle covers it
  ObstacleIndex index_;  ///< the obstacles side by side, and their present cells' watch flags
  WorldBounds dirty_ = WorldBounds::none();
  /// One obstacle's changes during monitor (kept so that a scan does not allocate them again).
  std::vector<std::uint32_t> marked_, cleared_, seen_again_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_FLEET_OBSTACLES_H
