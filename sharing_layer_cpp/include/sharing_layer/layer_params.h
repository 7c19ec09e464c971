#ifndef SHARING_LAYER_LAYER_PARAMS_H
#define SHARING_LAYER_LAYER_PARAMS_H

#include <cstddef>
#include <cstdint>
#include <string>

#include "sharing_layer/proposals.h"
#include "sharing_layer/scan_update.h"

namespace sharing_layer
{
/// @brief Parameters of the sharing layer, with the defaults of the original AGVs.
struct LayerParams
{
  ScanLimits limits;                       ///< obstacle_range 2.5, raytrace_range 3.0, heights 0..2
  int static_tolerance = 3;                ///< cells around the static (or unknown) map that are never shared: 0.3 m on a 0.1 m map
  std::uint8_t static_occupied_cost = 254; ///< static costs at or above this are walls
  ProposalStrategy strategy = ProposalStrategy::Sectors;
  double trigger_debounce = 2.0;           ///< seconds without a stuck signal that end a burst
  unsigned int cluster_gap = 1;            ///< Clusters: cells within this Chebyshev distance join
  std::size_t min_cluster_cells = 1;       ///< Clusters: smaller groups are not proposed
  double rectangle_padding = 0.0;          ///< metres added around a proposal's cells
  std::size_t max_update_cells = 1000000;  ///< larger updates are rejected
  std::string robot_name = "robot";        ///< source of this robot's updates
  // Evidence-based clearing of shared cells and remembered cells (the obstacle grid keeps costmap_2d's rules).
  double clearing_margin = 0.1;            ///< a beam is evidence of free space only when it ends this far (m) beyond the cell
  unsigned int clearing_scans = 3;         ///< scans with such evidence, without a sign of occupancy in between, that clear a cell
  double clearing_time = 1.0;              ///< ... and the time (s) from the first to the last of them
  unsigned int clearing_neighbours = 8;    ///< shadow filter: beams on each side whose endpoints also bound the evidence
  // Trigger memory: recently marked non-static cells, for triggers that come after the robot backed off.
  double trigger_memory = 30.0;            ///< seconds a marked cell is remembered (0: no memory)
  double trigger_radius = 4.0;             ///< a trigger proposes remembered cells within this distance (m) of the robot
  /// stuck_feedback comes at the moment of failure, with the block in view (fleet_nav): by default only
  /// recovery_status and manual triggers (and plan_blocked's clusters on the plan) use the memory, which
  /// otherwise also proposes bystanders such as another robot waiting within trigger_radius
  bool memory_on_stuck_feedback = false;
  // Plan-blocked trigger.
  double inscribed_radius = 0.25;          ///< new cells within this distance (m) of a plan pose ahead block the plan
  /// Leases: a scan that sees present cells of a shared obstacle occupied again sends them as marked (an
  /// observation, which renews the obstacle's deadline fleet-wide) when no observation of it, by any robot,
  /// has been applied here for this long (s). Bounds the traffic of a block many robots keep seeing.
  double lease_renewal_interval = 5.0;

  /// @throws std::invalid_argument naming the parameter and its value
  void validate() const;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_LAYER_PARAMS_H
