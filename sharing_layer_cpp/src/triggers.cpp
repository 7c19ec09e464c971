#include "sharing_layer/triggers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace sharing_layer
{
namespace
{
constexpr double kInf = std::numeric_limits<double>::infinity();

/// printf-style formatting of up to two doubles (a format using one ignores the second)
std::string format(const char* fmt, double a, double b)
{
  char buf[256];
  std::snprintf(buf, sizeof(buf), fmt, a, b);
  return buf;
}

std::string describeProposals(const std::vector<Proposal>& proposals)
{
  std::string out = "proposed " + std::to_string(proposals.size()) + " obstacle(s): ";
  for (std::size_t i = 0; i < proposals.size(); ++i)
  {
    out += (i ? "; " : "") + std::to_string(proposals[i].cells.size()) + " cells in " +
           proposals[i].rectangle.describe();
  }
  return out;
}

double squaredDistance(double ax, double ay, double bx, double by)
{
  return (ax - bx) * (ax - bx) + (ay - by) * (ay - by);
}

/// @return the index of the pose of `plan` nearest (x, y) and its squared distance; (0, infinity) when no pose is
/// finite (a pose that is not gives no finite distance, so it is never the nearest)
std::pair<std::size_t, double> nearestPose(const std::vector<std::pair<double, double>>& plan, double x, double y)
{
  std::size_t nearest = 0;
  double best = kInf;
  for (std::size_t i = 0; i < plan.size(); ++i)
  {
    const double d = squaredDistance(plan[i].first, plan[i].second, x, y);
    if (d < best)
    {
      best = d;
      nearest = i;
    }
  }
  return {nearest, best};
}

/// @return the centre of a cell, in the grid's frame
void cellCentre(const GridGeometry& g, std::uint32_t index, double& wx, double& wy)
{
  unsigned int mx = 0, my = 0;
  g.indexToCells(index, mx, my);
  g.mapToWorld(mx, my, wx, wy);
}
}  // namespace

const char* triggerSourceName(TriggerSource source)
{
  switch (source)
  {
    case TriggerSource::StuckFeedback:
      return "stuck_feedback";
    case TriggerSource::RecoveryStatus:
      return "recovery_status";
    case TriggerSource::PlanBlocked:
      return "plan_blocked";
    case TriggerSource::Manual:
      return "manual";
  }
  return "unknown";
}

TriggerSource parseTriggerSource(const std::string& name)
{
  for (TriggerSource source : { TriggerSource::StuckFeedback, TriggerSource::RecoveryStatus,
                                TriggerSource::PlanBlocked, TriggerSource::Manual })
  {
    if (name == triggerSourceName(source))
    {
      return source;
    }
  }
  throw std::invalid_argument("trigger source must be stuck_feedback, recovery_status, plan_blocked or manual, got \"" +
                              name + "\"");
}

const char* triggerReasonName(TriggerReason reason)
{
  switch (reason)
  {
    case TriggerReason::None:
      return "none";
    case TriggerReason::Proposed:
      return "proposed";
    case TriggerReason::Debounced:
      return "debounced";
    case TriggerReason::NothingMarked:
      return "nothing_marked";
    case TriggerReason::OutOfRange:
      return "out_of_range";
    case TriggerReason::Static:
      return "static";
    case TriggerReason::AlreadyShared:
      return "already_shared";
    case TriggerReason::TooSmall:
      return "too_small";
    case TriggerReason::FleetRobot:
      return "fleet_robot";
  }
  return "unknown";
}

TriggerDebounce::TriggerDebounce(double window_s) : window_(window_s)
{
  if (!std::isfinite(window_s) || window_s < 0.0)
  {
    throw std::invalid_argument("TriggerDebounce: trigger_debounce must be finite and >= 0, got " +
                                std::to_string(window_s));
  }
}

void TriggerDebounce::setWindow(double window_s)
{
  window_ = TriggerDebounce(window_s).window_;
}

bool TriggerDebounce::signal(double now_s)
{
  if (!std::isfinite(now_s))
  {
    return false;
  }
  const bool fires = now_s < last_signal_ || now_s - last_signal_ > window_;
  last_signal_ = now_s;
  burst_signals_ = fires ? 1 : burst_signals_ + 1;
  return fires;
}

// --- The stuck triggers: stuck_feedback, recovery_status, manual ---

TriggerReport Triggers::trigger(TriggerSource source, double now_s, double robot_x, double robot_y,
                                FleetRobots& robots, const TriggerInputs& in)
{
  TriggerReport report;
  report.source = source;
  report.log = true;
  report.message = std::string(triggerSourceName(source)) + " trigger at " + format("(%.2f, %.2f): ", robot_x, robot_y);
  if (!std::isfinite(now_s) || !std::isfinite(robot_x) || !std::isfinite(robot_y))
  {
    report.message += "ignored: time or robot pose not finite";
    return report;
  }
  robots.expire(now_s);
  if (!stuck_.signal(now_s))
  {
    report.reason = TriggerReason::Debounced;
    report.log = stuck_.burstSignals() == 2;  // once per burst
    report.message += format("debounced: less than trigger_debounce %.1f s after the previous signal (further "
                             "signals of this burst are not logged)",
                             in.params.trigger_debounce, 0.0);
    return report;
  }
  const bool use_memory = source == TriggerSource::RecoveryStatus || source == TriggerSource::Manual ||
                          (source == TriggerSource::StuckFeedback && in.params.memory_on_stuck_feedback);
  report.proposals = propose(robot_x, robot_y, use_memory, in);
  if (!report.proposals.empty())
  {
    report.reason = TriggerReason::Proposed;
    report.message += describeProposals(report.proposals);
    return report;
  }
  explainNothing(report, robot_x, robot_y, use_memory, in);
  return report;
}

std::vector<Proposal> Triggers::propose(double robot_x, double robot_y, bool use_memory, const TriggerInputs& in) const
{
  return group(candidates(robot_x, robot_y, use_memory, in), robot_x, robot_y, in);
}

std::vector<std::uint32_t> Triggers::candidates(double robot_x, double robot_y, bool use_memory,
                                                const TriggerInputs& in, bool with_robots) const
{
  std::vector<std::uint32_t> cells;
  const std::vector<std::uint32_t>& shareable = in.observed.shareable();
  cells.reserve(shareable.size());
  for (std::uint32_t index : shareable)
  {
    if (with_robots || !in.robots.excludes(index))
    {
      cells.push_back(index);
    }
  }
  if (use_memory && !in.observed.memory().empty() && std::isfinite(robot_x) && std::isfinite(robot_y))
  {
    const double radius_sq = in.params.trigger_radius * in.params.trigger_radius;
    const double range_sq = in.params.limits.obstacle_range * in.params.limits.obstacle_range;
    const bool have_origin = in.last.originKnown();
    for (const auto& entry : in.observed.memory())
    {
      const std::uint32_t index = entry.first;
      if (in.flags.has(index, CellFlags::kShareable) || in.fleet.monitored(index) || in.statics.isStatic(index) ||
          (!with_robots && in.robots.excludes(index)))
      {
        continue;
      }
      double wx = 0.0, wy = 0.0;
      cellCentre(in.geometry, index, wx, wy);
      const double sensor_sq = have_origin ? squaredDistance(wx, wy, in.last.origin_x, in.last.origin_y) : kInf;
      if (squaredDistance(wx, wy, robot_x, robot_y) <= radius_sq && sensor_sq >= range_sq)
      {
        cells.push_back(index);
      }
    }
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}

std::vector<Proposal> Triggers::group(const std::vector<std::uint32_t>& cells, double robot_x, double robot_y,
                                      const TriggerInputs& in) const
{
  if (cells.empty())
  {
    return {};
  }
  if (in.params.strategy == ProposalStrategy::Clusters)
  {
    return proposeByClusters(in.geometry, cells, in.params.cluster_gap, in.params.min_cluster_cells,
                             in.params.rectangle_padding);
  }
  return proposeBySectors(in.geometry, cells, robot_x, robot_y, in.params.rectangle_padding);
}

// --- Why a trigger proposed nothing ---

bool Triggers::explainFleetRobots(TriggerReport& report, double robot_x, double robot_y, bool use_memory,
                                  const TriggerInputs& in) const
{
  // Cells on fleet robots are neither shareable nor remembered: the last scan's marks on them explain it.
  std::vector<std::uint32_t> with_robots = candidates(robot_x, robot_y, use_memory, in, true);
  with_robots.insert(with_robots.end(), in.last.robot_marked.begin(), in.last.robot_marked.end());
  if (with_robots.empty() || !candidates(robot_x, robot_y, use_memory, in).empty())
  {
    return false;
  }
  std::vector<std::string> names;
  for (std::uint32_t index : with_robots)
  {
    for (std::string& name : in.robots.robotsAt(index))
    {
      names.push_back(std::move(name));
    }
  }
  std::sort(names.begin(), names.end());
  names.erase(std::unique(names.begin(), names.end()), names.end());
  std::string list;
  for (const std::string& name : names)
  {
    list += (list.empty() ? "" : ", ") + name;
  }
  report.reason = TriggerReason::FleetRobot;
  report.message += "nothing proposed: the cells marked near the robot lie within the footprint of fleet "
                    "robot(s) " + list +
                    format(" (plus robot_exclusion_margin %.2f m)", in.robots.params().margin, 0.0);
  return true;
}

void Triggers::explainNothing(TriggerReport& report, double robot_x, double robot_y, bool use_memory,
                              const TriggerInputs& in) const
{
  std::size_t near = 0, near_shared = 0, far = 0;
  double nearest = kInf;
  for (const auto& entry : in.observed.memory())
  {
    if (in.statics.isStatic(entry.first))
    {
      continue;
    }
    double wx = 0.0, wy = 0.0;
    cellCentre(in.geometry, entry.first, wx, wy);
    const double d = std::hypot(wx - robot_x, wy - robot_y);
    if (d <= in.params.trigger_radius)
    {
      ++near;
      near_shared += in.fleet.monitored(entry.first);
    }
    else
    {
      ++far;
      nearest = std::min(nearest, d);
    }
  }
  const LayerParams& p = in.params;
  if (explainFleetRobots(report, robot_x, robot_y, use_memory, in))
  {
    return;
  }
  if (!use_memory && candidates(robot_x, robot_y, true, in).size() > in.observed.shareable().size())
  {
    report.reason = TriggerReason::OutOfRange;
    report.message += format("nothing proposed: the recently marked cells near the robot lie beyond obstacle_range "
                             "%.2f m of the current view, and ",
                             p.limits.obstacle_range, 0.0);
    report.message += std::string(triggerSourceName(report.source)) +
                      " does not use the trigger memory (memory_on_stuck_feedback)";
  }
  else if (!candidates(robot_x, robot_y, use_memory, in).empty())
  {
    report.reason = TriggerReason::TooSmall;
    report.message += "nothing proposed: the candidate cells form groups smaller than min_cluster_cells " +
                      std::to_string(p.min_cluster_cells);
  }
  else if (near_shared > 0)
  {
    report.reason = TriggerReason::AlreadyShared;
    report.message += "nothing proposed: " + std::to_string(near_shared) + " of the " + std::to_string(near) +
                      " recently marked cell(s) near the robot lie in obstacles already shared, the rest were "
                      "seen free since";
  }
  else if (far > 0 && near == 0)
  {
    report.reason = TriggerReason::OutOfRange;
    report.message += "nothing proposed: " + std::to_string(far) + " recently marked cell(s), " +
                      format("the nearest %.2f m away, beyond trigger_radius %.2f m", nearest, p.trigger_radius);
  }
  else if (near > 0)
  {
    report.reason = TriggerReason::NothingMarked;
    report.message += "nothing proposed: the " + std::to_string(near) +
                      " recently marked cell(s) near the robot were seen free since";
  }
  else if (in.last.static_marked > 0)
  {
    report.reason = TriggerReason::Static;
    report.message += "nothing proposed: the " + std::to_string(in.last.static_marked) +
                      " cell(s) the last scan marked are all static (within static_tolerance " +
                      std::to_string(p.static_tolerance) + " cells of a wall or unknown map area)";
  }
  else
  {
    report.reason = TriggerReason::NothingMarked;
    report.message += format("nothing proposed: no new cell marked within obstacle_range %.2f m in the last "
                             "trigger_memory %.1f s",
                             p.limits.obstacle_range, p.trigger_memory);
  }
}

// --- The plan-blocked trigger ---

double nearestPlanDistance(const std::vector<std::pair<double, double>>& plan, double robot_x, double robot_y)
{
  return std::sqrt(nearestPose(plan, robot_x, robot_y).second);
}

bool Triggers::setPlan(const std::vector<std::pair<double, double>>& poses)
{
  plan_.clear();
  plan_.reserve(poses.size());
  for (const auto& pose : poses)
  {
    if (std::isfinite(pose.first) && std::isfinite(pose.second))
    {
      plan_.push_back(pose);
    }
  }
  return !plan_.empty();
}

std::vector<std::size_t> Triggers::planAhead(double robot_x, double robot_y, double reach) const
{
  const std::size_t nearest = nearestPose(plan_, robot_x, robot_y).first;
  std::vector<std::size_t> ahead;
  const double reach_sq = reach * reach;
  for (std::size_t i = nearest; i < plan_.size(); ++i)
  {
    const double d = squaredDistance(plan_[i].first, plan_[i].second, robot_x, robot_y);
    // A segment is kept when either end is in reach, so a sparse plan keeps its segments near the robot.
    const bool next_in_reach =
        i + 1 < plan_.size() && squaredDistance(plan_[i + 1].first, plan_[i + 1].second, robot_x, robot_y) <= reach_sq;
    if (d <= reach_sq || next_in_reach)
    {
      ahead.push_back(i);
    }
  }
  return ahead;
}

bool Triggers::nearPlan(std::uint32_t index, const std::vector<std::size_t>& ahead, const TriggerInputs& in) const
{
  double px = 0.0, py = 0.0;
  cellCentre(in.geometry, index, px, py);
  const double r_sq = in.params.inscribed_radius * in.params.inscribed_radius;
  for (std::size_t i : ahead)
  {
    const double ax = plan_[i].first, ay = plan_[i].second;
    double bx = ax, by = ay;
    if (i + 1 < plan_.size())
    {
      bx = plan_[i + 1].first;
      by = plan_[i + 1].second;
    }
    // Distance from the cell centre to the segment between this pose and the next.
    const double vx = bx - ax, vy = by - ay;
    const double len_sq = vx * vx + vy * vy;
    double t = len_sq > 0.0 ? ((px - ax) * vx + (py - ay) * vy) / len_sq : 0.0;
    t = std::min(1.0, std::max(0.0, t));
    const double dx = ax + t * vx - px, dy = ay + t * vy - py;
    if (dx * dx + dy * dy <= r_sq)
    {
      return true;
    }
  }
  return false;
}

TriggerReport Triggers::checkPlan(double robot_x, double robot_y, double now_s, FleetRobots& robots,
                                  const TriggerInputs& in)
{
  TriggerReport report;
  report.source = TriggerSource::PlanBlocked;
  if (plan_.empty() || in.last.new_marked.empty() || !std::isfinite(robot_x) || !std::isfinite(robot_y) ||
      !std::isfinite(now_s))
  {
    return report;
  }
  robots.expire(now_s);
  const LayerParams& p = in.params;
  const std::vector<std::size_t> ahead = planAhead(robot_x, robot_y, p.limits.obstacle_range + p.inscribed_radius);
  if (ahead.empty())
  {
    return report;
  }
  // obstacle_range counts from the laser that marked the cells: a laser ahead of the robot's centre marks a cell
  // first at obstacle_range from itself, and once marked the cell is no longer new.
  const double from_x = in.last.originKnown() ? in.last.origin_x : robot_x;
  const double from_y = in.last.originKnown() ? in.last.origin_y : robot_y;
  const double reach = p.limits.obstacle_range + 0.5 * in.geometry.resolution * std::sqrt(2.0);
  std::size_t blocking = 0, blocking_shared = 0;
  for (std::uint32_t index : in.last.new_marked)
  {
    double wx = 0.0, wy = 0.0;
    cellCentre(in.geometry, index, wx, wy);
    if (squaredDistance(wx, wy, from_x, from_y) > reach * reach || !nearPlan(index, ahead, in) ||
        in.robots.excludes(index))  // a fleet robot on the plan is not an obstacle to share
    {
      continue;
    }
    ++blocking;
    blocking_shared += in.fleet.monitored(index);
  }
  if (blocking == 0)
  {
    return report;
  }
  report.log = true;
  report.message = "plan_blocked trigger at " + format("(%.2f, %.2f): ", robot_x, robot_y) +
                   std::to_string(blocking) + " newly marked cell(s) on the plan ahead; ";
  if (!plan_trigger_.signal(now_s))
  {
    report.reason = TriggerReason::Debounced;
    report.log = plan_trigger_.burstSignals() == 2;
    report.message += format("debounced: less than trigger_debounce %.1f s after the previous one (further ones of "
                             "this burst are not logged)",
                             p.trigger_debounce, 0.0);
    return report;
  }
  if (blocking_shared == blocking)
  {
    report.reason = TriggerReason::AlreadyShared;
    report.message += "nothing proposed: they lie in obstacles already shared";
    return report;
  }
  report.proposals = planProposals(robot_x, robot_y, ahead, in);
  if (!report.proposals.empty())
  {
    report.reason = TriggerReason::Proposed;
    report.message += describeProposals(report.proposals);
    return report;
  }
  report.reason = TriggerReason::TooSmall;
  report.message += "nothing proposed: the cells on the plan form groups smaller than min_cluster_cells " +
                    std::to_string(p.min_cluster_cells);
  return report;
}

std::vector<Proposal> Triggers::planProposals(double robot_x, double robot_y, const std::vector<std::size_t>& ahead,
                                              const TriggerInputs& in) const
{
  // The trigger fires on the first cells of a block within obstacle_range, and navfn's detour may keep the robot from
  // ever marking the rest of its face: the endpoints the same scan saw beyond obstacle_range (within raytrace_range)
  // join the clusters they touch, so a corridor the block closes is closed for the peers too. Walls, unknown map
  // cells, shared obstacles and fleet robots stay out, as for marked cells.
  std::vector<std::uint32_t> cells = candidates(robot_x, robot_y, true, in);
  for (std::uint32_t index : in.last.far_hits)
  {
    if (!in.statics.isStatic(index) && !in.fleet.monitored(index) && !in.robots.excludes(index))
    {
      cells.push_back(index);
    }
  }
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  std::vector<Proposal> on_plan;
  for (Proposal& proposal : proposeByClusters(in.geometry, cells, in.params.cluster_gap, in.params.min_cluster_cells,
                                              in.params.rectangle_padding))
  {
    if (std::any_of(proposal.cells.begin(), proposal.cells.end(),
                    [&](std::uint32_t index) { return nearPlan(index, ahead, in); }))
    {
      on_plan.push_back(std::move(proposal));
    }
  }
  return on_plan;
}

}  // namespace sharing_layer
