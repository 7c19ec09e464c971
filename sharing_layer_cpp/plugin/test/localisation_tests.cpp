// The plugin's check of odometry against localisation (issue 49): while the two disagree on the robot's motion the
// layer sends nothing of what it sees (here: the lease renewals of a shared obstacle it keeps seeing), and says so in
// /diagnostics; once they agree for a window it sends again. Needs a ROS master: plugin_localisation.test.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include <costmap_2d/layered_costmap.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/SharedObstacle.h>
#include <tf2/LinearMath/Quaternion.h>
#include <tf2_ros/buffer.h>

#include "../sharing_layer.h"
#include "plugin_fixture.h"

namespace
{
class FedSharingLayer : public sharing_layer::SharingLayer
{
public:
  void feed(const sensor_msgs::PointCloud2& cloud)
  {
    observation_buffers_[0]->lock();
    observation_buffers_[0]->bufferCloud(cloud);
    observation_buffers_[0]->unlock();
  }
};

void setTransform(tf2_ros::Buffer& tf, const std::string& parent, const std::string& child, double x, double y,
                  double yaw, const ros::Time& stamp)
{
  geometry_msgs::TransformStamped t;
  t.header.frame_id = parent;
  t.header.stamp = stamp;
  t.child_frame_id = child;
  t.transform.translation.x = x;
  t.transform.translation.y = y;
  tf2::Quaternion q;
  q.setRPY(0.0, 0.0, yaw);
  t.transform.rotation.x = q.x();
  t.transform.rotation.y = q.y();
  t.transform.rotation.z = q.z();
  t.transform.rotation.w = q.w();
  tf.setTransform(t, "localisation_tests", false);
}

/// The robot: map -> odom_w -> base_w -> laser_w at `stamp`, the robot at (4, 4) in the map, its odometry saying
/// it has turned by odom_yaw (the localisation holds it still: the map pose is the same whatever odom_yaw says).
void placeRobot(tf2_ros::Buffer& tf, double odom_yaw, const ros::Time& stamp)
{
  // odom_w -> base_w: at the origin of odom_w, turned by odom_yaw; map -> odom_w undoes that turn about (4, 4)
  setTransform(tf, "odom_w", "base_w", 0.0, 0.0, odom_yaw, stamp);
  setTransform(tf, "map", "odom_w", 4.0, 4.0, -odom_yaw, stamp);
  setTransform(tf, "base_w", "laser_w", 0.0, 0.0, 0.0, stamp);
}

/// Endpoints on the shared block's cells around (3.05, 3.05), seen from the laser at (4, 4) (1.3 m: within
/// obstacle_range) whose heading in the map is 0 (the map pose never turns here).
sensor_msgs::PointCloud2 onTheBlock(const ros::Time& stamp)
{
  sensor_msgs::PointCloud2 cloud;
  cloud.header.frame_id = "laser_w";
  cloud.header.stamp = stamp;
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(9);
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  for (int i = 0; i < 9; ++i, ++x, ++y, ++z)
  {
    *x = static_cast<float>(3.0 + 0.05 * (i % 3) + 0.025 - 4.0);
    *y = static_cast<float>(3.0 + 0.05 * (i / 3) + 0.025 - 4.0);
    *z = 0.0f;
  }
  return cloud;
}
}  // namespace

TEST(PluginLocalisation, NothingIsSentWhileOdometryAndLocalisationDisagree)
{
  ros::NodeHandle nh;
  const std::string layer_name = "watch";
  ros::param::set("~robot_base_frame", std::string("base_w"));  // the costmap's namespace is ~ for this name
  ros::param::set("~" + layer_name + "/observation_sources", std::string("scan"));
  ros::param::set("~" + layer_name + "/scan/topic", std::string("localisation_test_unused"));
  ros::param::set("~" + layer_name + "/scan/data_type", std::string("PointCloud2"));
  ros::param::set("~" + layer_name + "/scan/sensor_frame", std::string("laser_w"));
  ros::param::set("~" + layer_name + "/scan/marking", true);
  ros::param::set("~" + layer_name + "/scan/clearing", true);
  ros::param::set("~" + layer_name + "/robot_name", std::string("robot_0"));
  ros::param::set("~" + layer_name + "/map_topic", std::string("none"));
  ros::param::set("~" + layer_name + "/plan_topics", std::string("none"));
  ros::param::set("~" + layer_name + "/fleet_robots_topic", std::string("none"));
  ros::param::set("~" + layer_name + "/lease_renewal_interval", 0.0);  // every scan that sees the block renews it

  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, layer_name, &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);

  std::vector<sharing_msgs::SharedObstacle> sent;
  ros::Subscriber updates = nh.subscribe<sharing_msgs::SharedObstacle>(
      "obstacle_updates", 100, [&](const sharing_msgs::SharedObstacle::ConstPtr& msg) { sent.push_back(*msg); });
  ros::Publisher shared = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 1, true);
  shared.publish(sharing_layer_test::blockAt3m());

  ros::Time stamp = ros::Time::now();
  double odom_yaw = 0.0;
  // One cycle every 0.1 s of stamps: the odometry turns by `turn` rad, a scan sees the block, the costmap updates.
  const auto cycles = [&](int n, double turn) {
    for (int i = 0; i < n; ++i)
    {
      stamp += ros::Duration(0.1);
      odom_yaw += turn;
      placeRobot(tf, odom_yaw, stamp);
      layer->feed(onTheBlock(stamp));
      costmap.updateMap(4.0, 4.0, 0.0);
      ros::WallDuration(0.01).sleep();
      ros::spinOnce();
    }
  };
  // The layer holds the block (from its handler) before anything else.
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(30.0);
  while (layer->sharedObstacleCount() == 0 && ros::WallTime::now() < end)
  {
    cycles(1, 0.0);
  }
  ASSERT_EQ(1u, layer->sharedObstacleCount());

  cycles(15, 0.0);  // agreeing: renewals go out
  ros::WallDuration(0.3).sleep();
  ros::spinOnce();
  EXPECT_TRUE(layer->localisationAgrees());
  EXPECT_FALSE(sent.empty()) << "no renewal of the block the robot keeps seeing";

  // The odometry says it turns at 0.5 rad/s; the localisation holds it still: they disagree.
  cycles(5, 0.05);
  EXPECT_FALSE(layer->localisationAgrees());
  ros::WallDuration(0.3).sleep();
  ros::spinOnce();
  const std::size_t before = sent.size();
  const std::size_t withheld_before = layer->updatesWithheld();
  cycles(10, 0.05);
  ros::WallDuration(0.3).sleep();
  ros::spinOnce();
  EXPECT_EQ(before, sent.size()) << "renewals sent while odometry and localisation disagreed";
  EXPECT_GT(layer->updatesWithheld(), withheld_before);

  // Agreeing again for a whole window (1 s): renewals again.
  cycles(12, 0.0);
  EXPECT_TRUE(layer->localisationAgrees());
  cycles(5, 0.0);
  ros::WallDuration(0.3).sleep();
  ros::spinOnce();
  EXPECT_GT(sent.size(), before);
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "localisation_tests");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
