#include "bench_fixture.h"

#include <dlfcn.h>
#include <malloc.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <thread>

#include <costmap_2d/cost_values.h>
#include <costmap_2d/footprint.h>
#include <costmap_2d/layered_costmap.h>
#include <geometry_msgs/TransformStamped.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/SharedObstacle.h>

#include "../messages.h"

namespace sharing_layer
{
namespace bench
{
Stamp Stamp::now()
{
  timespec cpu{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &cpu);
  return Stamp{ std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(),
                static_cast<double>(cpu.tv_sec) + 1e-9 * static_cast<double>(cpu.tv_nsec) };
}

double median(std::vector<double> values)
{
  if (values.empty())
  {
    return std::numeric_limits<double>::quiet_NaN();
  }
  std::sort(values.begin(), values.end());
  return values[values.size() / 2];
}

void MapOnce::onInitialize()
{
  current_ = true;
  enabled_ = true;  // costmap_2d::Layer starts disabled
}

void MapOnce::updateBounds(double, double, double, double* min_x, double* min_y, double* max_x, double* max_y)
{
  if (!fresh_)
  {
    return;
  }
  const costmap_2d::Costmap2D& m = *layered_costmap_->getCostmap();
  *min_x = std::min(*min_x, m.getOriginX());
  *min_y = std::min(*min_y, m.getOriginY());
  *max_x = std::max(*max_x, m.getOriginX() + m.getSizeInMetersX());
  *max_y = std::max(*max_y, m.getOriginY() + m.getSizeInMetersY());
}

void MapOnce::updateCosts(costmap_2d::Costmap2D& master, int min_i, int min_j, int max_i, int max_j)
{
  if (!fresh_ || costs_.size() != master.getSizeInCellsX() * master.getSizeInCellsY())
  {
    return;
  }
  fresh_ = false;
  const unsigned int size_x = master.getSizeInCellsX();
  for (int j = min_j; j < max_j; ++j)
  {
    std::copy(costs_.begin() + j * size_x + min_i, costs_.begin() + j * size_x + max_i,
              master.getCharMap() + j * size_x + min_i);
  }
}

/// Shares every crate with the layer through its topic and waits until it has drawn them all (the outcome).
namespace
{
bool shareCrates(const Scene& scene, costmap_2d::LayeredCostmap& costmap)
{
  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 200);
  if (!spinUntil([&] { return pub.getNumSubscribers() > 0; }))
  {
    return false;
  }
  for (int i = 0; i < kCrates; ++i)
  {
    pub.publish(sharing_layer::toMessage(crateUpdate(scene, i), "map"));
  }
  return spinUntil([&] {
    costmap.updateMap(scene.scan.origin.x, scene.scan.origin.y, 0.0);
    int drawn = 0;
    for (int i = 0; i < kCrates; ++i)
    {
      unsigned int mx = 0, my = 0;
      costmap.getCostmap()->worldToMap(scene.crates[i].first + 0.001, scene.crates[i].second + 0.001, mx, my);
      drawn += costmap.getCostmap()->getCost(mx, my) == costmap_2d::LETHAL_OBSTACLE;
    }
    return drawn == kCrates;
  });
}
}  // namespace

Stage::Stage(ros::NodeHandle& nh) : scene(makeScene()), master_map(masterMap(scene))
{
  // A robot's frames, as on move_base: map -> odom -> base_link (at the scan's origin) -> laser. Ours compares the
  // odometry with the localisation every cycle (two lookups), as it does on a robot.
  tf.setUsingDedicatedThread(true);
  const auto frame = [&](const char* parent, const char* child, double x, double y, double z) {
    geometry_msgs::TransformStamped t;
    t.header.frame_id = parent;
    t.child_frame_id = child;
    t.transform.translation.x = x;
    t.transform.translation.y = y;
    t.transform.translation.z = z;
    t.transform.rotation.w = 1.0;
    tf.setTransform(t, "bench", true);
  };
  frame("map", "odom", 0.0, 0.0, 0.0);
  frame("odom", "base_link", scene.scan.origin.x, scene.scan.origin.y, 0.0);
  frame("base_link", "laser", 0.0, 0.0, scene.scan.origin.z);
  cloud = laserCloud(scene);
  path = plan(scene);
  plan_pub = nh.advertise<nav_msgs::Path>("bench_plan", 1, true);
  robots_pub = nh.advertise<sharing_msgs::RobotFootprintArray>("bench_fleet_robots", 1, true);
  plan_pub.publish(path);
  robots_pub.publish(fleetRobots());
}

void warmUp(Stage& stage, Subject<costmap_2d::ObstacleLayer>& upstream)
{
  for (int r = 0; r < 3; ++r)
  {
    upstream.layer->feed(stage.cloud);
    upstream.costmap.updateMap(stage.scene.scan.origin.x, stage.scene.scan.origin.y, 0.0);
  }
}

std::string warmUp(Stage& stage, ros::NodeHandle& nh, Subject<sharing_layer::SharingLayer>& ours, bool shared)
{
  const double x = stage.scene.scan.origin.x, y = stage.scene.scan.origin.y;
  {
    ros::Publisher map_pub = nh.advertise<nav_msgs::OccupancyGrid>("bench_map", 1, true);
    map_pub.publish(occupancyGrid(stage.scene));
    ours.layer->feed(stage.cloud);
    ours.costmap.updateMap(x, y, 0.0);
    if (!spinUntil([&] { return ours.layer->mapReceived() && ours.layer->planPoses() > 0; }))
    {
      return std::string("the layer did not receive the map and the plan within 60 s (map ") +
             (ours.layer->mapReceived() ? "received" : "waiting") + ", plan " +
             std::to_string(ours.layer->planPoses()) + " poses)";
    }
    map_pub.shutdown();
  }
  if (shared && !shareCrates(stage.scene, ours.costmap))
  {
    return "the shared crates did not reach the layer within 60 s";
  }
  for (int r = 0; r < 3; ++r)
  {
    ours.layer->feed(stage.cloud);
    ours.costmap.updateMap(x, y, 0.0);
  }
  ros::spinOnce();
  return "";
}

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
  ros::param::set(ns + "map_topic", std::string("bench_map"));
  ros::param::set(ns + "plan_topics", std::string("bench_plan"));
  ros::param::set(ns + "fleet_robots_topic", std::string("bench_fleet_robots"));
  ros::param::set(ns + "robot_timeout", 0.0);  // the robots' stamps do not age out during the run
}

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

std::vector<unsigned char> masterMap(const Scene& scene)
{
  std::vector<unsigned char> costs(scene.map.size(), costmap_2d::FREE_SPACE);
  for (std::size_t i = 0; i < costs.size(); ++i)
  {
    costs[i] = scene.map[i] ? costmap_2d::LETHAL_OBSTACLE : costmap_2d::FREE_SPACE;
  }
  return costs;
}

nav_msgs::OccupancyGrid::Ptr occupancyGrid(const Scene& scene)
{
  const GridGeometry& g = scene.geometry;
  nav_msgs::OccupancyGrid::Ptr map(new nav_msgs::OccupancyGrid);
  map->header.frame_id = "map";
  map->info.resolution = static_cast<float>(g.resolution);
  map->info.width = g.size_x;
  map->info.height = g.size_y;
  map->info.origin.position.x = g.origin_x;
  map->info.origin.position.y = g.origin_y;
  map->info.origin.orientation.w = 1.0;
  map->data.assign(g.cellCount(), 0);
  for (unsigned int y = 0; y < g.size_y; ++y)
  {
    for (unsigned int x = 0; x < g.size_x; ++x)
    {
      const double wx = g.origin_x + (x + 0.5) * g.resolution, wy = g.origin_y + (y + 0.5) * g.resolution;
      const std::uint32_t i = g.getIndex(x, y);
      map->data[i] = scene.map[i] ? 100 : (wx < 20.0 || wx > 80.0 || wy < 30.0 || wy > 70.0) ? -1 : 0;
    }
  }
  return map;
}

nav_msgs::Path plan(const Scene& scene)
{
  nav_msgs::Path path;
  path.header.frame_id = "map";
  const double x0 = scene.scan.origin.x, y0 = scene.scan.origin.y;
  const auto add = [&](double x, double y) {
    geometry_msgs::PoseStamped pose;
    pose.header.frame_id = "map";
    pose.pose.position.x = x;
    pose.pose.position.y = y;
    pose.pose.orientation.w = 1.0;
    path.poses.push_back(pose);
  };
  for (double x = x0; x < 60.0; x += 0.05)
  {
    add(x, y0);
  }
  for (double y = y0; y < 60.0; y += 0.05)
  {
    add(60.0, y);
  }
  return path;
}

sharing_msgs::RobotFootprintArray fleetRobots()
{
  sharing_msgs::RobotFootprintArray array;
  array.header.stamp = ros::Time::now();
  for (int k = 0; k < 10; ++k)
  {
    sharing_msgs::RobotFootprint robot;
    robot.header.frame_id = "map";
    robot.header.stamp = ros::Time::now();
    robot.robot = "robot_" + std::to_string(k + 1);
    const double cx = 30.0 + 4.0 * k, cy = 45.0;
    for (const auto& corner : { std::make_pair(-0.3, -0.3), std::make_pair(0.3, -0.3), std::make_pair(0.3, 0.3),
                                std::make_pair(-0.3, 0.3) })
    {
      geometry_msgs::Point32 p;
      p.x = static_cast<float>(cx + corner.first);
      p.y = static_cast<float>(cy + corner.second);
      robot.footprint.points.push_back(p);
    }
    array.robots.push_back(robot);
  }
  return array;
}

double heapBytes()
{
  const struct mallinfo2 m = mallinfo2();
  return static_cast<double>(m.uordblks + m.hblkhd);
}

bool spinUntil(const std::function<bool()>& done)
{
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60.0);
  while (ros::WallTime::now() < end)
  {
    ros::spinOnce();
    if (done())
    {
      return true;
    }
    ros::WallDuration(0.005).sleep();
  }
  return done();
}

std::string upstreamBuild()
{
  Dl_info info;
  if (dladdr(reinterpret_cast<void*>(&costmap_2d::calculateMinAndMaxDistances), &info) == 0 || !info.dli_fname)
  {
    return "costmap_2d: (not found)";
  }
  const std::string path = info.dli_fname;
  std::string type = "?", cache;
  // catkin_make: <ws>/devel/lib/libcostmap_2d.so -> <ws>/build/CMakeCache.txt; catkin_make_isolated (make setup):
  // <ws>/devel_isolated/costmap_2d/lib/libcostmap_2d.so -> <ws>/build_isolated/costmap_2d/CMakeCache.txt
  const std::size_t devel = path.rfind("/devel/lib/"), isolated = path.rfind("/devel_isolated/costmap_2d/lib/");
  if (devel != std::string::npos)
  {
    cache = path.substr(0, devel) + "/build/CMakeCache.txt";
  }
  else if (isolated != std::string::npos)
  {
    cache = path.substr(0, isolated) + "/build_isolated/costmap_2d/CMakeCache.txt";
  }
  std::ifstream in(cache);
  for (std::string line; std::getline(in, line);)
  {
    if (line.rfind("CMAKE_BUILD_TYPE:", 0) == 0)
    {
      type = line.substr(line.find('=') + 1);
    }
  }
  return "costmap_2d " + path + " (CMAKE_BUILD_TYPE " + type + ")";
}

std::string machine()
{
  std::string model = "unknown CPU";
  std::ifstream cpuinfo("/proc/cpuinfo");
  for (std::string line; std::getline(cpuinfo, line);)
  {
    if (line.rfind("model name", 0) == 0)
    {
      model = line.substr(line.find(':') + 2);
      break;
    }
  }
  double load[3] = { -1.0, -1.0, -1.0 };
  getloadavg(load, 3);
  char text[96];
  std::snprintf(text, sizeof(text), ", %u cores; load %.2f %.2f %.2f", std::thread::hardware_concurrency(), load[0],
                load[1], load[2]);
  return model + text;
}
}  // namespace bench
}  // namespace sharing_layer
