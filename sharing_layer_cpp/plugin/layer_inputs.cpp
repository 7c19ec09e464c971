// What the layer hears besides its sensors: the a-priori map's unknown cells, the fleet robots' footprints, the
// fleet's obstacles and their expiry. Members of SharingLayer; the cycle itself is in sharing_layer.cpp.
#include "sharing_layer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include <geometry_msgs/TransformStamped.h>
#include <tf2/exceptions.h>

#include "sharing_layer/cost_values.h"
#include "messages.h"

namespace sharing_layer
{
void SharingLayer::mapCallback(const nav_msgs::OccupancyGrid::ConstPtr& msg)
{
  if (msg->info.width == 0 || msg->info.height == 0 ||
      msg->data.size() != static_cast<std::size_t>(msg->info.width) * msg->info.height ||
      !(msg->info.resolution > 0.0f))
  {
    ROS_WARN("SharingLayer (%s): ignoring a map of %ux%u cells with %zu values at resolution %f",
             params_.robot_name.c_str(), msg->info.width, msg->info.height, msg->data.size(), msg->info.resolution);
    return;
  }
  // Only its unknown cells are needed, a bit each: the message itself is not kept.
  std::unique_ptr<UnknownMap> map(new UnknownMap);
  map->info = msg->info;
  map->unknown.assign(msg->data.size());
  for (std::size_t i = 0; i < msg->data.size(); ++i)
  {
    if (msg->data[i] < 0)
    {
      map->unknown.set(i);
    }
  }
  std::lock_guard<std::mutex> lock(core_mutex_);
  map_ = std::move(map);
  map_seen_ = true;
  applyUnknownMap();
}

void SharingLayer::applyUnknownMap()
{
  if (!core_ || !map_)
  {
    return;
  }
  // Unknown (-1) cells of the a-priori map, looked up for every master cell through world coordinates, so a
  // master of another size or origin (a static layer with a different map, rolling window off) still works.
  const GridGeometry g = core_->geometry();
  const nav_msgs::MapMetaData& info = map_->info;
  const BitGrid& map_unknown = map_->unknown;
  std::vector<std::uint8_t> unknown(g.cellCount(), 0);
  std::size_t count = 0;
  for (unsigned int my = 0; my < g.size_y; ++my)
  {
    for (unsigned int mx = 0; mx < g.size_x; ++mx)
    {
      double wx = 0.0, wy = 0.0;
      g.mapToWorld(mx, my, wx, wy);
      const double fx = (wx - info.origin.position.x) / info.resolution;
      const double fy = (wy - info.origin.position.y) / info.resolution;
      if (fx < 0.0 || fy < 0.0 || fx >= info.width || fy >= info.height)
      {
        continue;  // outside the map: the static layer's business
      }
      const std::size_t index = static_cast<std::size_t>(fy) * info.width + static_cast<std::size_t>(fx);
      if (map_unknown.test(index))
      {
        unknown[g.getIndex(mx, my)] = 1;
        ++count;
      }
    }
  }
  core_->setUnknownMap(unknown.data(), unknown.size());
  ROS_INFO("SharingLayer (%s): %zu cells of the a-priori map are unknown and never shared",
           params_.robot_name.c_str(), count);
}

void SharingLayer::fleetRobotsCallback(const sharing_msgs::RobotFootprintArray::ConstPtr& msg)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  fleet_robots_ = msg;
  applyFleetRobots();
}

void SharingLayer::applyFleetRobots()
{
  if (!core_ || !fleet_robots_)
  {
    return;
  }
  std::vector<FleetRobot> robots;
  for (const sharing_msgs::RobotFootprint& item : fleet_robots_->robots)
  {
    if (item.robot == params_.robot_name)
    {
      continue;  // this robot's own footprint is the footprint clearing's business
    }
    FleetRobot robot;
    robot.name = item.robot;
    robot.stamp = item.header.stamp.isZero() ? ros::Time::now().toSec() : item.header.stamp.toSec();
    double tx = 0.0, ty = 0.0, yaw = 0.0;
    std::string frame = item.header.frame_id;
    if (!frame.empty() && frame[0] == '/')
    {
      frame.erase(0, 1);
    }
    try
    {
      if (!frame.empty() && frame != global_frame_)
      {
        const geometry_msgs::TransformStamped t = tf_->lookupTransform(global_frame_, frame, ros::Time(0));
        const geometry_msgs::Quaternion& q = t.transform.rotation;
        tx = t.transform.translation.x;
        ty = t.transform.translation.y;
        yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
      }
      const double c = std::cos(yaw), s = std::sin(yaw);
      for (const geometry_msgs::Point32& p : item.footprint.points)
      {
        robot.footprint.emplace_back(tx + c * p.x - s * p.y, ty + s * p.x + c * p.y);
      }
      FleetRobots::check(robot);
      robots.push_back(std::move(robot));
    }
    catch (const tf2::TransformException& e)
    {
      ROS_WARN_THROTTLE(5.0, "SharingLayer (%s): ignoring fleet robot %s: cannot transform its footprint from %s to "
                             "%s: %s",
                        params_.robot_name.c_str(), item.robot.c_str(), frame.c_str(), global_frame_.c_str(), e.what());
    }
    catch (const std::invalid_argument& e)
    {
      ROS_WARN_THROTTLE(5.0, "SharingLayer (%s): ignoring fleet robot: %s", params_.robot_name.c_str(), e.what());
    }
  }
  core_->fleetRobots().replaceAll(robots);  // all checked: cannot throw
}

void SharingLayer::sharedCallback(const sharing_msgs::SharedObstacle::ConstPtr& msg)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!core_)
  {
    ROS_WARN_THROTTLE(5.0, "SharingLayer (%s): obstacle %s from %s arrived before the map; dropped",
                      params_.robot_name.c_str(), msg->uuid.c_str(), msg->source.c_str());
    ++fleet_rejected_;
    last_rejection_ = "obstacle " + msg->uuid + " from " + msg->source + ": arrived before the map";
    return;
  }
  try
  {
    ObstacleUpdate update = fromMessage(*msg);
    if (!update.geometry.sameAs(core_->geometry()))
    {
      // Sent on another grid (the sender's map differs in size or origin, or this is a rolling window): the
      // cells go where they are in the world.
      std::size_t dropped = 0;
      update = reprojectUpdate(update, core_->geometry(), &dropped);
      if (dropped > 0)
      {
        ROS_DEBUG("SharingLayer (%s): obstacle %s from %s: %zu cell(s) outside this layer's grid dropped",
                  params_.robot_name.c_str(), msg->uuid.c_str(), msg->source.c_str(), dropped);
      }
    }
    const ApplyResult result = core_->applyShared(update, ros::Time::now().toSec());
    fleet_applied_ += result.ok;
    if (!result.ok)
    {
      ROS_WARN_THROTTLE(1.0, "SharingLayer (%s): ignoring shared obstacle: %s", params_.robot_name.c_str(),
                        result.error.c_str());
      ++fleet_rejected_;
      last_rejection_ = "obstacle " + msg->uuid + " from " + msg->source + ": " + result.error;
    }
  }
  catch (const std::invalid_argument& e)
  {
    ROS_WARN_THROTTLE(1.0, "SharingLayer (%s): ignoring shared obstacle %s from %s: %s", params_.robot_name.c_str(),
                      msg->uuid.c_str(), msg->source.c_str(), e.what());
    ++fleet_rejected_;
    last_rejection_ = "obstacle " + msg->uuid + " from " + msg->source + ": " + e.what();
  }
}

void SharingLayer::expiredCallback(const std_msgs::String::ConstPtr& msg)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  const bool expired = core_ && core_->expire(msg->data);
  fleet_applied_ += expired;
  if (core_ && !expired)
  {
    ROS_DEBUG("SharingLayer (%s): expired obstacle %s was not known", params_.robot_name.c_str(), msg->data.c_str());
  }
}

}  // namespace sharing_layer
