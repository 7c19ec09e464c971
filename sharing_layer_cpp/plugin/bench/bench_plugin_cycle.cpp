// The plugin's whole costmap update cycle against costmap_2d's own ObstacleLayer (issue 13): each in its own
// LayeredCostmap, fed the reference scan (bench/reference_scene.h: 2000 x 2000 at 0.05 m, 1081 beams over 270
// degrees) through its real observation buffer, timed over LayeredCostmap::updateMap (updateBounds, the master
// reset over the bounds, updateCosts). Rounds alternate between the two so that machine noise hits both alike;
// the figures are medians and the ratio ours / upstream is taken within the run.
//
// Built only where costmap_2d is installed; needs a ROS master (parameters, the shared-obstacle topic):
//   rosrun sharing_layer_cpp bench_plugin_cycle [rounds] [case 0..3, default all]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <costmap_2d/layered_costmap.h>
#include <costmap_2d/obstacle_layer.h>
#include <costmap_2d/observation_buffer.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/SharedObstacle.h>
#include <tf2_ros/buffer.h>

#include "../../bench/reference_scene.h"
#include "../messages.h"
#include "../sharing_layer.h"

namespace
{
using sharing_layer::bench::Scene;

template <class Base>
class Fed : public Base
{
public:
  void feed(const sensor_msgs::PointCloud2& cloud)
  {
    this->observation_buffers_[0]->lock();
    this->observation_buffers_[0]->bufferCloud(cloud);
    this->observation_buffers_[0]->unlock();
  }
};

void setSource(const std::string& layer, double obstacle_range, double raytrace_range)
{
  const std::string ns = "~" + layer + "/";
  ros::param::set(ns + "observation_sources", std::string("scan"));
  ros::param::set(ns + "scan/topic", std::string("bench_plugin_cycle_unused"));
  ros::param::set(ns + "scan/data_type", std::string("PointCloud2"));
  ros::param::set(ns + "scan/sensor_frame", std::string("laser"));
  ros::param::set(ns + "scan/marking", true);
  ros::param::set(ns + "scan/clearing", true);
  ros::param::set(ns + "scan/obstacle_range", obstacle_range);
  ros::param::set(ns + "scan/raytrace_range", raytrace_range);
  ros::param::set(ns + "obstacle_range", obstacle_range);
  ros::param::set(ns + "raytrace_range", raytrace_range);
  ros::param::set(ns + "robot_name", std::string("robot_0"));
  ros::param::set(ns + "map_topic", std::string("none"));
  ros::param::set(ns + "plan_topics", std::string("none"));
  ros::param::set(ns + "fleet_robots_topic", std::string("none"));
}

/// The scan's points in the laser frame (the laser at the scan's origin).
sensor_msgs::PointCloud2 laserCloud(const Scene& scene)
{
  sensor_msgs::PointCloud2 cloud;
  cloud.header.frame_id = "laser";
  cloud.header.stamp = ros::Time::now();
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(scene.scan.points.size());
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  for (const auto& p : scene.scan.points)
  {
    *x = static_cast<float>(p.x - scene.scan.origin.x);
    *y = static_cast<float>(p.y - scene.scan.origin.y);
    *z = static_cast<float>(p.z - scene.scan.origin.z);
    ++x, ++y, ++z;
  }
  return cloud;
}

/// Shares every crate with the layer through its topic and waits until it has drawn them all (the outcome).
bool shareCrates(const Scene& scene, costmap_2d::LayeredCostmap& costmap)
{
  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 200);
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60.0);
  while (pub.getNumSubscribers() == 0 && ros::WallTime::now() < end)
  {
    ros::WallDuration(0.01).sleep();
  }
  for (int i = 0; i < sharing_layer::bench::kCrates; ++i)
  {
    pub.publish(sharing_layer::toMessage(sharing_layer::bench::crateUpdate(scene, i), "map"));
  }
  while (ros::WallTime::now() < end)
  {
    ros::spinOnce();
    costmap.updateMap(scene.scan.origin.x, scene.scan.origin.y, 0.0);
    int drawn = 0;
    for (int i = 0; i < sharing_layer::bench::kCrates; ++i)
    {
      unsigned int mx = 0, my = 0;
      costmap.getCostmap()->worldToMap(scene.crates[i].first + 0.001, scene.crates[i].second + 0.001, mx, my);
      drawn += costmap.getCostmap()->getCost(mx, my) == costmap_2d::LETHAL_OBSTACLE;
    }
    if (drawn == sharing_layer::bench::kCrates)
    {
      return true;
    }
    ros::WallDuration(0.02).sleep();
  }
  return false;
}

double median(std::vector<double> v)
{
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Case
{
  double raytrace_range;
  double obstacle_range;
  bool shared;
};
}  // namespace

int main(int argc, char** argv)
{
  ros::init(argc, argv, "bench_plugin_cycle");
  ros::NodeHandle nh;
  const int rounds = argc > 1 ? std::max(5, std::atoi(argv[1])) : 60;
  const int only_case = argc > 2 ? std::atoi(argv[2]) : -1;  // one case (0..3) alone, e.g. under a profiler
  const Scene scene = sharing_layer::bench::makeScene();
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  geometry_msgs::TransformStamped laser;
  laser.header.frame_id = "map";
  laser.child_frame_id = "laser";
  laser.transform.translation.x = scene.scan.origin.x;
  laser.transform.translation.y = scene.scan.origin.y;
  laser.transform.translation.z = scene.scan.origin.z;
  laser.transform.rotation.w = 1.0;
  tf.setTransform(laser, "bench", true);
  const sensor_msgs::PointCloud2 cloud = laserCloud(scene);
  std::printf("reference scan: %zu beams on %s; %d rounds per case, medians; each layer alone in its "
              "LayeredCostmap\n", scene.scan.points.size(), scene.geometry.describe().c_str(), rounds);
  std::printf("%-32s %14s %14s %8s %22s\n", "case", "upstream ms", "ours ms", "ratio", "bounds cells up / ours");
  const Case cases[] = { { 3.0, 2.5, false }, { 3.0, 2.5, true }, { 30.0, 30.0, false }, { 30.0, 30.0, true } };
  int index = 0;
  for (const Case& c : cases)
  {
    if (only_case >= 0 && index != only_case)
    {
      ++index;
      continue;
    }
    const std::string tag = std::to_string(index++);
    setSource("upstream_" + tag, c.obstacle_range, c.raytrace_range);
    setSource("ours_" + tag, c.obstacle_range, c.raytrace_range);
    costmap_2d::LayeredCostmap upstream_costmap("map", false, false), our_costmap("map", false, false);
    auto* upstream = new Fed<costmap_2d::ObstacleLayer>();
    upstream_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(upstream));
    upstream->initialize(&upstream_costmap, "upstream_" + tag, &tf);
    auto* ours = new Fed<sharing_layer::SharingLayer>();
    our_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(ours));
    ours->initialize(&our_costmap, "ours_" + tag, &tf);
    const sharing_layer::GridGeometry& g = scene.geometry;
    upstream_costmap.resizeMap(g.size_x, g.size_y, g.resolution, g.origin_x, g.origin_y);
    our_costmap.resizeMap(g.size_x, g.size_y, g.resolution, g.origin_x, g.origin_y);
    upstream->feed(cloud);
    ours->feed(cloud);
    if (c.shared && !shareCrates(scene, our_costmap))
    {
      std::fprintf(stderr, "bench_plugin_cycle: the shared crates did not reach the layer within 60 s\n");
      return 2;
    }
    std::vector<double> t_upstream, t_ours;
    const double x = scene.scan.origin.x, y = scene.scan.origin.y;
    for (int r = 0; r < rounds; ++r)
    {
      upstream->feed(cloud);
      ours->feed(cloud);
      auto start = std::chrono::steady_clock::now();
      upstream_costmap.updateMap(x, y, 0.0);
      t_upstream.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      start = std::chrono::steady_clock::now();
      our_costmap.updateMap(x, y, 0.0);
      t_ours.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
    unsigned int a[4], b[4];
    upstream_costmap.getBounds(&a[0], &a[1], &a[2], &a[3]);
    our_costmap.getBounds(&b[0], &b[1], &b[2], &b[3]);
    char label[64], bounds[64];
    std::snprintf(label, sizeof(label), "%.0f m / %.1f m, %s", c.raytrace_range, c.obstacle_range,
                  c.shared ? "100 shared obstacles" : "0 shared obstacles");
    std::snprintf(bounds, sizeof(bounds), "%ux%u / %ux%u", a[1] - a[0], a[3] - a[2], b[1] - b[0], b[3] - b[2]);
    std::printf("%-32s %14.3f %14.3f %8.3f %22s\n", label, median(t_upstream) * 1e3, median(t_ours) * 1e3,
                median(t_ours) / median(t_upstream), bounds);
    std::fflush(stdout);
  }
  return 0;
}
