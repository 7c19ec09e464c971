#ifndef SHARING_LAYER_SHARING_CORE_H
#define SHARING_LAYER_SHARING_CORE_H

#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "sharing_layer/cost_grid.h"
#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/observation.h"
#include "sharing_layer/proposals.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/static_filter.h"
#include "sharing_layer/trigger.h"

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

/// @brief Where a trigger came from.
enum class TriggerSource
{
  StuckFeedback,   ///< std_msgs/Empty from a local planner that cannot get past
  RecoveryStatus,  ///< move_base/recovery_status of an unmodified move_base
  PlanBlocked,     ///< newly marked cells on the current global plan (checkPlan)
  Manual,          ///< a test or a tool
};

/// @return "stuck_feedback", "recovery_status", "plan_blocked" or "manual"
const char* triggerSourceName(TriggerSource source);
/// @brief Parses a triggerSourceName(); @throws std::invalid_argument naming the bad value
TriggerSource parseTriggerSource(const std::string& name);

/// @brief What a trigger did.
enum class TriggerReason
{
  None,           ///< no trigger (checkPlan: nothing new on the plan); nothing to log
  Proposed,       ///< proposals were made
  Debounced,      ///< inside the debounce window of an earlier trigger of the same kind
  NothingMarked,  ///< no non-static cell marked near the robot recently
  OutOfRange,     ///< remembered cells exist, but none within trigger_radius / obstacle_range of the robot
  Static,         ///< everything marked near the robot is part of the static map (within static_tolerance)
  AlreadyShared,  ///< the cells lie in rectangles of obstacles already shared
  TooSmall,       ///< candidate groups were smaller than min_cluster_cells
  FleetRobot,     ///< every candidate cell lies within a known fleet robot's footprint (plus margin)
};

/// @return "none", "proposed", "debounced", "nothing_marked", "out_of_range", "static", "already_shared", "too_small",
/// "fleet_robot"
const char* triggerReasonName(TriggerReason reason);

/// @brief Outcome of one trigger, for the caller to publish the proposals and log the message.
struct TriggerReport
{
  TriggerSource source = TriggerSource::Manual;
  TriggerReason reason = TriggerReason::None;
  bool log = false;                  ///< log the message (once per trigger; repeats of a debounced burst are quiet)
  std::vector<Proposal> proposals;   ///< empty unless reason == Proposed
  std::string message;               ///< one human-readable line: source, what was proposed or why nothing
};

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

/**
 * @brief The same update on another grid, for a layer whose grid is not the sender's (a rolling window, a map of
 * another size or origin): each cell goes to the cell of `to` holding its centre, a marked cell winning over a
 * cleared one that lands on the same cell; cells off `to` are dropped and counted in `dropped`. Everything else
 * (uuid, rectangle in world coordinates, version, deadline, source, stamp) is kept.
 * @throws std::invalid_argument naming the obstacle when an index lies outside the update's own grid
 */
ObstacleUpdate reprojectUpdate(const ObstacleUpdate& update, const GridGeometry& to, std::size_t* dropped = nullptr);

/// @brief What moving the layer onto another grid (SharingCore::moveTo) kept and dropped.
struct MoveReport
{
  std::size_t shared_cells_dropped = 0;    ///< present shared cells whose centre lies off the new grid
  std::size_t obstacles_out_of_grid = 0;   ///< shared obstacles left with no present cell on it (still held)
  std::size_t obstacle_cells_kept = 0;     ///< lethal cells of the own obstacle grid carried over
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
  bool signalStuck(double now_s) { return trigger_.signal(now_s); }

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
  const std::vector<std::pair<double, double>>& plan() const { return plan_; }

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
  const std::map<std::string, SharedObstacle>& sharedObstacles() const { return shared_; }
  /// @return present cells of one obstacle (empty when unknown)
  std::vector<std::uint32_t> sharedCells(const std::string& uuid) const;

private:
  void trackShareable(const ScanTouch& touch, const Observation& observation, double obstacle_range);
  void rebuildStaticFilter();
  /// @brief Sets the static source `bit` (kStaticOccupied or kStaticUnknown) where is_set(index), clears it elsewhere.
  template <class IsSet>
  void setStaticSource(std::uint8_t bit, IsSet is_set);
  void dropStaticCandidates();
  void remember(const ScanTouch& touch, const std::vector<std::uint32_t>& occupied, const Observation& observation,
                double now_s);
  /// @brief Shareable cells plus remembered cells within trigger_radius of (x, y), not static, not shared.
  /// Cells of known fleet robots are left out unless with_robots.
  std::vector<std::uint32_t> candidates(double robot_x, double robot_y, bool use_memory,
                                        bool with_robots = false) const;
  std::vector<Proposal> group(const std::vector<std::uint32_t>& cells, double robot_x, double robot_y) const;
  /// @brief Fills reason and message for a trigger that proposed nothing.
  void explainNothing(TriggerReport& report, double robot_x, double robot_y, bool use_memory) const;
  /// @brief Indexes of plan poses ahead of the robot that lie within reach of it.
  std::vector<std::size_t> planAhead(double robot_x, double robot_y, double reach) const;
  bool nearPlan(std::uint32_t index, const std::vector<std::size_t>& ahead) const;
  void markDirty(const std::vector<std::uint32_t>& cells);
  bool insideMonitoredRectangle(std::uint32_t index) const { return monitored_.test(index); }
  /// @brief Sets (or clears) monitored_ over a rectangle of cells.
  void markMonitored(const CellRect& rect, bool monitored);
  /// @brief After an obstacle left: clears monitored_ over its rectangle but where another still covers it.
  void unmarkMonitored(const CellRect& rect);
  /// @brief The union of the monitored rectangles: an obstacle's rectangle only grows (merging), here as in
  /// the handler, so its monitoring covers every cell the fleet added to it.
  void growRectangle(SharedObstacle& obstacle, const Subsection& rectangle);
  /// @brief Growing: shareable cells (non-static, marked, in obstacle_range) that touch the obstacle's present
  /// cells, within cluster_gap, directly or through each other, are part of it: they join `marked` and the
  /// rectangle grows over them. Only cells marked steadily count: in clearing_scans scans in a row over
  /// clearing_time (the evidence that clears a cell, mirrored), which needs the trigger memory (trigger_memory > 0). A block first seen in part (the plan trigger fires on its first cells) ends
  /// whole in the fleet as the robot sees more of it, instead of its rest waiting for a trigger that may
  /// never come (navfn's detour no longer runs into it).
  void growInto(SharedObstacle& obstacle, std::vector<std::uint32_t>& steady, std::vector<std::uint32_t>& marked);
  /// @brief Shareable cells marked steadily (the candidates of growInto; those it takes leave the list), into
  /// `steady`; also flags them in cell_flags_, which processScan resets.
  void steadyShareable(std::vector<std::uint32_t>& steady);
  /// @return whether a flagged steady cell lies within gap cells around the rectangle, outside it
  bool steadyInRing(const CellRect& rect, int gap) const;
  /// @brief moveTo, onto a caller's buffer when costs is not null.
  MoveReport moveGrid(const GridGeometry& geometry, bool keep_observations, std::uint8_t* costs,
                      std::uint8_t default_value);
  /// @brief Rebuilds view_index_ when obstacles came, went or grew (view_index_stale_).
  void refreshViewIndex();
  /// @return the remembered cell at index, or memory_.end(). Most cells asked about (watched cells, shareable
  /// cells) are not remembered: kRememberedFlag spares them the hash lookup.
  std::unordered_map<std::uint32_t, RememberedCell>::iterator findRemembered(std::uint32_t index)
  {
    return (cell_flags_[index] & kRememberedFlag) ? memory_.find(index) : memory_.end();
  }
  /// @brief Flags every present shared cell in cell_flags_ (ScanWatch::kFlaggedWatched) and sets each obstacle's
  /// present_box, when the present cells changed since the last call (shared_flags_stale_).
  void refreshSharedFlags();
  /// @brief Cells inside a new or grown rectangle stop being this robot's candidates: monitoring has them.
  void dropShareableInside(const CellRect& rect);

  LayerParams params_;
  CostGrid obstacles_;
  StaticMapFilter static_filter_;
  TriggerDebounce trigger_;
  TriggerDebounce plan_trigger_;
  /// Per cell, one bit each: where a shared obstacle's rectangle covers it, and what the static filter is built
  /// from (kept to rebuild it when one of them changes; allocated once given): a wall in the last setStaticMap,
  /// unknown in the last setUnknownMap.
  BitGrid monitored_;
  BitGrid static_occupied_;
  BitGrid static_unknown_;
  std::uint8_t static_source_bits_ = 0;  ///< the static sources given so far
  static constexpr std::uint8_t kStaticOccupied = 1;
  static constexpr std::uint8_t kStaticUnknown = 2;
  std::unordered_map<std::uint32_t, RememberedCell> memory_;
  std::vector<std::pair<double, double>> plan_;
  std::vector<std::uint32_t> last_new_marked_;  ///< non-static cells the last scan marked that were not lethal before
  std::vector<std::uint32_t> last_far_hits_;    ///< endpoints of the last scan beyond obstacle_range, within raytrace_range
  std::size_t last_static_marked_ = 0;          ///< static cells the last scan marked
  double last_scan_time_ = 0.0;
  double last_origin_x_ = 0.0;  ///< sensor origin of the last scan (NaN before the first)
  double last_origin_y_ = 0.0;
  std::vector<std::uint32_t> shareable_;

  /// Per-cell flags, one byte for all: ScanWatch::kFlaggedWatched on every present shared cell (kept between scans,
  /// so a scan does not list them: refreshSharedFlags), applyScan's own bits during a scan, kShareableFlag on the
  /// cells of shareable_, kRememberedFlag on the cells of memory_, and kSteadyFlag on the current scan's growth
  /// candidates (steadyShareable) until processScan resets them.
  std::vector<std::uint8_t> cell_flags_;
  static constexpr std::uint8_t kSteadyFlag = 0x80;
  static constexpr std::uint8_t kRememberedFlag = 0x40;  ///< the cell is in memory_ (kept with it)
  static constexpr std::uint8_t kShareableFlag = 0x20;   ///< the cell is in shareable_ (kept with it)
  std::vector<std::uint32_t> flagged_cells_;  ///< cells flagged kFlaggedWatched
  bool shared_flags_stale_ = true;            ///< present shared cells changed since refreshSharedFlags
  std::map<std::string, SharedObstacle> shared_;
  /// The shared obstacles with cells on the grid and their rectangles, side by side: the in-view test of every scan.
  struct ViewEntry
  {
    Subsection rectangle;
    SharedObstacle* obstacle;
  };
  std::vector<ViewEntry> view_index_;
  bool view_index_stale_ = true;
  /// A scan's temporaries, kept so that a scan does not allocate them again (their contents mean nothing between
  /// scans).
  struct ScanBuffers
  {
    std::vector<SharedObstacle*> in_view;
    ScanWatch watch;
    std::vector<std::uint32_t> not_lethal_before, grazed, marked_known, signs, occupied, marked_watched, seen_again,
        steady, steady_all, marked, cleared;
  };
  ScanBuffers buffers_;
  WorldBounds dirty_;
  FleetRobots fleet_robots_;  ///< fleet robots' footprints: never shared
  std::vector<std::uint32_t> last_robot_marked_;  ///< non-static cells the last scan marked on fleet robots
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SHARING_CORE_H
