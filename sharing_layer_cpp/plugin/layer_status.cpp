// The layer's run-time face: /diagnostics and dynamic_reconfigure (issue 28). Members of SharingLayer, kept apart
// from the cycle (sharing_layer.cpp) so that each file reads as one concern.
#include "sharing_layer.h"

#include <algorithm>
#include <string>
#include <vector>

namespace sharing_layer
{
namespace
{
std::string joined(const std::vector<std::string>& names)
{
  std::string text;
  for (const std::string& name : names)
  {
    text += (text.empty() ? "" : " ") + name;
  }
  return text;
}
}  // namespace

void SharingLayer::startDiagnosticsAndReconfigure(const ros::NodeHandle& private_nh)
{
  // /diagnostics: "sharing_layer: <robot_name> (<layer>)" (the updater prefixes its node name without the slash).
  diagnostics_.reset(new diagnostic_updater::Updater(ros::NodeHandle(), private_nh, "/sharing_layer"));
  diagnostics_->setHardwareID(params_.robot_name);
  diagnostics_->add(params_.robot_name + " (" + name_ + ")", this, &SharingLayer::diagnose);
  diagnostics_timer_ = ros::NodeHandle().createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) {
    diagnostics_->force_update();
  });
  // dynamic_reconfigure in <layer>/sharing: ObstacleLayer's server has the layer's own namespace. The layer's
  // parameters are the start values (not what an earlier run left in <layer>/sharing).
  sharing_layer_cpp::SharingLayerConfig initial;
  {
    std::lock_guard<std::mutex> lock(core_mutex_);
    initial.trigger_debounce = params_.trigger_debounce;
    initial.trigger_memory = params_.trigger_memory;
    initial.trigger_radius = params_.trigger_radius;
    initial.memory_on_stuck_feedback = params_.memory_on_stuck_feedback;
    initial.inscribed_radius = params_.inscribed_radius;
    initial.static_tolerance = params_.static_tolerance;
    initial.clearing_margin = params_.clearing_margin;
    initial.clearing_scans = static_cast<int>(std::min(params_.clearing_scans, 1000000u));
    initial.clearing_time = params_.clearing_time;
    initial.clearing_neighbours = static_cast<int>(std::min(params_.clearing_neighbours, 1000000u));
    initial.robot_exclusion_margin = fleet_params_.margin;
    initial.robot_timeout = fleet_params_.timeout;
    initial.robot_exclusion_trail = fleet_params_.trail;
    initial.lease_renewal_interval = params_.lease_renewal_interval;
  }
  boost::recursive_mutex::scoped_lock lock(reconfigure_mutex_);
  reconfigure_server_.reset(new dynamic_reconfigure::Server<sharing_layer_cpp::SharingLayerConfig>(
      reconfigure_mutex_, ros::NodeHandle(private_nh, "sharing")));
  reconfigure_config_ = initial;
  reconfigure_server_->updateConfig(initial);
  reconfigure_server_->setCallback(
      [this](sharing_layer_cpp::SharingLayerConfig& config, uint32_t level) { reconfigure(config, level); });
}

void SharingLayer::reconfigure(sharing_layer_cpp::SharingLayerConfig& config, uint32_t)
{
  // reconfigure_mutex_ is held (the server's). Only the fields that changed since the last accepted configuration
  // are applied, onto the values in use (inscribed_radius may follow the footprint meanwhile).
  const sharing_layer_cpp::SharingLayerConfig& old = reconfigure_config_;
  std::lock_guard<std::mutex> lock(core_mutex_);
  PendingReconfigure next{ pending_ ? pending_->params : params_, pending_ ? pending_->fleet : fleet_params_,
                           pending_ && pending_->inscribed_set };
  std::vector<std::string> changed;
  const auto take = [&](auto value, auto old_value, auto& target, const char* name) {
    if (value != old_value)
    {
      target = value;
      changed.push_back(name);
    }
  };
  LayerParams& p = next.params;
  take(config.trigger_debounce, old.trigger_debounce, p.trigger_debounce, "trigger_debounce");
  take(config.trigger_memory, old.trigger_memory, p.trigger_memory, "trigger_memory");
  take(config.trigger_radius, old.trigger_radius, p.trigger_radius, "trigger_radius");
  take(config.memory_on_stuck_feedback, old.memory_on_stuck_feedback, p.memory_on_stuck_feedback,
       "memory_on_stuck_feedback");
  take(config.inscribed_radius, old.inscribed_radius, p.inscribed_radius, "inscribed_radius");
  take(config.static_tolerance, old.static_tolerance, p.static_tolerance, "static_tolerance");
  take(config.clearing_margin, old.clearing_margin, p.clearing_margin, "clearing_margin");
  take(config.clearing_time, old.clearing_time, p.clearing_time, "clearing_time");
  take(config.robot_exclusion_margin, old.robot_exclusion_margin, next.fleet.margin, "robot_exclusion_margin");
  take(config.robot_timeout, old.robot_timeout, next.fleet.timeout, "robot_timeout");
  take(config.robot_exclusion_trail, old.robot_exclusion_trail, next.fleet.trail, "robot_exclusion_trail");
  take(config.lease_renewal_interval, old.lease_renewal_interval, p.lease_renewal_interval,
       "lease_renewal_interval");
  // Negative counts stay out of range after the cast (validate() names them), as readLayerConfig does.
  if (config.clearing_scans != old.clearing_scans)
  {
    p.clearing_scans = config.clearing_scans < 0 ? 0u : static_cast<unsigned int>(config.clearing_scans);
    changed.push_back("clearing_scans");
  }
  if (config.clearing_neighbours != old.clearing_neighbours)
  {
    p.clearing_neighbours =
        config.clearing_neighbours < 0 ? 100000u : static_cast<unsigned int>(config.clearing_neighbours);
    changed.push_back("clearing_neighbours");
  }
  if (changed.empty())
  {
    return;
  }
  std::string names;
  for (const std::string& name : changed)
  {
    names += (names.empty() ? "" : ", ") + name;
  }
  try
  {
    next.params.validate();
    next.fleet.validate();
  }
  catch (const std::invalid_argument& e)
  {
    last_refusal_ = names + ": " + e.what();
    ROS_ERROR("SharingLayer %s (%s): dynamic_reconfigure refused (%s): %s; the previous configuration stays",
              name_.c_str(), params_.robot_name.c_str(), names.c_str(), e.what());
    config = reconfigure_config_;  // what the server keeps and answers
    return;
  }
  next.inscribed_set = next.inscribed_set || config.inscribed_radius != old.inscribed_radius;
  pending_.reset(new PendingReconfigure(next));
  reconfigure_config_ = config;
  ROS_INFO("SharingLayer %s (%s): dynamic_reconfigure accepted %s; applied at the next cycle", name_.c_str(),
           params_.robot_name.c_str(), names.c_str());
}

void SharingLayer::applyPendingReconfigure()
{
  if (!pending_)
  {
    return;
  }
  std::unique_ptr<PendingReconfigure> next = std::move(pending_);
  try
  {
    if (core_)
    {
      core_->setParams(next->params);  // validated in reconfigure(): keeps the grid and the obstacles
      core_->fleetRobots().setParams(next->fleet);
    }
  }
  catch (const std::invalid_argument& e)
  {
    ROS_ERROR("SharingLayer %s (%s): reconfiguration not applied: %s", name_.c_str(), params_.robot_name.c_str(),
              e.what());
    return;
  }
  params_ = next->params;
  fleet_params_ = next->fleet;
  if (next->inscribed_set)
  {
    inscribed_from_footprint_ = false;
  }
  ROS_INFO("SharingLayer %s (%s): reconfigured: trigger debounce %.2f s, memory %.1f s within %.2f m (on "
           "stuck_feedback: %s), plan trigger within %.3f m%s, static tolerance %d cells, clearing after %u scans "
           "over %.2f s seen free %.2f m on (%u neighbours), fleet robots + %.2f m forgotten after %.1f s, lease "
           "renewal %.1f s",
           name_.c_str(), params_.robot_name.c_str(), params_.trigger_debounce, params_.trigger_memory,
           params_.trigger_radius, params_.memory_on_stuck_feedback ? "yes" : "no", params_.inscribed_radius,
           inscribed_from_footprint_ ? " (the footprint's)" : "", params_.static_tolerance, params_.clearing_scans,
           params_.clearing_time, params_.clearing_margin, params_.clearing_neighbours, fleet_params_.margin,
           fleet_params_.timeout, params_.lease_renewal_interval);
}

LayerParams SharingLayer::sharingParams()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return core_ ? core_->params() : params_;
}

FleetRobotParams SharingLayer::fleetRobotParams()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return core_ ? core_->fleetRobots().params() : fleet_params_;
}

bool SharingLayer::mapReceived()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return static_seen_ && !static_pending_ && (map_topic_.empty() || map_seen_);
}

std::size_t SharingLayer::planPoses()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return core_ ? core_->plan().size() : 0;
}

std::size_t SharingLayer::perCellBytes()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return (core_ ? core_->perCellBytes() : 0) + (map_ ? map_->unknown.bytes() : 0);
}

void SharingLayer::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  using diagnostic_msgs::DiagnosticStatus;
  std::lock_guard<std::mutex> lock(core_mutex_);
  status.summary(DiagnosticStatus::OK, "sharing");
  // Observation sources.
  status.add("observation sources", source_names_.empty() ? std::string("none") : joined(source_names_));
  if (!adopted_.empty())
  {
    status.add("taken from the costmap's namespace", joined(adopted_));
  }
  if (source_names_.empty())
  {
    status.mergeSummary(DiagnosticStatus::ERROR, "no observation source (set " + private_namespace_ +
                                                     "/observation_sources): marks nothing, shares nothing");
  }
  else if (!sources_current_)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "an observation source is not current (no recent data)");
  }
  diagnosePlanAndMap(status);
  diagnoseLocalisation(status);
  // Counts.
  status.add("proposals published", proposals_published_);
  status.add("updates published", updates_published_);
  status.add("shared obstacles held", core_ ? core_->sharedObstacles().size() : std::size_t(0));
  status.add("fleet messages applied", fleet_applied_);
  status.add("fleet messages rejected", fleet_rejected_);
  if (!last_rejection_.empty())
  {
    status.add("last rejection", last_rejection_);
  }
  status.add("reconfigure namespace", private_namespace_ + "/sharing");
  if (!last_refusal_.empty())
  {
    status.add("last refused reconfiguration", last_refusal_);
  }
}

void SharingLayer::diagnosePlanAndMap(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  using diagnostic_msgs::DiagnosticStatus;
  // The plan trigger.
  std::size_t plan_publishers = 0;
  for (const ros::Subscriber& sub : plan_subs_)
  {
    plan_publishers += sub.getNumPublishers();
  }
  const double since_plan = last_plan_.isZero() ? -1.0 : (ros::Time::now() - last_plan_).toSec();
  status.add("plan topics", plan_topics_.empty() ? std::string("none (plan trigger off)") : joined(plan_topics_));
  status.add("plan publishers", plan_publishers);
  status.add("plans received", plans_received_);
  status.add("plans out of the local planner's reach", plans_out_of_reach_);
  status.add("last plan", since_plan < 0.0 ? std::string("never") : std::to_string(since_plan) + " s ago");
  const bool plan_alive = !plan_topics_.empty() && (plan_publishers > 0 || (since_plan >= 0.0 && since_plan < 60.0));
  status.add("plan trigger alive", plan_alive);
  if (!plan_topics_.empty() && !plan_alive)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "nothing publishes the global plan on [" + joined(plan_topics_) +
                                                    "]: the plan-blocked trigger is off (set " + private_namespace_ +
                                                    "/plan_topics)");
  }
  // The a-priori map.
  status.add("map received", static_seen_ && !static_pending_);
  status.add("map topic", map_topic_.empty() ? std::string("none") :
                                                map_topic_ + (map_seen_ ? " (received)" : " (waiting)"));
  if (rolling_window_)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "rolling window: draws the fleet's obstacles, proposes nothing of "
                                                "its own (put the layer in the global costmap to share)");
  }
  else if (!core_)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "waiting for the map: the costmap has no size yet");
  }
  else if (static_pending_)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "waiting for the static layer's map: no proposals, no plan trigger");
  }
  if (!rolling_window_ && !map_topic_.empty() && !map_seen_)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "no map on [" + map_topic_ + "] yet: its unknown cells are not known");
  }
}

}  // namespace sharing_layer
