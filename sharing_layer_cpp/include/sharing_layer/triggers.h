#ifndef SHARING_LAYER_TRIGGERS_H
#define SHARING_LAYER_TRIGGERS_H

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "sharing_layer/cell_flags.h"
#include "sharing_layer/fleet_obstacles.h"
#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/layer_params.h"
#include "sharing_layer/observed_cells.h"
#include "sharing_layer/proposals.h"
#include "sharing_layer/scan_pass.h"
#include "sharing_layer/static_mask.h"

namespace sharing_layer
{
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

/**
 * @brief Debounces the "cannot get past" signal.
 *
 * A stuck local planner reports failure at its control rate (10 Hz); only the first signal
 * of a burst fires. A burst ends when no signal came for longer than the window. Time going
 * backwards (a simulation restart) starts a new burst.
 */
class TriggerDebounce
{
public:
  /// @throws std::invalid_argument when window_s is negative or not finite
  explicit TriggerDebounce(double window_s = 2.0);

  /// @brief Registers a signal at now_s; @return true when it starts a new burst
  bool signal(double now_s);
  double window() const { return window_; }
  /// @brief A new window from the next signal on (the current burst's last signal is kept);
  /// @throws std::invalid_argument when negative or not finite, and changes nothing
  void setWindow(double window_s);
  /// @return signals in the current burst, the last one included (1 right after a burst started)
  unsigned long burstSignals() const { return burst_signals_; }

private:
  double window_;
  double last_signal_ = -std::numeric_limits<double>::infinity();
  unsigned long burst_signals_ = 0;
};

/// @brief What the triggers read, lent by SharingCore for one call.
struct TriggerInputs
{
  const LayerParams& params;
  const GridGeometry& geometry;
  const ObservedCells& observed;  ///< the candidates: shareable cells and trigger memory
  const CellFlags& flags;
  const FleetObstacles& fleet;    ///< cells in shared rectangles are not proposed again
  const StaticMask& statics;
  const FleetRobots& robots;      ///< their cells are never proposed
  const LastScan& last;           ///< what the last scan marked
};

/// m: base_local_planner's prunePlan (TrajectoryPlannerROS, and DWA with prune_plan) keeps a global plan from its
/// first pose within this distance of the robot on, and drops all of it when no pose is that near
constexpr double kLocalPlannerPlanReach = 1.0;

/// @brief Distance from (robot_x, robot_y) to the nearest finite pose of `plan`; infinity when it has none. Above
/// kLocalPlannerPlanReach move_base's local planner finds no valid control: NavfnROS, for one, returns a route
/// longer than twice its costmap's width cut short, starting part of the way along.
double nearestPlanDistance(const std::vector<std::pair<double, double>>& plan, double robot_x, double robot_y);
/// @brief Whether a plan whose nearest pose is `gap` m from the robot is dropped by move_base's local planner
inline bool outOfLocalPlannerReach(double gap) { return gap > kLocalPlannerPlanReach; }

/**
 * @brief When this robot proposes an obstacle to the fleet, and what:
 * - the stuck triggers (stuck_feedback, recovery_status, manual), one debounce window for all of them;
 * - the plan-blocked trigger: cells the last scan newly marked on the plan ahead, on its own window;
 * - the candidates both draw from (shareable cells, trigger memory) and how they are grouped into proposals;
 * - the explanation of a trigger that proposed nothing, one line a field engineer can act on.
 * Owns the two debounces and the plan.
 */
class Triggers
{
public:
  /// @throws std::invalid_argument when debounce_s is negative or not finite
  explicit Triggers(double debounce_s) : stuck_(debounce_s), plan_trigger_(debounce_s) {}

  /// @brief A "cannot get past" signal; @return true when it starts a burst
  bool signalStuck(double now_s) { return stuck_.signal(now_s); }
  /// @param robots the fleet robots of `in`, expired at now_s once the trigger is taken (the one write a trigger
  /// makes outside its own state)
  TriggerReport trigger(TriggerSource source, double now_s, double robot_x, double robot_y, FleetRobots& robots,
                        const TriggerInputs& in);
  TriggerReport checkPlan(double robot_x, double robot_y, double now_s, FleetRobots& robots, const TriggerInputs& in);
  std::vector<Proposal> propose(double robot_x, double robot_y, bool use_memory, const TriggerInputs& in) const;

  /// @brief Keeps the finite poses; @return whether any is left
  bool setPlan(const std::vector<std::pair<double, double>>& poses);
  /// @brief trigger_debounce for both windows, from the next signal on; @throws std::invalid_argument when
  /// negative or not finite, and changes nothing
  void setDebounce(double debounce_s)
  {
    TriggerDebounce check(debounce_s);
    (void)check;
    stuck_.setWindow(debounce_s);
    plan_trigger_.setWindow(debounce_s);
  }
  const std::vector<std::pair<double, double>>& plan() const { return plan_; }

private:
  /// @brief Shareable cells plus remembered cells within trigger_radius of (x, y) beyond obstacle_range of the last
  /// scan's origin, not static, not shared. Cells of known fleet robots are left out unless with_robots.
  std::vector<std::uint32_t> candidates(double robot_x, double robot_y, bool use_memory, const TriggerInputs& in,
                                        bool with_robots = false) const;
  std::vector<Proposal> group(const std::vector<std::uint32_t>& cells, double robot_x, double robot_y,
                              const TriggerInputs& in) const;
  /// @brief Fills reason and message for a trigger that proposed nothing.
  void explainNothing(TriggerReport& report, double robot_x, double robot_y, bool use_memory,
                      const TriggerInputs& in) const;
  /// @brief explainNothing when fleet robots explain it: @return false when they do not
  bool explainFleetRobots(TriggerReport& report, double robot_x, double robot_y, bool use_memory,
                          const TriggerInputs& in) const;
  /// @brief Indexes of plan poses ahead of the robot that lie within reach of it.
  std::vector<std::size_t> planAhead(double robot_x, double robot_y, double reach) const;
  bool nearPlan(std::uint32_t index, const std::vector<std::size_t>& ahead, const TriggerInputs& in) const;
  /// @brief The clusters of candidate cells and far endpoints that touch the plan ahead.
  std::vector<Proposal> planProposals(double robot_x, double robot_y, const std::vector<std::size_t>& ahead,
                                      const TriggerInputs& in) const;

  TriggerDebounce stuck_;
  TriggerDebounce plan_trigger_;
  std::vector<std::pair<double, double>> plan_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_TRIGGERS_H
