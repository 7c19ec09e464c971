#include "sharing_layer.h"

#include <algorithm>
#include <limits>
#include <cmath>
#include <cstring>
#include <iterator>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <geometry_msgs/TransformStamped.h>
#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <tf2/exceptions.h>

#include "sharing_layer/cost_merge.h"
#include "sharing_layer/cost_values.h"
#include "layer_config.h"
#include "messages.h"

PLUGINLIB_EXPORT_CLASS(sharing_layer::SharingLayer, costmap_2d::Layer)

namespace sharing_layer
{
namespace
{
Observation toObservation(const costmap_2d::Observation& observation)
{
  Observation obs;
  obs.origin = Point3{ observation.origin_.x, observation.origin_.y, observation.origin_.z };
  const sensor_msgs::PointCloud2& cloud = *observation.cloud_;
  // float32 x, y, z (what ObservationBuffer makes of every cloud and scan): read at their offsets, point by point as
  // PointCloud2ConstIterator walks them (data.size() / point_step points), without its per-point bookkeeping.
  int offsets[3] = { -1, -1, -1 };
  for (const sensor_msgs::PointField& field : cloud.fields)
  {
    const int axis = field.name == "x" ? 0 : field.name == "y" ? 1 : field.name == "z" ? 2 : -1;
    if (axis >= 0 && field.datatype == sensor_msgs::PointField::FLOAT32 && field.count == 1 && !cloud.is_bigendian)
    {
      offsets[axis] = static_cast<int>(field.offset);
    }
  }
  if (offsets[0] >= 0 && offsets[1] >= 0 && offsets[2] >= 0 && cloud.point_step >= 4 &&
      static_cast<std::uint32_t>(std::max({ offsets[0], offsets[1], offsets[2] })) + 4 <= cloud.point_step)
  {
    const std::size_t n = cloud.data.size() / cloud.point_step;
    obs.points.resize(n);
    const std::uint8_t* data = cloud.data.data();
    for (std::size_t i = 0; i < n; ++i, data += cloud.point_step)
    {
      float v[3];
      std::memcpy(&v[0], data + offsets[0], 4);
      std::memcpy(&v[1], data + offsets[1], 4);
      std::memcpy(&v[2], data + offsets[2], 4);
      obs.points[i] = Point3{ v[0], v[1], v[2] };
    }
    return obs;
  }
  obs.points.reserve(cloud.width * cloud.height);
  sensor_msgs::PointCloud2ConstIterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  for (; x != x.end(); ++x, ++y, ++z)
  {
    obs.points.push_back(Point3{ *x, *y, *z });
  }
  return obs;
}
}  // namespace

void SharingLayer::onInitialize()
{
  // Before ObstacleLayer reads them: a layer with no observation source marks nothing and never shares.
  const std::vector<std::string> adopted = adoptParentObservationSources(name_);
  ObstacleLayer::onInitialize();
  ros::NodeHandle private_nh("~/" + name_);
  LayerConfig config;
  try
  {
    readLayerConfig(private_nh, layered_costmap_->getInscribedRadius(), ros::this_node::getName(),
                    ros::this_node::getNamespace(), config);
  }
  catch (const std::invalid_argument& e)
  {
    ROS_FATAL("SharingLayer %s (%s): bad parameter: %s", name_.c_str(), config.params.robot_name.c_str(), e.what());
    throw;
  }
  params_ = config.params;
  fleet_params_ = config.fleet;
  inscribed_from_footprint_ = config.inscribed_from_footprint;
  source_names_ = config.source_names;
  adopted_ = adopted;
  private_namespace_ = private_nh.getNamespace();
  map_topic_ = config.map_topic == "none" ? std::string() : config.map_topic;
  global_frame_ = layered_costmap_->getGlobalFrameID();
  localisation_watch_.setLimits(config.localisation);  // validated with the rest
  {
    // The costmap's namespace holds robot_base_frame (Costmap2DROS's default: base_link).
    const std::size_t slash = name_.rfind('/');
    ros::NodeHandle costmap_nh(slash == std::string::npos ? "~" : "~/" + name_.substr(0, slash));
    costmap_nh.param("robot_base_frame", robot_base_frame_, std::string("base_link"));
  }
  warnAboutSetup(adopted, private_nh.getNamespace());
  wireTopics(config);
  ROS_INFO("SharingLayer %s (%s): fleet robots from [%s] are never shared (footprint + %.2f m, and where they were "
           "in the last %.1f s; forgotten after %.1f s)",
           name_.c_str(), params_.robot_name.c_str(), config.fleet_robots_topic.c_str(), fleet_params_.margin,
           fleet_params_.trail, fleet_params_.timeout);
  ROS_INFO("SharingLayer %s (%s): clearing after %u scans over %.1f s seen free %.2f m before the beam ends; "
           "trigger memory %.1f s within %.2f m; plan trigger on [%s] within %.2f m of the plan; unknown cells "
           "from [%s]",
           name_.c_str(), params_.robot_name.c_str(), params_.clearing_scans, params_.clearing_time,
           params_.clearing_margin, params_.trigger_memory, params_.trigger_radius, config.plan_topics.c_str(),
           params_.inscribed_radius, config.map_topic.c_str());
  rebuildCore();
  startDiagnosticsAndReconfigure(private_nh);
}

void SharingLayer::warnAboutSetup(const std::vector<std::string>& adopted, const std::string& private_namespace)
{
  if (!adopted.empty())
  {
    std::string names;
    for (const std::string& name : adopted)
    {
      names += (names.empty() ? "" : ", ") + name;
    }
    ROS_WARN("SharingLayer %s: no observation_sources in its namespace %s; took them from the costmap's (pre-Hydro "
             "parameter files, which costmap_2d moves only into a costmap_2d::ObstacleLayer): %s",
             name_.c_str(), private_namespace.c_str(), names.c_str());
  }
  if (source_names_.empty())
  {
    ROS_ERROR("SharingLayer %s: no observation source (set %s/observation_sources): this layer marks nothing and "
              "shares nothing",
              name_.c_str(), private_namespace.c_str());
  }
  if (layered_costmap_->isRolling())
  {
    ROS_WARN("SharingLayer %s: in a rolling-window costmap it works as costmap_2d::ObstacleLayer and draws the "
             "fleet's obstacles (placed by world position; its global_frame must be the fleet's, e.g. map), but "
             "proposes and sends nothing of its own (no a-priori map there tells walls from new obstacles, and its "
             "cell indexes move with the robot); put it in the global costmap to share",
             name_.c_str());
  }
}

void SharingLayer::wireTopics(const LayerConfig& config)
{
  ros::NodeHandle robot_nh;
  proposals_pub_ = robot_nh.advertise<sharing_msgs::SharedObstacle>("obstacle_proposals", 10);
  updates_pub_ = robot_nh.advertise<sharing_msgs::SharedObstacle>("obstacle_updates", 100);
  stuck_sub_ = robot_nh.subscribe("stuck_feedback", 10, &SharingLayer::stuckCallback, this);
  recovery_sub_ = robot_nh.subscribe("move_base/recovery_status", 10, &SharingLayer::recoveryCallback, this);
  shared_sub_ = robot_nh.subscribe("shared_obstacles", 100, &SharingLayer::sharedCallback, this);
  expired_sub_ = robot_nh.subscribe("expired_obstacles", 100, &SharingLayer::expiredCallback, this);
  // Whichever of the planners publishes; an empty list (or "none") switches the plan trigger off.
  std::istringstream topics(config.plan_topics);
  for (std::string topic; topics >> topic;)
  {
    if (topic != "none")
    {
      plan_subs_.push_back(robot_nh.subscribe(topic, 1, &SharingLayer::planCallback, this));
      plan_topics_.push_back(plan_subs_.back().getTopic());
    }
  }
  if (!plan_subs_.empty())
  {
    // move_base's action server is "move_base" in the robot's namespace, whatever the node's name.
    goal_status_sub_ = robot_nh.subscribe("move_base/status", 1, &SharingLayer::goalStatusCallback, this);
    plan_publisher_check_ = robot_nh.createTimer(ros::Duration(15.0), &SharingLayer::checkPlanPublishers, this, true);
  }
  if (!config.map_topic.empty() && config.map_topic != "none")
  {
    map_sub_ = robot_nh.subscribe(config.map_topic, 1, &SharingLayer::mapCallback, this);
  }
  if (!config.fleet_robots_topic.empty() && config.fleet_robots_topic != "none")
  {
    fleet_robots_sub_ = robot_nh.subscribe(config.fleet_robots_topic, 2, &SharingLayer::fleetRobotsCallback, this);
  }
}

void SharingLayer::updateBounds(double robot_x, double robot_y, double robot_yaw, double* min_x, double* min_y,
                                double* max_x, double* max_y)
{
  if (rolling_window_)
  {
    followRollingWindow(robot_x, robot_y);
  }
  if (!enabled_)
  {
    return;
  }
  useExtraBounds(min_x, min_y, max_x, max_y);
  watchLocalisation();
  std::vector<SourceObservation> observations;
  current_ = sourceObservations(observations);

  std::lock_guard<std::mutex> lock(core_mutex_);
  sources_current_ = current_;
  have_robot_pose_ = true;
  robot_x_ = robot_x;
  robot_y_ = robot_y;
  applyPendingReconfigure();  // dynamic_reconfigure's accepted changes, from this cycle on
  if (!core_)
  {
    return;
  }
  const double now = ros::Time::now().toSec();
  for (const SourceObservation& source_observation : observations)
  {
    processObservation(source_observation, now, robot_x, robot_y, min_x, min_y, max_x, max_y);
  }
  if (stuck_pending_ && !localisation_steady_)
  {
    ++triggers_withheld_;  // kept pending: acted on once odometry and localisation agree again
  }
  else if (stuck_pending_)
  {
    stuck_pending_ = false;
    if (rolling_window_)
    {
      ROS_INFO("SharingLayer (%s): %s ignored: a rolling-window costmap proposes nothing of its own",
               params_.robot_name.c_str(), triggerSourceName(stuck_source_));
    }
    else
    {
      handleTrigger(core_->trigger(stuck_source_, stuck_stamp_.toSec(), robot_x, robot_y), now);
    }
  }
  // Only obstacles that changed grow the bounds; the others are drawn directly in updateCosts.
  const WorldBounds dirty = core_->takeDirtyBounds();
  if (!dirty.empty())
  {
    touch(dirty.min_x, dirty.min_y, min_x, min_y, max_x, max_y);
    touch(dirty.max_x, dirty.max_y, min_x, min_y, max_x, max_y);
  }
  updateFootprint(robot_x, robot_y, robot_yaw, min_x, min_y, max_x, max_y);
}

void SharingLayer::processObservation(const SourceObservation& source_observation, double now, double robot_x,
                                      double robot_y, double* min_x, double* min_y, double* max_x, double* max_y)
{
  const costmap_2d::Observation& observation = *source_observation.observation;
  const ScanLimits& limits = source_observation.limits;
  Observation scan = toObservation(observation);
  ScanOutcome outcome;
  try
  {
    outcome = core_->processScan(scan, now, limits);
  }
  catch (const std::invalid_argument& e)  // a source's ranges (ObstacleLayer takes any value)
  {
    ROS_ERROR_THROTTLE(10.0, "SharingLayer (%s): observation source %s skipped: %s (its obstacle_range %g, "
                             "raytrace_range %g)",
                       params_.robot_name.c_str(), source_observation.source.c_str(), e.what(),
                       limits.obstacle_range, limits.raytrace_range);
    return;
  }
  if (static_pending_)
  {
    if (pre_static_scans_.size() == kMaxPreStaticScans)
    {
      pre_static_scans_.pop_front();
    }
    pre_static_scans_.emplace_back(std::move(scan), limits);
  }
  if (!outcome.touch.origin_in_map)
  {
    ROS_WARN_THROTTLE(1.0, "SharingLayer (%s): sensor origin (%.2f, %.2f) is off the map; not clearing",
                      params_.robot_name.c_str(), observation.origin_.x, observation.origin_.y);
  }
  if (!rolling_window_ && !localisation_steady_)
  {
    // Placed through a localisation that disagrees with the odometry, this scan's marks may lie where nothing is:
    // nothing of it goes to the fleet (its marks and clears stay in this costmap, as ObstacleLayer's would).
    updates_withheld_ += outcome.updates.size();
    triggers_withheld_ += static_pending_ ? 0 : 1;
  }
  else if (!rolling_window_)  // its cell indexes would be those of a grid that moves with the robot
  {
    for (const ObstacleUpdate& update : outcome.updates)
    {
      updates_pub_.publish(toMessage(update, global_frame_));
      ++updates_published_;
    }
    if (!static_pending_)  // without the a-priori map every wall looks new
    {
      handleTrigger(core_->checkPlan(robot_x, robot_y, now), now);
    }
  }
  // What the scan touched, as ObstacleLayer grows its bounds (the origin, the beams up to raytrace_range, the marked
  // points), not a box of the range around the sensor: every later layer works over this.
  if (!outcome.touch.touchedNothing())
  {
    touch(outcome.touch.min_x, outcome.touch.min_y, min_x, min_y, max_x, max_y);
    touch(outcome.touch.max_x, outcome.touch.max_y, min_x, min_y, max_x, max_y);
  }
}

bool SharingLayer::sourceObservations(std::vector<SourceObservation>& out)
{
  // ObstacleLayer clears with every clearing source before it marks with any. One core pass per observation
  // (its evidence and the plan trigger's "newly marked" need clearing and marking of a scan together) keeps
  // that order between clearing-only, dual and marking-only sources; two dual sources each clear right before
  // they mark.
  const auto has = [](const std::vector<boost::shared_ptr<costmap_2d::ObservationBuffer>>& buffers,
                      const boost::shared_ptr<costmap_2d::ObservationBuffer>& buffer) {
    return std::find(buffers.begin(), buffers.end(), buffer) != buffers.end();
  };
  std::vector<SourceObservation> by_rank[3];
  const auto add = [&](const costmap_2d::Observation& observation, bool marking, bool clearing,
                       const std::string& source) {
    // As ObstacleLayer: the source's observation buffer has kept only points within the source's heights, and
    // the layer's max_obstacle_height (dynamic_reconfigure's, read every cycle) bounds marking only. Ranges and
    // roles are the source's.
    ScanLimits limits = params_.limits;
    limits.min_obstacle_height = -std::numeric_limits<double>::infinity();
    limits.max_obstacle_height = std::numeric_limits<double>::infinity();
    limits.max_marking_height = max_obstacle_height_;
    limits.obstacle_range = observation.obstacle_range_;
    limits.raytrace_range = observation.raytrace_range_;
    limits.marking = marking;
    limits.clearing = clearing;
    by_rank[clearing ? (marking ? 1 : 0) : 2].push_back(SourceObservation{ &observation, limits, source });
  };
  bool current = true;
  cycle_observations_.resize(observation_buffers_.size());  // before any is filled: their addresses stay
  for (std::size_t i = 0; i < observation_buffers_.size(); ++i)
  {
    const auto& buffer = observation_buffers_[i];
    const std::string source = i < source_names_.size() ? source_names_[i] : "#" + std::to_string(i);
    const bool marking = has(marking_buffers_, buffer), clearing = has(clearing_buffers_, buffer);
    if (!marking && !clearing)
    {
      continue;
    }
    std::vector<costmap_2d::Observation>& observations = cycle_observations_[i];
    observations.clear();
    buffer->lock();
    buffer->getObservations(observations);
    current = current && buffer->isCurrent();
    buffer->unlock();
    for (const costmap_2d::Observation& observation : observations)
    {
      add(observation, marking, clearing, source);
    }
  }
  for (const costmap_2d::Observation& observation : static_clearing_observations_)
  {
    add(observation, false, true, "(static clearing observation)");
  }
  for (const costmap_2d::Observation& observation : static_marking_observations_)
  {
    add(observation, true, false, "(static marking observation)");
  }
  out.clear();
  for (auto& rank : by_rank)
  {
    std::move(rank.begin(), rank.end(), std::back_inserter(out));
  }
  return current;
}

void SharingLayer::updateCosts(costmap_2d::Costmap2D& master_grid, int min_i, int min_j, int max_i, int max_j)
{
  if (!enabled_)
  {
    return;
  }
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!core_)
  {
    return;
  }
  if (static_pending_ && min_i == 0 && min_j == 0 && max_i >= static_cast<int>(master_grid.getSizeInCellsX()) &&
      max_j >= static_cast<int>(master_grid.getSizeInCellsY()))
  {
    // The layers before us (the static layer) have drawn the whole map: that is the a-priori map.
    core_->setStaticMap(master_grid.getCharMap(), master_grid.getSizeInCellsX() * master_grid.getSizeInCellsY());
    static_pending_ = false;
    static_seen_ = true;
    // Scans that came between the new core and this update (a map that arrives or changes size while
    // the sensors run) made wall cells shareable, and a wall seen on every scan never leaves that set.
    // Clear the obstacle grid and the shareable cells (shared obstacles stay) and replay those scans
    // through the static filter.
    if (!pre_static_scans_.empty())
    {
      core_->resetObstacleLayer();
      const double now = ros::Time::now().toSec();
      for (const auto& scan : pre_static_scans_)
      {
        for (const ObstacleUpdate& update : core_->processScan(scan.first, now, scan.second).updates)
        {
          updates_pub_.publish(toMessage(update, global_frame_));
          ++updates_published_;
        }
      }
      pre_static_scans_.clear();
    }
  }
  // The core's obstacle grid is this layer's costmap_ (shareGridWithCore); only if it could not be, copy the window.
  const CostGrid& grid = core_->obstacleGrid();
  if (grid.data() != costmap_)
  {
    const unsigned int size_x = getSizeInCellsX();
    for (int j = min_j; j < max_j; ++j)
    {
      std::copy(grid.data() + j * size_x + min_i, grid.data() + j * size_x + max_i, costmap_ + j * size_x + min_i);
    }
  }
  if (footprint_clearing_enabled_)
  {
    setConvexPolygonCost(transformed_footprint_, costmap_2d::FREE_SPACE);
  }
  // ObstacleLayer's two combination methods, by the same rules (test_cost_merge) in loops that vectorise: half of
  // a 30 m update cycle is this merge.
  const MergeWindow window{ master_grid.getSizeInCellsX(), min_i, min_j, max_i, max_j };
  switch (combination_method_)
  {
    case 0:
      mergeOverwrite(costmap_, master_grid.getCharMap(), window);
      break;
    case 1:
      mergeMax(costmap_, master_grid.getCharMap(), window);
      break;
    default:
      break;
  }
  // Inside the window only (the layer contract): shared obstacles outside it are still in the master from the cycles
  // that drew them, and one that changes grows the bounds over itself (takeDirtyBounds in updateBounds).
  core_->drawShared(master_grid.getCharMap(), master_grid.getSizeInCellsX() * master_grid.getSizeInCellsY(), min_i,
                    min_j, max_i, max_j);
}

void SharingLayer::clearArea(int start_x, int start_y, int end_x, int end_y, bool invert_area)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!core_)
  {
    ObstacleLayer::clearArea(start_x, start_y, end_x, end_y, invert_area);
    return;
  }
  std::size_t cleared = 0;
  if (!invert_area)
  {
    cleared = core_->clearObstaclesOutside(start_x, start_y, end_x, end_y);
  }
  else
  {
    // Inside the open window only (clear_costmap_recovery with invert_area_to_clear): the cells there, one by
    // one; the shareable set drops them at the next scan, as they are no longer lethal.
    const GridGeometry& g = core_->geometry();
    CostGrid& grid = core_->obstacleGrid();
    for (int y = std::max(0, start_y + 1); y < std::min(static_cast<int>(g.size_y), end_y); ++y)
    {
      for (int x = std::max(0, start_x + 1); x < std::min(static_cast<int>(g.size_x), end_x); ++x)
      {
        const std::uint32_t index = g.getIndex(static_cast<unsigned int>(x), static_cast<unsigned int>(y));
        if (grid.at(index) == sharing_layer::LETHAL_OBSTACLE)
        {
          ++cleared;
        }
        grid.set(index, grid.defaultValue());
      }
    }
  }
  // After the core, which counts what it clears in the grid they share (the same cells, so nothing is left).
  ObstacleLayer::clearArea(start_x, start_y, end_x, end_y, invert_area);
  ROS_INFO("SharingLayer (%s): clearArea cleared %zu obstacle cell(s) of its own; shared obstacles stay",
           params_.robot_name.c_str(), cleared);
}

void SharingLayer::reset()
{
  ObstacleLayer::reset();
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (core_)
  {
    core_->resetObstacleLayer();  // shared obstacles stay
  }
}

}  // namespace sharing_layer
