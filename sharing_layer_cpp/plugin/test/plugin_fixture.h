// What the plugin's rostest gtests share: a layer fed through its real observation buffers, its sources set as
// parameters, the laser placed in tf, a ring of beams, and a shared obstacle sent as a handler would.
#ifndef SHARING_LAYER_PLUGIN_TEST_PLUGIN_FIXTURE_H
#define SHARING_LAYER_PLUGIN_TEST_PLUGIN_FIXTURE_H

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include <costmap_2d/cost_values.h>
#include <costmap_2d/layered_costmap.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/SharedObstacle.h>
#include <tf2_ros/buffer.h>

namespace sharing_layer_test
{
/// A layer whose observation buffers can be fed directly, as their topic subscription feeds them.
template <class Base>
class Fed : public Base
{
public:
  void feed(std::size_t source, const sensor_msgs::PointCloud2& cloud)
  {
    ASSERT_LT(source, this->observation_buffers_.size());
    this->observation_buffers_[source]->lock();
    this->observation_buffers_[source]->bufferCloud(cloud);
    this->observation_buffers_[source]->unlock();
  }
};

struct Source
{
  std::string name;
  bool marking;
  bool clearing;
  double obstacle_range;
  double raytrace_range;
};

inline void setSources(const std::string& layer, const std::vector<Source>& sources)
{
  std::string names;
  for (const Source& s : sources)
  {
    names += s.name + " ";
    const std::string ns = "~" + layer + "/" + s.name + "/";
    ros::param::set(ns + "topic", "plugin_layer_test_unused_" + s.name);
    ros::param::set(ns + "data_type", std::string("PointCloud2"));
    ros::param::set(ns + "sensor_frame", std::string("laser"));
    ros::param::set(ns + "marking", s.marking);
    ros::param::set(ns + "clearing", s.clearing);
    ros::param::set(ns + "obstacle_range", s.obstacle_range);
    ros::param::set(ns + "raytrace_range", s.raytrace_range);
  }
  ros::param::set("~" + layer + "/observation_sources", names);
  ros::param::set("~" + layer + "/robot_name", std::string("robot_0"));
  ros::param::set("~" + layer + "/map_topic", std::string("none"));
  ros::param::set("~" + layer + "/plan_topics", std::string("none"));
  ros::param::set("~" + layer + "/fleet_robots_topic", std::string("none"));
}

/// The laser at (x, y, 0.5) in the map.
inline void placeLaser(tf2_ros::Buffer& tf, double x, double y)
{
  geometry_msgs::TransformStamped t;
  t.header.frame_id = "map";
  t.child_frame_id = "laser";
  t.transform.translation.x = x;
  t.transform.translation.y = y;
  t.transform.translation.z = 0.5;
  t.transform.rotation.w = 1.0;
  tf.setTransform(t, "plugin_layer_tests", true);
}

/// Endpoints in the laser frame (z 0): a ring of beams whose lengths sweep from 0.5 m to 7.4 m, so that some are
/// marked, some only cleared, some cut at raytrace_range and some leave a 10 m map.
inline sensor_msgs::PointCloud2 ring(int beams, double phase)
{
  sensor_msgs::PointCloud2 cloud;
  cloud.header.frame_id = "laser";
  cloud.header.stamp = ros::Time::now();
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(beams);
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  for (int i = 0; i < beams; ++i, ++x, ++y, ++z)
  {
    const double angle = phase + 2.0 * M_PI * i / beams;
    const double range = 0.5 + 0.1 * ((i * 7) % 70);
    *x = static_cast<float>(range * std::cos(angle));
    *y = static_cast<float>(range * std::sin(angle));
    *z = 0.0f;
  }
  return cloud;
}

/// A 3 x 3-cell shared obstacle of robot_1 around world (3.05, 3.05) on a 10 m map at 0.05 m, as a handler sends it.
inline sharing_msgs::SharedObstacle blockAt3m()
{
  sharing_msgs::SharedObstacle msg;
  msg.header.frame_id = "map";
  msg.header.stamp = ros::Time::now();
  msg.uuid = "block-3m";
  msg.resolution = 0.05f;
  msg.origin_x = 0.0;
  msg.origin_y = 0.0;
  msg.size_x = 200;
  msg.size_y = 200;
  for (unsigned int y = 60; y <= 62; ++y)
  {
    for (unsigned int x = 60; x <= 62; ++x)
    {
      msg.marked_indexes.push_back(y * 200 + x);
    }
  }
  msg.deadline = 600;
  msg.rectangle_shape = { 2.9f, 2.9f, 3.3f, 3.3f };
  msg.source = "robot_1";
  msg.version = 1;
  return msg;
}

/// Sends a 3 x 3-cell shared obstacle around world (3.05, 3.05) to the layer, as its handler would, and waits
/// until the layer has drawn it into the master (the outcome), at most 30 s.
inline bool shareBlockAt3m(costmap_2d::LayeredCostmap& costmap, double robot_x, double robot_y)
{
  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 1, true);
  const sharing_msgs::SharedObstacle msg = blockAt3m();
  pub.publish(msg);
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(30.0);
  while (ros::WallTime::now() < end)
  {
    ros::spinOnce();
    costmap.updateMap(robot_x, robot_y, 0.0);
    unsigned int mx = 0, my = 0;
    if (costmap.getCostmap()->worldToMap(3.05, 3.05, mx, my) &&
        costmap.getCostmap()->getCost(mx, my) == costmap_2d::LETHAL_OBSTACLE)
    {
      return true;
    }
    ros::WallDuration(0.02).sleep();
  }
  return false;
}

inline unsigned char costAt(costmap_2d::LayeredCostmap& costmap, double x, double y)
{
  unsigned int mx = 0, my = 0;
  if (!costmap.getCostmap()->worldToMap(x, y, mx, my))
  {
    return 0;
  }
  return costmap.getCostmap()->getCost(mx, my);
}
}  // namespace sharing_layer_test

#endif  // SHARING_LAYER_PLUGIN_TEST_PLUGIN_FIXTURE_H
