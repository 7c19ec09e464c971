#include "sharing_layer.h"

#include <algorithm>
#include <cmath>

#include <pluginlib/class_list_macros.hpp>
#include <sensor_msgs/point_cloud2_iterator.h>

PLUGINLIB_EXPORT_CLASS(sharing_layer::SharingLayer, costmap_2d::Layer)

namespace sharing_layer
{
namespace
{
sharing_msgs::SharedObstacle toMessage(const ObstacleUpdate& update, const std::string& frame)
{
  sharing_msgs::SharedObstacle msg;
  msg.header.stamp = ros::Time(update.stamp);
  msg.header.frame_id = frame;
  msg.uuid = update.uuid;
  msg.marked_indexes = update.marked;
  msg.cleared_indexes = update.cleared;
  msg.deadline = update.deadline;
  msg.rectangle_shape = { static_cast<float>(update.rectangle.min_x), static_cast<float>(update.rectangle.min_y),
                          static_cast<float>(update.rectangle.max_x), static_cast<float>(update.rectangle.max_y) };
  msg.source = update.source;
  msg.resolution = static_cast<float>(update.geometry.resolution);
  msg.origin_x = update.geometry.origin_x;
  msg.origin_y = update.geometry.origin_y;
  msg.size_x = update.geometry.size_x;
  msg.size_y = update.geometry.size_y;
  msg.version = update.version;
  return msg;
}

/// @throws std::invalid_argument when the message cannot be a valid update
ObstacleUpdate fromMessage(const sharing_msgs::SharedObstacle& msg)
{
  if (msg.rectangle_shape.size() != 4)
  {
    throw std::invalid_argument("rectangle_shape has " + std::to_string(msg.rectangle_shape.size()) +
                                " values, expected 4");
  }
  ObstacleUpdate update;
  update.uuid = msg.uuid;
  update.marked = msg.marked_indexes;
  update.cleared = msg.cleared_indexes;
  update.deadline = msg.deadline;
  update.rectangle = Subsection(msg.rectangle_shape[0], msg.rectangle_shape[1], msg.rectangle_shape[2],
                                msg.rectangle_shape[3]);
  update.source = msg.source;
  update.geometry = GridGeometry(msg.resolution, msg.origin_x, msg.origin_y, msg.size_x, msg.size_y);
  update.version = msg.version;
  update.stamp = msg.header.stamp.toSec();
  return update;
}

Observation toObservation(const costmap_2d::Observation& observation)
{
  Observation obs;
  obs.origin = Point3{ observation.origin_.x, observation.origin_.y, observation.origin_.z };
  const sensor_msgs::PointCloud2& cloud = *observation.cloud_;
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
  ObstacleLayer::onInitialize();
  ros::NodeHandle private_nh("~/" + name_);
  ros::NodeHandle robot_nh;
  global_frame_ = layered_costmap_->getGlobalFrameID();

  private_nh.param("obstacle_range", params_.limits.obstacle_range, 2.5);
  private_nh.param("raytrace_range", params_.limits.raytrace_range, 3.0);
  private_nh.param("min_obstacle_height", params_.limits.min_obstacle_height, 0.0);
  private_nh.param("max_obstacle_height", params_.limits.max_obstacle_height, 2.0);
  private_nh.param("static_tolerance", params_.static_tolerance, 2);
  int occupied = 254;
  private_nh.param("static_occupied_cost", occupied, 254);
  params_.static_occupied_cost = static_cast<std::uint8_t>(std::min(255, std::max(1, occupied)));
  std::string strategy;
  private_nh.param("proposal_strategy", strategy, std::string("sectors"));
  private_nh.param("trigger_debounce", params_.trigger_debounce, 2.0);
  int gap = 1, min_cells = 1, max_cells = 1000000;
  private_nh.param("cluster_gap", gap, 1);
  private_nh.param("min_cluster_cells", min_cells, 1);
  private_nh.param("max_update_cells", max_cells, 1000000);
  params_.cluster_gap = static_cast<unsigned int>(std::max(0, gap));
  params_.min_cluster_cells = static_cast<std::size_t>(std::max(0, min_cells));
  params_.max_update_cells = static_cast<std::size_t>(std::max(0, max_cells));
  private_nh.param("rectangle_padding", params_.rectangle_padding, 0.0);
  std::string robot_name = ros::this_node::getNamespace();
  robot_name.erase(std::remove(robot_name.begin(), robot_name.end(), '/'), robot_name.end());
  private_nh.param("robot_name", params_.robot_name, robot_name.empty() ? std::string("robot") : robot_name);
  try
  {
    params_.strategy = parseProposalStrategy(strategy);
    params_.validate();
  }
  catch (const std::invalid_argument& e)
  {
    ROS_FATAL("SharingLayer %s (%s): bad parameter: %s", name_.c_str(), params_.robot_name.c_str(), e.what());
    throw;
  }

  proposals_pub_ = robot_nh.advertise<sharing_msgs::SharedObstacle>("obstacle_proposals", 10);
  updates_pub_ = robot_nh.advertise<sharing_msgs::SharedObstacle>("obstacle_updates", 100);
  stuck_sub_ = robot_nh.subscribe("stuck_feedback", 10, &SharingLayer::stuckCallback, this);
  recovery_sub_ = robot_nh.subscribe("move_base/recovery_status", 10, &SharingLayer::recoveryCallback, this);
  shared_sub_ = robot_nh.subscribe("shared_obstacles", 100, &SharingLayer::sharedCallback, this);
  expired_sub_ = robot_nh.subscribe("expired_obstacles", 100, &SharingLayer::expiredCallback, this);
  rebuildCore();
}

GridGeometry SharingLayer::masterGeometry() const
{
  const costmap_2d::Costmap2D* master = layered_costmap_->getCostmap();
  return GridGeometry(master->getResolution(), master->getOriginX(), master->getOriginY(),
                      master->getSizeInCellsX(), master->getSizeInCellsY());
}

void SharingLayer::rebuildCore()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  const costmap_2d::Costmap2D* master = layered_costmap_->getCostmap();
  if (master->getSizeInCellsX() == 0 || master->getSizeInCellsY() == 0)
  {
    return;  // the static layer has no map yet; matchSize() calls again
  }
  core_.reset(new SharingCore(masterGeometry(), params_));
  // LayeredCostmap::resizeMap() blanks the master before calling matchSize(); the static layer writes
  // its map into the master only in the next updateCosts(), before ours. Take the a-priori map there.
  static_pending_ = true;
  pre_static_scans_.clear();
}

void SharingLayer::matchSize()
{
  ObstacleLayer::matchSize();
  rebuildCore();
}

void SharingLayer::stuckCallback(const std_msgs::Empty::ConstPtr&)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  stuck_pending_ = true;
  stuck_stamp_ = ros::Time::now();
}

void SharingLayer::recoveryCallback(const ros::MessageEvent<topic_tools::ShapeShifter const>&)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  stuck_pending_ = true;
  stuck_stamp_ = ros::Time::now();
}

void SharingLayer::sharedCallback(const sharing_msgs::SharedObstacle::ConstPtr& msg)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!core_)
  {
    ROS_WARN_THROTTLE(5.0, "SharingLayer (%s): obstacle %s from %s arrived before the map; dropped",
                      params_.robot_name.c_str(), msg->uuid.c_str(), msg->source.c_str());
    return;
  }
  try
  {
    const ApplyResult result = core_->applyShared(fromMessage(*msg), ros::Time::now().toSec());
    if (!result.ok)
    {
      ROS_WARN_THROTTLE(1.0, "SharingLayer (%s): ignoring shared obstacle: %s", params_.robot_name.c_str(),
                        result.error.c_str());
    }
  }
  catch (const std::invalid_argument& e)
  {
    ROS_WARN_THROTTLE(1.0, "SharingLayer (%s): ignoring shared obstacle %s from %s: %s", params_.robot_name.c_str(),
                      msg->uuid.c_str(), msg->source.c_str(), e.what());
  }
}

void SharingLayer::expiredCallback(const std_msgs::String::ConstPtr& msg)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (core_ && !core_->expire(msg->data))
  {
    ROS_DEBUG("SharingLayer (%s): expired obstacle %s was not known", params_.robot_name.c_str(), msg->data.c_str());
  }
}

void SharingLayer::updateBounds(double robot_x, double robot_y, double robot_yaw, double* min_x, double* min_y,
                                double* max_x, double* max_y)
{
  if (!enabled_)
  {
    return;
  }
  useExtraBounds(min_x, min_y, max_x, max_y);
  std::vector<costmap_2d::Observation> observations;
  const bool current = getMarkingObservations(observations);
  current_ = current;

  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!core_)
  {
    return;
  }
  const double now = ros::Time::now().toSec();
  for (const costmap_2d::Observation& observation : observations)
  {
    Observation scan = toObservation(observation);
    const ScanOutcome outcome = core_->processScan(scan, now);
    if (static_pending_)
    {
      if (pre_static_scans_.size() == kMaxPreStaticScans)
      {
        pre_static_scans_.pop_front();
      }
      pre_static_scans_.push_back(std::move(scan));
    }
    if (!outcome.touch.origin_in_map)
    {
      ROS_WARN_THROTTLE(1.0, "SharingLayer (%s): sensor origin (%.2f, %.2f) is off the map; not clearing",
                        params_.robot_name.c_str(), observation.origin_.x, observation.origin_.y);
    }
    for (const ObstacleUpdate& update : outcome.updates)
    {
      updates_pub_.publish(toMessage(update, global_frame_));
    }
    // Marking reaches obstacle_range, clearing raytrace_range around the sensor.
    const double reach = std::max(params_.limits.obstacle_range, params_.limits.raytrace_range);
    touch(observation.origin_.x - reach, observation.origin_.y - reach, min_x, min_y, max_x, max_y);
    touch(observation.origin_.x + reach, observation.origin_.y + reach, min_x, min_y, max_x, max_y);
  }
  if (stuck_pending_)
  {
    stuck_pending_ = false;
    if (core_->signalStuck(stuck_stamp_.toSec()))
    {
      for (const Proposal& proposal : core_->propose(robot_x, robot_y))
      {
        ObstacleUpdate value;
        value.marked = proposal.cells;
        value.rectangle = proposal.rectangle;
        value.source = params_.robot_name;
        value.geometry = core_->geometry();
        value.stamp = now;
        proposals_pub_.publish(toMessage(value, global_frame_));
      }
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
    // Scans that came between the new core and this update (a map that arrives or changes size while
    // the sensors run) made wall cells shareable, and a wall seen on every scan never leaves that set.
    // Clear the obstacle grid and the shareable cells (shared obstacles stay) and replay those scans
    // through the static filter.
    if (!pre_static_scans_.empty())
    {
      core_->resetObstacleLayer();
      const double now = ros::Time::now().toSec();
      for (const Observation& scan : pre_static_scans_)
      {
        for (const ObstacleUpdate& update : core_->processScan(scan, now).updates)
        {
          updates_pub_.publish(toMessage(update, global_frame_));
        }
      }
      pre_static_scans_.clear();
    }
  }
  // The core's obstacle grid is this layer's data; copy the window, then combine like ObstacleLayer.
  const CostGrid& grid = core_->obstacleGrid();
  const unsigned int size_x = getSizeInCellsX();
  for (int j = min_j; j < max_j; ++j)
  {
    std::copy(grid.data() + j * size_x + min_i, grid.data() + j * size_x + max_i, costmap_ + j * size_x + min_i);
  }
  if (footprint_clearing_enabled_)
  {
    setConvexPolygonCost(transformed_footprint_, costmap_2d::FREE_SPACE);
  }
  switch (combination_method_)
  {
    case 0:
      updateWithOverwrite(master_grid, min_i, min_j, max_i, max_j);
      break;
    case 1:
      updateWithMax(master_grid, min_i, min_j, max_i, max_j);
      break;
    default:
      break;
  }
  core_->drawShared(master_grid.getCharMap(), master_grid.getSizeInCellsX() * master_grid.getSizeInCellsY());
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
