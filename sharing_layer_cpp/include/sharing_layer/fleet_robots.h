#ifndef SHARING_LAYER_FLEET_ROBOTS_H
#define SHARING_LAYER_FLEET_ROBOTS_H

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/grid_geometry.h"

namespace sharing_layer
{
/// @brief Parameters of the fleet-robot exclusion (DESIGN §6: fleet robots are never obstacles).
struct FleetRobotParams
{
  double margin = 0.2;   ///< robot_exclusion_margin: m around a footprint whose cells are excluded too
  double timeout = 3.0;  ///< robot_timeout: s after its last refresh that a robot is forgotten (0: never)
  /// robot_exclusion_trail: s that a robot's past footprints stay excluded. A layer marks a scan at its next
  /// costmap update, against a peer's newest footprint: a peer driving away has moved on since the scan saw its
  /// back (in the ten-robot fleet bench 0.05-0.08 m beyond footprint + margin, shared as an obstacle).
  double trail = 1.0;

  /// @throws std::invalid_argument naming the parameter and its value
  void validate() const;
};

/// @brief One fleet robot as the layer knows it: its footprint placed at its pose, in the grid's frame.
struct FleetRobot
{
  std::string name;                                   ///< the robot's name (its bridge's robot_name)
  std::vector<std::pair<double, double>> footprint;   ///< polygon vertices, world (x, y) in the grid's frame
  double stamp = 0.0;                                 ///< when it was last refreshed, s (the layer's clock)
};

/// Largest extent (m, either axis) of an accepted footprint: a robot, not a building.
constexpr double kMaxFootprintExtent = 50.0;
/// Most vertices of an accepted footprint.
constexpr std::size_t kMaxFootprintPoints = 1000;
/// Longest robot_exclusion_trail, s: a costmap marks a scan within a second or two of taking it.
constexpr double kMaxTrail = 10.0;
/// Most past footprints kept per robot (a robot refreshed at 10 Hz keeps ten for the default 1 s trail).
constexpr std::size_t kMaxTrailFootprints = 64;
/// Fastest a fleet robot drives, m/s, for its footprints to make one trail: a footprint farther from one kept
/// than this speed allows in the time between them (plus kTrailSlack) starts the trail anew. A peer's login
/// does not make its adverts true: one racing its footprint about would otherwise leave up to
/// kMaxTrailFootprints footprints along a path it made up, none of whose cells the layer would share.
constexpr double kMaxTrailSpeed = 5.0;
/// m of a robot's advertised position the time between two footprints does not account for: a dead-reckoned
/// footprint corrected by the next advert, stamps taken when a bridge heard it.
constexpr double kTrailSlack = 0.5;

/**
 * @brief The fleet robots a layer knows, and the grid cells they cover: every cell whose centre lies
 * inside a robot's footprint polygon or within `margin` of its outline. The sharing core never shares
 * those cells (proposals, trigger memory, plan trigger, marked cells of monitoring updates): a robot
 * waiting near a block is not an obstacle of the fleet.
 *
 * Robots not refreshed within `timeout` are forgotten by expire(). ROS-free; times are passed in.
 */
class FleetRobots
{
public:
  /// @throws std::invalid_argument on bad parameters
  explicit FleetRobots(const GridGeometry& geometry, const FleetRobotParams& params = FleetRobotParams());

  const FleetRobotParams& params() const { return params_; }
  /// @brief Changes margin / timeout; the excluded cells are recomputed. @throws std::invalid_argument
  void setParams(const FleetRobotParams& params);

  /**
   * @brief Adds or refreshes one robot. @throws std::invalid_argument (and changes nothing) on an empty
   * name, no vertex, more than kMaxFootprintPoints vertices, a non-finite vertex or stamp, or a footprint
   * wider than kMaxFootprintExtent.
   */
  void update(const FleetRobot& robot);
  /// @brief As update(robot); when the robot moved since `previous` (its last known footprint), the footprint
  /// moved on by as much is excluded too, so a driving robot's front is covered until its next refresh.
  /// Its footprints of the last `trail` s (by its stamps) stay excluded behind it; a jump of more than 2 m
  /// (relocalised, restarted), a stamp older than the last one, or a footprint no robot drives to from a kept
  /// one in the time between them (kMaxTrailSpeed) ends that trail.
  void update(const FleetRobot& robot, const FleetRobot* previous, std::pair<double, double> motion);

  /**
   * @brief The whole known set at once (a fleet_robots message): robots not in it are forgotten.
   * All robots are validated first; @throws std::invalid_argument naming the bad one and changes nothing.
   * A name listed twice keeps its last entry.
   */
  void replaceAll(const std::vector<FleetRobot>& robots);

  /// @brief Moves onto another grid (a resized or moved costmap): the known robots, with their motion, are
  /// excluded anew in it.
  void setGeometry(const GridGeometry& geometry);

  /// @return false when the name is unknown
  bool forget(const std::string& name);
  /// @brief Forgets everything.
  void clear();

  /// @brief Forgets robots whose stamp is more than timeout away from now_s (older, or from a clock
  /// that went backwards); timeout 0 keeps them. @return the names forgotten, sorted
  std::vector<std::string> expire(double now_s);

  /// @return whether a cell lies within a known robot's footprint plus margin (no bounds check)
  bool excludes(std::uint32_t index) const { return !excluded_.empty() && excluded_.test(index); }
  /// @return bytes it keeps per grid (a bit per cell once a robot was known)
  std::size_t gridBytes() const { return excluded_.bytes(); }
  /// @return the excluded cells, sorted
  std::vector<std::uint32_t> excludedCells() const;
  /// @return names of the known robots who cover a cell, sorted
  std::vector<std::string> robotsAt(std::uint32_t index) const;

  /// @return known robot names, sorted
  std::vector<std::string> names() const;
  const std::map<std::string, FleetRobot>& robots() const { return robots_; }
  std::size_t size() const { return robots_.size(); }
  bool empty() const { return robots_.empty(); }

  /// @brief The cells a footprint covers with a margin, sorted (what update() excludes for it).
  static std::vector<std::uint32_t> rasterize(const GridGeometry& geometry,
                                              const std::vector<std::pair<double, double>>& footprint, double margin);

  /// @brief What update() refuses: @throws std::invalid_argument naming the robot and the fault
  static void check(const FleetRobot& robot);

private:
  /// @brief One footprint a robot had (the last: has), from `stamp` until its next one, with the cells it covers.
  struct PastFootprint
  {
    double stamp = 0.0;
    std::vector<std::pair<double, double>> footprint;
    std::pair<double, double> centroid;
    std::vector<std::uint32_t> cells;
  };

  /// @brief Ends every exclusion but keeps what is known of the robots (their footprints, motion, trails).
  void clearCells();
  /// @brief Excludes the known robots anew (after the grid or the margin changed): their trails re-rasterized.
  void rebuild();
  /// @brief Whether a robot at `here` at `stamp` could have driven from every footprint kept (kMaxTrailSpeed).
  static bool drivable(const std::deque<PastFootprint>& past, std::pair<double, double> here, double stamp);
  /// @brief The union of sorted cell lists, sorted, without duplicates.
  std::vector<std::uint32_t> unite(const std::vector<const std::vector<std::uint32_t>*>& parts);
  /// @brief Excludes cells (a robot's new footprint).
  void include(const std::vector<std::uint32_t>& cells);
  /// @brief Ends the exclusion of a robot's cells (its entry in cells_), except where another robot covers them.
  void release(const std::vector<std::uint32_t>& cells);

  GridGeometry geometry_;
  FleetRobotParams params_;
  std::map<std::string, FleetRobot> robots_;
  std::map<std::string, std::vector<std::uint32_t>> cells_;   ///< per robot: the cells it excludes
  std::map<std::string, std::pair<double, double>> motion_;   ///< per robot: its move between its last two adverts
  std::map<std::string, std::deque<PastFootprint>> trail_;    ///< per robot: its footprint now and of the last trail s
  BitGrid excluded_;  ///< per cell: within a known robot's footprint plus margin (allocated on the first robot)
  std::vector<std::uint64_t> scratch_;  ///< unite()'s bits, kept between calls
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_FLEET_ROBOTS_H
