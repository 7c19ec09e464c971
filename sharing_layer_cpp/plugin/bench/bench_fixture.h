// What the plugin's benchmarks share: the reference scene as ROS messages, a layer whose scan pass is timed, the map
// layer in front of it, both clocks, and the machine they ran on. Built only where costmap_2d is installed.
#ifndef SHARING_LAYER_PLUGIN_BENCH_BENCH_FIXTURE_H
#define SHARING_LAYER_PLUGIN_BENCH_BENCH_FIXTURE_H

#include <functional>
#include <string>
#include <vector>

#include <costmap_2d/layer.h>
#include <costmap_2d/layered_costmap.h>
#include <costmap_2d/obstacle_layer.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sharing_msgs/RobotFootprintArray.h>
#include <tf2_ros/buffer.h>

#include "../../bench/reference_scene.h"
#include "../sharing_layer.h"

namespace sharing_layer
{
namespace bench
{
/// @brief One reading of both clocks: the wall (steady) clock, and the CPU time of the calling thread. On a shared
/// machine the wall clock also counts the time other processes held the core; the thread's CPU time does not (it
/// still pays for the caches they evicted).
struct Stamp
{
  double wall = 0.0;  ///< s, steady clock
  double cpu = 0.0;   ///< s, CLOCK_THREAD_CPUTIME_ID
  static Stamp now();
  /// @return the time from `start` to this reading, on both clocks
  Stamp since(const Stamp& start) const { return Stamp{ wall - start.wall, cpu - start.cpu }; }
};

/// @brief Samples of one subject on both clocks.
struct Samples
{
  std::vector<double> wall, cpu;
  void add(const Stamp& duration)
  {
    wall.push_back(duration.wall);
    cpu.push_back(duration.cpu);
  }
};

/// @return the median (the upper one of an even count); NaN for none
double median(std::vector<double> values);

/// @brief A layer whose observation buffer is fed directly, and whose updateBounds (the scan pass) is timed on both
/// clocks.
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
    const Stamp start = Stamp::now();
    Base::updateBounds(robot_x, robot_y, robot_yaw, min_x, min_y, max_x, max_y);
    bounds = Stamp::now().since(start);
  }
  Stamp bounds;  ///< the last updateBounds
};

/// @brief The a-priori map as costmap_2d's StaticLayer delivers it to the layers after it (not rolling): on its first
/// cycle the bounds cover the whole map and the map is written into the master; after that it adds no bounds.
/// (StaticLayer also copies its map over the update window on every later cycle: the same work before either obstacle
/// layer, left out so that the ratio is theirs.)
class MapOnce : public costmap_2d::Layer
{
public:
  explicit MapOnce(const std::vector<unsigned char>& costs) : costs_(costs) {}
  void onInitialize() override;
  void updateBounds(double, double, double, double* min_x, double* min_y, double* max_x, double* max_y) override;
  void updateCosts(costmap_2d::Costmap2D& master, int min_i, int min_j, int max_i, int max_j) override;

private:
  const std::vector<unsigned char>& costs_;
  bool fresh_ = true;
};

/// One layer in its own LayeredCostmap behind the map layer, its cycle and scan pass timed on both clocks.
template <class LayerType>
struct Subject
{
  costmap_2d::LayeredCostmap costmap{ "map", false, false };
  Fed<LayerType>* layer = nullptr;
  Samples cycle, scan;

  Subject(const std::vector<unsigned char>& master_map, const std::string& name, tf2_ros::Buffer& tf,
          const sharing_layer::GridGeometry& g)
  {
    auto* map = new MapOnce(master_map);
    costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(map));
    map->initialize(&costmap, name + "_map", &tf);
    layer = new Fed<LayerType>();
    costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
    layer->initialize(&costmap, name, &tf);
    costmap.resizeMap(g.size_x, g.size_y, g.resolution, g.origin_x, g.origin_y);
  }
  /// One cycle with a fresh scan, timed.
  void timedCycle(double x, double y)
  {
    const Stamp start = Stamp::now();
    costmap.updateMap(x, y, 0.0);
    cycle.add(Stamp::now().since(start));
    scan.add(layer->bounds);
  }
};

/// @brief What every subject needs around it: the scene, the master's a-priori costs, the laser's transform and its
/// cloud, and, latched for ours, the plan and the fleet robots.
struct Stage
{
  explicit Stage(ros::NodeHandle& nh);
  Scene scene;
  std::vector<unsigned char> master_map;
  tf2_ros::Buffer tf;
  sensor_msgs::PointCloud2 cloud;
  nav_msgs::Path path;
  ros::Publisher plan_pub, robots_pub;
};

/// @brief Three cycles of upstream's layer with the scene's scan.
void warmUp(Stage& stage, Subject<costmap_2d::ObstacleLayer>& upstream);
/// @brief Ours in steady state: the map topic's unknown cells (its publisher gone once received: the heap keeps what
/// the layer keeps) and the static map read, the plan received, the crates shared when `shared` (through the layer's
/// topic, drawn: the outcome), then three cycles. @return "" or what did not happen within 60 s
std::string warmUp(Stage& stage, ros::NodeHandle& nh, Subject<sharing_layer::SharingLayer>& ours, bool shared);

/// @brief The private parameters of an obstacle layer named `layer` (either kind): one PointCloud2 source "scan" that
/// marks and clears with these ranges, and ours' topics renamed to the bench's.
void setSource(const std::string& layer, double obstacle_range, double raytrace_range);
/// @brief The scan's points in the laser frame (the laser at the scan's origin).
sensor_msgs::PointCloud2 laserCloud(const Scene& scene);
/// @brief The master's a-priori costs: walls lethal, everything else free (unknown areas come on the map topic).
std::vector<unsigned char> masterMap(const Scene& scene);
/// @brief The map topic's OccupancyGrid: walls 100, the hall free, outside the hall (x < 20, x > 80, y < 30, y > 70 m)
/// unknown.
nav_msgs::OccupancyGrid::Ptr occupancyGrid(const Scene& scene);
/// @brief A 20 m plan from the robot east along y = 50.03 to (60, 50), then north to (60, 60), a pose every 0.05 m.
nav_msgs::Path plan(const Scene& scene);
/// @brief Ten fleet robots, 0.6 m squares along y = 45 m, in the map frame.
sharing_msgs::RobotFootprintArray fleetRobots();
/// @return bytes in use on the heap (every arena, and mmapped blocks)
double heapBytes();
/// @brief Spins ROS callbacks until done() or 60 s; @return done()
bool spinUntil(const std::function<bool()>& done);
/// @return where upstream's costmap_2d was loaded from, and its CMAKE_BUILD_TYPE when its build folder is there
std::string upstreamBuild();
/// @return "<CPU model>, <n> cores; load <1, 5, 15 min>" of this machine now
std::string machine();
}  // namespace bench
}  // namespace sharing_layer

#endif  // SHARING_LAYER_PLUGIN_BENCH_BENCH_FIXTURE_H
