// The plugin's whole costmap update cycle against costmap_2d's own ObstacleLayer (issues 13, 29), in steady state:
// each layer in its own LayeredCostmap behind the same a-priori map layer, fed the reference scan
// (bench/reference_scene.h: 2000 x 2000 at 0.05 m, 1081 beams over 270 degrees) through its real observation
// buffer, timed over LayeredCostmap::updateMap (updateBounds, the master reset over the bounds, updateCosts).
// Ours has received the static map (it has left "waiting for the map"), the map topic's unknown cells, a global plan
// (the plan trigger runs on every scan) and 10 fleet robots' footprints before the timing starts.
// Rounds alternate which layer goes first; the figures are medians and the ratio ours / upstream is taken within
// the run. Also timed: the scan pass alone (each layer's updateBounds inside the same cycles), and the heap each
// layer adds (mallinfo2 around building, feeding and warming up each costmap), per cell, ours beyond upstream's,
// with beside it what the layer counts itself (SharingLayer::perCellBytes: the core's grids and the map's unknown).
// Targets (issue 29) are printed with each figure, "NOT MET" where missed; the exit code never depends on them.
//
// Built only where costmap_2d is installed; needs a ROS master (parameters, topics):
//   rosrun sharing_layer_cpp bench_plugin_cycle [rounds, default 500] [case 0..3, default all]
#include <dlfcn.h>
#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <costmap_2d/cost_values.h>
#include <costmap_2d/footprint.h>
#include <costmap_2d/layered_costmap.h>
#include <costmap_2d/obstacle_layer.h>
#include <costmap_2d/observation_buffer.h>
#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/RobotFootprintArray.h>
#include <sharing_msgs/SharedObstacle.h>
#include <tf2_ros/buffer.h>

#include "../../bench/reference_scene.h"
#include "../messages.h"
#include "../sharing_layer.h"

#ifndef SHARING_BENCH_FLAGS
#define SHARING_BENCH_FLAGS "unknown (built without SHARING_BENCH_FLAGS)"
#endif

namespace
{
using sharing_layer::bench::Scene;
using Clock = std::chrono::steady_clock;

/// A layer whose observation buffer is fed directly, and whose updateBounds (the scan pass) is timed.
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
  void updateBounds(double robot_x, double robot_y, double robot_yaw, double* min_x, double* min_y, double* max_x,
                    double* max_y) override
  {
    const auto start = Clock::now();
    Base::updateBounds(robot_x, robot_y, robot_yaw, min_x, min_y, max_x, max_y);
    bounds_seconds = std::chrono::duration<double>(Clock::now() - start).count();
  }
  double bounds_seconds = 0.0;  ///< the last updateBounds
};

/// The a-priori map as costmap_2d's StaticLayer delivers it to the layers after it (not rolling): on its first cycle
/// the bounds cover the whole map and the map is written into the master; after that it adds no bounds. (StaticLayer
/// also copies its map over the update window on every later cycle: the same work before either obstacle layer, left
/// out so that the ratio is theirs.)
class MapOnce : public costmap_2d::Layer
{
public:
  explicit MapOnce(const std::vector<unsigned char>& costs) : costs_(costs) {}
  void onInitialize() override
  {
    current_ = true;
    enabled_ = true;  // costmap_2d::Layer starts disabled
  }
  void updateBounds(double, double, double, double* min_x, double* min_y, double* max_x, double* max_y) override
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
  void updateCosts(costmap_2d::Costmap2D& master, int min_i, int min_j, int max_i, int max_j) override
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

private:
  const std::vector<unsigned char>& costs_;
  bool fresh_ = true;
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
  ros::param::set(ns + "map_topic", std::string("bench_map"));
  ros::param::set(ns + "plan_topics", std::string("bench_plan"));
  ros::param::set(ns + "fleet_robots_topic", std::string("bench_fleet_robots"));
  ros::param::set(ns + "robot_timeout", 0.0);  // the robots' stamps do not age out during the run
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

/// The master's a-priori costs: walls lethal, everything else free (unknown areas come on the map topic).
std::vector<unsigned char> masterMap(const Scene& scene)
{
  std::vector<unsigned char> costs(scene.map.size(), costmap_2d::FREE_SPACE);
  for (std::size_t i = 0; i < costs.size(); ++i)
  {
    costs[i] = scene.map[i] ? costmap_2d::LETHAL_OBSTACLE : costmap_2d::FREE_SPACE;
  }
  return costs;
}

/// The map topic's OccupancyGrid: walls 100, the hall free, outside the hall (x < 20, x > 80, y < 30, y > 70 m)
/// unknown.
nav_msgs::OccupancyGrid::Ptr occupancyGrid(const Scene& scene)
{
  const sharing_layer::GridGeometry& g = scene.geometry;
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

/// A 20 m plan from the robot east along y = 50.03 to (60, 50), then north to (60, 60), a pose every 0.05 m.
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

/// Ten fleet robots, 0.6 m squares along y = 45 m, in the map frame.
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

/// Bytes in use on the heap (every arena, and mmapped blocks).
double heapBytes()
{
  const struct mallinfo2 m = mallinfo2();
  return static_cast<double>(m.uordblks + m.hblkhd);
}

/// Spins until done() or 60 s; @return done()
template <class Done>
bool spinUntil(Done done)
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

/// Shares every crate with the layer through its topic and waits until it has drawn them all (the outcome).
bool shareCrates(const Scene& scene, costmap_2d::LayeredCostmap& costmap)
{
  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 200);
  if (!spinUntil([&] { return pub.getNumSubscribers() > 0; }))
  {
    return false;
  }
  for (int i = 0; i < sharing_layer::bench::kCrates; ++i)
  {
    pub.publish(sharing_layer::toMessage(sharing_layer::bench::crateUpdate(scene, i), "map"));
  }
  return spinUntil([&] {
    costmap.updateMap(scene.scan.origin.x, scene.scan.origin.y, 0.0);
    int drawn = 0;
    for (int i = 0; i < sharing_layer::bench::kCrates; ++i)
    {
      unsigned int mx = 0, my = 0;
      costmap.getCostmap()->worldToMap(scene.crates[i].first + 0.001, scene.crates[i].second + 0.001, mx, my);
      drawn += costmap.getCostmap()->getCost(mx, my) == costmap_2d::LETHAL_OBSTACLE;
    }
    return drawn == sharing_layer::bench::kCrates;
  });
}

double median(std::vector<double> v)
{
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

/// Where upstream's costmap_2d was loaded from, and its workspace's CMAKE_BUILD_TYPE when its CMakeCache is there.
std::string upstreamBuild()
{
  Dl_info info;
  if (dladdr(reinterpret_cast<void*>(&costmap_2d::calculateMinAndMaxDistances), &info) == 0 || !info.dli_fname)
  {
    return "costmap_2d: (not found)";
  }
  std::string path = info.dli_fname, type = "?";
  // <ws>/devel/lib/libcostmap_2d.so -> <ws>/build/CMakeCache.txt
  const std::size_t devel = path.rfind("/devel/lib/");
  if (devel != std::string::npos)
  {
    std::ifstream cache(path.substr(0, devel) + "/build/CMakeCache.txt");
    for (std::string line; std::getline(cache, line);)
    {
      if (line.rfind("CMAKE_BUILD_TYPE:", 0) == 0)
      {
        type = line.substr(line.find('=') + 1);
      }
    }
  }
  return "costmap_2d " + path + " (CMAKE_BUILD_TYPE " + type + ")";
}

struct Case
{
  double raytrace_range;
  double obstacle_range;
  bool shared;
};

const char* verdict(bool met)
{
  return met ? "met" : "NOT MET";
}
}  // namespace

int main(int argc, char** argv)
{
  ros::init(argc, argv, "bench_plugin_cycle");
  ros::NodeHandle nh;
  const int rounds = argc > 1 ? std::max(5, std::atoi(argv[1])) : 500;
  const int only_case = argc > 2 ? std::atoi(argv[2]) : -1;  // one case (0..3) alone, e.g. under a profiler
  const Scene scene = sharing_layer::bench::makeScene();
  const std::vector<unsigned char> master_map = masterMap(scene);
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
  const nav_msgs::Path path = plan(scene);
  ros::Publisher plan_pub = nh.advertise<nav_msgs::Path>("bench_plan", 1, true);
  ros::Publisher robots_pub = nh.advertise<sharing_msgs::RobotFootprintArray>("bench_fleet_robots", 1, true);
  plan_pub.publish(path);
  robots_pub.publish(fleetRobots());
  const double cells = static_cast<double>(scene.geometry.cellCount());

  std::printf("bench_plugin_cycle: ours built %s; upstream %s\n", SHARING_BENCH_FLAGS, upstreamBuild().c_str());
  std::printf("reference scan: %zu beams on %s; %d rounds per case, medians, alternating which layer goes first; each "
              "layer alone behind the same map layer; ours with the map received, a %zu-pose plan, 10 fleet robots\n",
              scene.scan.points.size(), scene.geometry.describe().c_str(), rounds, path.poses.size());
  std::printf("%-26s %9s %9s %22s %9s %9s %20s %15s %18s\n", "case", "up ms", "ours ms", "cycle ours/up", "up scan",
              "ours scan", "scan ours/up", "window", "heap beyond up");
  const Case cases[] = { { 3.0, 2.5, false }, { 3.0, 2.5, true }, { 30.0, 30.0, false }, { 30.0, 30.0, true } };
  bool all_met = true;
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
    const sharing_layer::GridGeometry& g = scene.geometry;
    const double x = scene.scan.origin.x, y = scene.scan.origin.y;

    // Upstream: built, fed and warmed up between two heap readings.
    const double heap0 = heapBytes();
    costmap_2d::LayeredCostmap upstream_costmap("map", false, false);
    auto* upstream_map = new MapOnce(master_map);
    upstream_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(upstream_map));
    upstream_map->initialize(&upstream_costmap, "upstream_map_" + tag, &tf);
    auto* upstream = new Fed<costmap_2d::ObstacleLayer>();
    upstream_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(upstream));
    upstream->initialize(&upstream_costmap, "upstream_" + tag, &tf);
    upstream_costmap.resizeMap(g.size_x, g.size_y, g.resolution, g.origin_x, g.origin_y);
    for (int r = 0; r < 3; ++r)
    {
      upstream->feed(cloud);
      upstream_costmap.updateMap(x, y, 0.0);
    }
    const double heap1 = heapBytes();

    // Ours: the same, plus the map topic (its publisher gone once received: the heap keeps what the layer keeps),
    // the plan, the fleet robots and, in the shared cases, the crates.
    costmap_2d::LayeredCostmap our_costmap("map", false, false);
    auto* our_map = new MapOnce(master_map);
    our_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(our_map));
    our_map->initialize(&our_costmap, "ours_map_" + tag, &tf);
    auto* ours = new Fed<sharing_layer::SharingLayer>();
    our_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(ours));
    ours->initialize(&our_costmap, "ours_" + tag, &tf);
    our_costmap.resizeMap(g.size_x, g.size_y, g.resolution, g.origin_x, g.origin_y);
    {
      ros::Publisher map_pub = nh.advertise<nav_msgs::OccupancyGrid>("bench_map", 1, true);
      map_pub.publish(occupancyGrid(scene));
      ours->feed(cloud);
      our_costmap.updateMap(x, y, 0.0);
      if (!spinUntil([&] { return ours->mapReceived() && ours->planPoses() > 0; }))
      {
        std::fprintf(stderr, "bench_plugin_cycle: the layer did not receive the map and the plan within 60 s (map %s, "
                     "plan %zu poses)\n", ours->mapReceived() ? "received" : "waiting", ours->planPoses());
        return 2;
      }
      map_pub.shutdown();
    }
    if (c.shared && !shareCrates(scene, our_costmap))
    {
      std::fprintf(stderr, "bench_plugin_cycle: the shared crates did not reach the layer within 60 s\n");
      return 2;
    }
    for (int r = 0; r < 3; ++r)
    {
      ours->feed(cloud);
      our_costmap.updateMap(x, y, 0.0);
    }
    ros::spinOnce();
    const double heap2 = heapBytes();

    std::vector<double> t_upstream, t_ours, s_upstream, s_ours;
    for (int r = 0; r < rounds; ++r)
    {
      upstream->feed(cloud);
      ours->feed(cloud);
      for (int k = 0; k < 2; ++k)
      {
        const bool upstream_now = (k == 0) == (r % 2 == 0);  // even rounds upstream first, odd rounds ours
        costmap_2d::LayeredCostmap& costmap = upstream_now ? upstream_costmap : our_costmap;
        const auto start = Clock::now();
        costmap.updateMap(x, y, 0.0);
        const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
        (upstream_now ? t_upstream : t_ours).push_back(seconds);
        (upstream_now ? s_upstream : s_ours).push_back(upstream_now ? upstream->bounds_seconds : ours->bounds_seconds);
      }
    }
    if (!ours->mapReceived())
    {
      std::fprintf(stderr, "bench_plugin_cycle: the layer went back to waiting for the map\n");
      return 2;
    }
    unsigned int a[4], b[4];
    upstream_costmap.getBounds(&a[0], &a[1], &a[2], &a[3]);
    our_costmap.getBounds(&b[0], &b[1], &b[2], &b[3]);
    const double cycle = median(t_ours) / median(t_upstream);
    const double scan = median(s_ours) / median(s_upstream);
    const double beyond = ((heap2 - heap1) - (heap1 - heap0)) / cells;
    const double reported = static_cast<double>(ours->perCellBytes()) / cells;  // what the layer counts, beside it
    const double cycle_target = 0.9, scan_target = 1.0, memory_target = 1.0;
    const bool cycle_met = cycle <= cycle_target, scan_met = !c.shared || scan <= scan_target;
    const bool memory_met = beyond <= memory_target;
    all_met = all_met && cycle_met && scan_met && memory_met;
    char label[64], window[32], cycle_text[48], scan_text[48], memory_text[64];
    std::snprintf(label, sizeof(label), "%.0f m / %.1f m, %d shared", c.raytrace_range, c.obstacle_range,
                  c.shared ? sharing_layer::bench::kCrates : 0);
    if (a[0] == b[0] && a[1] == b[1] && a[2] == b[2] && a[3] == b[3])
    {
      std::snprintf(window, sizeof(window), "%ux%u", a[1] - a[0], a[3] - a[2]);
    }
    else
    {
      std::snprintf(window, sizeof(window), "%ux%u/%ux%u", a[1] - a[0], a[3] - a[2], b[1] - b[0], b[3] - b[2]);
    }
    std::snprintf(cycle_text, sizeof(cycle_text), "%.3f (<=%.1f %s)", cycle, cycle_target, verdict(cycle_met));
    if (c.shared)
    {
      std::snprintf(scan_text, sizeof(scan_text), "%.3f (<=%.1f %s)", scan, scan_target, verdict(scan_met));
    }
    else
    {
      std::snprintf(scan_text, sizeof(scan_text), "%.3f", scan);
    }
    std::snprintf(memory_text, sizeof(memory_text), "%.3f B/cell (<=%.1f %s; counted %.3f)", beyond, memory_target,
                  verdict(memory_met), reported);
    std::printf("%-26s %9.3f %9.3f %22s %9.3f %9.3f %20s %15s %18s\n", label, median(t_upstream) * 1e3,
                median(t_ours) * 1e3, cycle_text, median(s_upstream) * 1e3, median(s_ours) * 1e3, scan_text, window,
                memory_text);
    std::fflush(stdout);
  }
  std::printf("targets: whole cycle <= 0.9 x upstream in every case; scan pass (updateBounds) <= 1.0 x with "
              "100 shared; heap beyond ObstacleLayer <= 1.0 B/cell: %s\n",
              all_met ? "all met" : "NOT all met (see above)");
  return 0;
}
