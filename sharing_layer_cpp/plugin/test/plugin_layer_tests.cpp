// The plugin beside costmap_2d's own ObstacleLayer (issue 13): both fed the same clouds through their real
// observation buffers, their grids must be byte-identical and their update bounds equal, for a source that marks
// and clears, for marking-only and clearing-only sources with their own ranges, and in a rolling window. Shared
// obstacles must keep their place in the world when the map is resized or moved, or the window rolls.
// Needs a ROS master (parameters, topics): plugin_layer.test.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <set>
#include <utility>
#include <string>
#include <vector>

#include <costmap_2d/cost_values.h>
#include <costmap_2d/layered_costmap.h>
#include <costmap_2d/obstacle_layer.h>
#include <costmap_2d/observation_buffer.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <geometry_msgs/TransformStamped.h>
#include <nav_msgs/OccupancyGrid.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/SharedObstacle.h>
#include <std_msgs/Empty.h>
#include <tf2_ros/buffer.h>

#include "../sharing_layer.h"
#include "diagnostics_listener.h"

namespace
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
using FedObstacleLayer = Fed<costmap_2d::ObstacleLayer>;
using FedSharingLayer = Fed<sharing_layer::SharingLayer>;

struct Source
{
  std::string name;
  bool marking;
  bool clearing;
  double obstacle_range;
  double raytrace_range;
};

void setSources(const std::string& layer, const std::vector<Source>& sources)
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
void placeLaser(tf2_ros::Buffer& tf, double x, double y)
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
sensor_msgs::PointCloud2 ring(int beams, double phase)
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

/// Two costmaps, one with each layer, driven alike.
struct SideBySide
{
  tf2_ros::Buffer tf;  // filled with setTransform only (setUsingDedicatedThread: no waiting for it)
  costmap_2d::LayeredCostmap upstream_costmap;
  costmap_2d::LayeredCostmap our_costmap;
  FedObstacleLayer* upstream = nullptr;
  FedSharingLayer* ours = nullptr;

  SideBySide(const std::string& tag, const std::vector<Source>& sources, bool rolling, unsigned int cells)
    : upstream_costmap("map", rolling, false), our_costmap("map", rolling, false)
  {
    tf.setUsingDedicatedThread(true);
    setSources("upstream_" + tag, sources);
    setSources("ours_" + tag, sources);
    upstream = new FedObstacleLayer();
    upstream_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(upstream));
    upstream->initialize(&upstream_costmap, "upstream_" + tag, &tf);
    ours = new FedSharingLayer();
    our_costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(ours));
    ours->initialize(&our_costmap, "ours_" + tag, &tf);
    upstream_costmap.resizeMap(cells, cells, 0.05, 0.0, 0.0);
    our_costmap.resizeMap(cells, cells, 0.05, 0.0, 0.0);
  }

  void feed(std::size_t source, const sensor_msgs::PointCloud2& cloud)
  {
    upstream->feed(source, cloud);
    ours->feed(source, cloud);
  }

  void update(double robot_x, double robot_y)
  {
    upstream_costmap.updateMap(robot_x, robot_y, 0.0);
    our_costmap.updateMap(robot_x, robot_y, 0.0);
  }

  /// The laser at (x, y), one cloud from the first source, an update there, then both compared (expectSame).
  void scanFrom(double x, double y, const sensor_msgs::PointCloud2& cloud, const std::string& when)
  {
    placeLaser(tf, x, y);
    feed(0, cloud);
    update(x, y);
    expectSame(when);
  }

  /// Cell centres (world, mm) lethal in our master and not in upstream's.
  std::set<std::pair<long, long>> onlyInOurs()
  {
    std::set<std::pair<long, long>> cells;
    const costmap_2d::Costmap2D& a = *upstream_costmap.getCostmap();
    const costmap_2d::Costmap2D& b = *our_costmap.getCostmap();
    for (unsigned int y = 0; y < b.getSizeInCellsY(); ++y)
    {
      for (unsigned int x = 0; x < b.getSizeInCellsX(); ++x)
      {
        if (b.getCost(x, y) == costmap_2d::LETHAL_OBSTACLE && a.getCost(x, y) != costmap_2d::LETHAL_OBSTACLE)
        {
          double wx = 0.0, wy = 0.0;
          b.mapToWorld(x, y, wx, wy);
          cells.emplace(std::lround(wx * 1000.0), std::lround(wy * 1000.0));
        }
      }
    }
    return cells;
  }

  /// Byte-identical own grids and masters, equal update bounds, same origin.
  void expectSame(const std::string& when)
  {
    SCOPED_TRACE(when);
    ASSERT_EQ(upstream->getSizeInCellsX(), ours->getSizeInCellsX());
    ASSERT_EQ(upstream->getSizeInCellsY(), ours->getSizeInCellsY());
    EXPECT_DOUBLE_EQ(upstream->getOriginX(), ours->getOriginX());
    EXPECT_DOUBLE_EQ(upstream->getOriginY(), ours->getOriginY());
    const std::size_t n = upstream->getSizeInCellsX() * upstream->getSizeInCellsY();
    std::size_t differ = 0, lethal = 0;
    for (std::size_t i = 0; i < n; ++i)
    {
      differ += upstream->getCharMap()[i] != ours->getCharMap()[i];
      differ += upstream_costmap.getCostmap()->getCharMap()[i] != our_costmap.getCostmap()->getCharMap()[i];
      lethal += upstream->getCharMap()[i] == costmap_2d::LETHAL_OBSTACLE;
    }
    EXPECT_EQ(0u, differ) << "cells that differ from costmap_2d's ObstacleLayer";
    EXPECT_TRUE(ours->sharesGridWithCore()) << "one obstacle grid: the core must work in the layer's own costmap_";
    EXPECT_GT(lethal, 0u) << "the scene marks something";
    unsigned int a[4], b[4];
    upstream_costmap.getBounds(&a[0], &a[1], &a[2], &a[3]);
    our_costmap.getBounds(&b[0], &b[1], &b[2], &b[3]);
    for (int k = 0; k < 4; ++k)
    {
      EXPECT_EQ(a[k], b[k]) << "update bounds (min_x, max_x, min_y, max_y) element " << k;
    }
  }
};

/// Sends a 3 x 3-cell shared obstacle around world (3.05, 3.05) to the layer, as its handler would, and waits
/// until the layer has drawn it into the master (the outcome), at most 30 s.
bool shareBlockAt3m(costmap_2d::LayeredCostmap& costmap, double robot_x, double robot_y)
{
  ros::NodeHandle nh;
  ros::Publisher pub = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 1, true);
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

unsigned char costAt(costmap_2d::LayeredCostmap& costmap, double x, double y)
{
  unsigned int mx = 0, my = 0;
  if (!costmap.getCostmap()->worldToMap(x, y, mx, my))
  {
    return 0;
  }
  return costmap.getCostmap()->getCost(mx, my);
}
}  // namespace

TEST(PluginLayer, ASourceThatMarksAndClearsMatchesObstacleLayer)
{
  SideBySide maps("dual", { { "scan", true, true, 2.5, 3.0 } }, false, 200);
  maps.scanFrom(5.0, 5.0, ring(360, 0.0), "first scan from (5, 5)");
  maps.scanFrom(5.6, 4.7, ring(360, 0.01), "second scan from (5.6, 4.7), clearing the first's marks");
}

TEST(PluginLayer, CombinationMethodOverwriteMatchesObstacleLayer)
{
  // combination_method 0 (updateWithOverwrite) with unknown space tracked, so that the layer holds all three
  // kinds of cell: free, lethal and NO_INFORMATION, which must leave the master alone.
  for (const std::string layer : { "~upstream_overwrite/", "~ours_overwrite/" })
  {
    ros::param::set(layer + "combination_method", 0);
    ros::param::set(layer + "track_unknown_space", true);
  }
  SideBySide maps("overwrite", { { "scan", true, true, 2.5, 3.0 } }, false, 200);
  maps.scanFrom(5.0, 5.0, ring(360, 0.0), "first scan from (5, 5)");
  maps.scanFrom(5.6, 4.7, ring(360, 0.01), "second scan from (5.6, 4.7)");
}

TEST(PluginLayer, TrackUnknownSpaceKeepsUnseenCellsUnknownAsObstacleLayerDoes)
{
  // track_unknown_space: the layer's grid starts NO_INFORMATION and keeps it where no beam passed; updateWithMax
  // leaves those cells of the master alone.
  for (const std::string layer : { "~upstream_unknown/", "~ours_unknown/" })
  {
    ros::param::set(layer + "track_unknown_space", true);
  }
  SideBySide maps("unknown", { { "scan", true, true, 2.5, 3.0 } }, false, 200);
  maps.scanFrom(5.0, 5.0, ring(360, 0.0), "first scan from (5, 5)");
  std::size_t unknown = 0;
  for (std::size_t i = 0; i < 200u * 200u; ++i)
  {
    unknown += maps.ours->getCharMap()[i] == costmap_2d::NO_INFORMATION;
  }
  EXPECT_GT(unknown, 200u * 200u / 2) << "cells no beam reached must stay unknown";
  maps.scanFrom(5.6, 4.7, ring(360, 0.01), "second scan from (5.6, 4.7)");
}

TEST(PluginLayer, TheLayersMaxObstacleHeightBoundsMarkingOnlyAsObstacleLayersDoes)
{
  // The layer-level max_obstacle_height (the one dynamic_reconfigure changes) keeps points above it from being
  // marked, yet they still clear; the source's own heights (2 m here) filter both in the observation buffer.
  for (const std::string layer : { "~upstream_height/", "~ours_height/" })
  {
    ros::param::set(layer + "max_obstacle_height", 0.4);
  }
  SideBySide maps("height", { { "scan", true, true, 2.5, 3.0 } }, false, 200);
  const auto at_height = [](sensor_msgs::PointCloud2 cloud, bool alternate) {
    sensor_msgs::PointCloud2Iterator<float> z(cloud, "z");
    for (int i = 0; z != z.end(); ++i, ++z)
    {
      *z = alternate && i % 2 == 0 ? 0.0f : -0.3f;  // the laser at 0.5 m: points at 0.5 m or 0.2 m
    }
    return cloud;
  };
  maps.scanFrom(5.0, 5.0, at_height(ring(360, 0.0), false), "every point at 0.2 m: marked");
  maps.scanFrom(5.6, 4.7, at_height(ring(360, 0.01), true),
                "every other point at 0.5 m: clears the first scan's marks, marks nothing");
}

TEST(PluginLayer, MarkingOnlyAndClearingOnlySourcesWithTheirOwnRangesMatchObstacleLayer)
{
  SideBySide maps("roles", { { "marker", true, false, 4.0, 3.0 }, { "clearer", false, true, 2.5, 6.0 } }, false,
                  200);
  placeLaser(maps.tf, 5.0, 5.0);
  maps.feed(0, ring(360, 0.0));
  maps.feed(1, ring(180, 0.3));
  maps.update(5.0, 5.0);
  maps.expectSame("marker and clearer from (5, 5)");
  placeLaser(maps.tf, 4.2, 5.5);
  maps.feed(0, ring(360, 0.05));
  maps.feed(1, ring(180, 0.2));
  maps.update(4.2, 5.5);
  maps.expectSame("both again from (4.2, 5.5)");
}

TEST(PluginLayer, ARollingWindowMovesLikeObstacleLayersAndKeepsSharedObstaclesInTheWorld)
{
  SideBySide maps("rolling", { { "scan", true, true, 2.5, 3.0 } }, true, 100);  // a 5 m window
  maps.scanFrom(2.0, 2.0, ring(360, 0.0), "window around (2, 2)");
  ASSERT_TRUE(shareBlockAt3m(maps.our_costmap, 2.0, 2.0));
  // Everything but the shared block is ObstacleLayer's; the block is its 9 cells, where it was sent.
  std::set<std::pair<long, long>> block;
  for (long y : { 3025, 3075, 3125 })
  {
    for (long x : { 3025, 3075, 3125 })
    {
      block.emplace(x, y);
    }
  }
  maps.update(2.0, 2.0);
  EXPECT_EQ(block, maps.onlyInOurs());
  placeLaser(maps.tf, 2.6, 2.3);
  maps.feed(0, ring(360, 0.02));
  maps.update(2.6, 2.3);
  EXPECT_NE(maps.upstream->getOriginX(), -0.5) << "the window moved";
  EXPECT_EQ(block, maps.onlyInOurs()) << "the block stayed where it is in the world as the window rolled";
}

TEST(PluginLayer, AMapResizeOrMoveKeepsSharedObstaclesWhereTheyAreInTheWorld)
{
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  setSources("resized", { { "scan", true, true, 2.5, 3.0 } });
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, "resized", &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);
  ASSERT_TRUE(shareBlockAt3m(costmap, 5.0, 5.0));
  costmap.resizeMap(240, 240, 0.05, -1.0, -1.0);  // a larger map, its origin moved
  costmap.updateMap(5.0, 5.0, 0.0);
  EXPECT_EQ(costmap_2d::LETHAL_OBSTACLE, costAt(costmap, 3.05, 3.05));
  costmap.resizeMap(200, 200, 0.1, 0.0, 0.0);  // another resolution
  costmap.updateMap(5.0, 5.0, 0.0);
  EXPECT_EQ(costmap_2d::LETHAL_OBSTACLE, costAt(costmap, 3.05, 3.05));
  costmap.resizeMap(40, 40, 0.05, 5.0, 5.0);  // the block falls off: dropped, nothing drawn
  costmap.updateMap(6.0, 6.0, 0.0);
  std::size_t lethal = 0;
  for (unsigned int i = 0; i < 40 * 40; ++i)
  {
    lethal += costmap.getCostmap()->getCharMap()[i] == costmap_2d::LETHAL_OBSTACLE;
  }
  EXPECT_EQ(0u, lethal);
}

// costmap_2d's layer contract: updateCosts(master, min_i, min_j, max_i, max_j) may write the master only inside that
// window (LayeredCostmap resets only the window; what lies outside is other layers' and earlier cycles'). The layer
// drew every shared cell on every cycle, wherever the window was.
TEST(PluginLayer, UpdateCostsWritesTheMasterOnlyInsideTheUpdateWindow)
{
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  setSources("window", { { "scan", true, true, 2.5, 3.0 } });
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, "window", &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);
  ASSERT_TRUE(shareBlockAt3m(costmap, 5.0, 5.0));  // cells (60..62, 60..62)
  placeLaser(tf, 5.0, 5.0);
  layer->feed(0, ring(360, 0.0));
  costmap.updateMap(5.0, 5.0, 0.0);  // the layer's own grid has marks around (5, 5) now
  costmap_2d::Costmap2D& master = *costmap.getCostmap();
  const auto check = [&](int min_i, int min_j, int max_i, int max_j, std::size_t block_cells_inside) {
    SCOPED_TRACE("window [" + std::to_string(min_i) + ", " + std::to_string(max_i) + ") x [" + std::to_string(min_j) +
                 ", " + std::to_string(max_j) + ")");
    std::fill(master.getCharMap(), master.getCharMap() + 200 * 200, 77);
    layer->updateCosts(master, min_i, min_j, max_i, max_j);
    std::size_t outside_written = 0, block_drawn = 0;
    for (int y = 0; y < 200; ++y)
    {
      for (int x = 0; x < 200; ++x)
      {
        const bool inside = x >= min_i && x < max_i && y >= min_j && y < max_j;
        const unsigned char cost = master.getCost(x, y);
        outside_written += !inside && cost != 77;
        block_drawn += inside && x >= 60 && x <= 62 && y >= 60 && y <= 62 && cost == costmap_2d::LETHAL_OBSTACLE;
      }
    }
    EXPECT_EQ(0u, outside_written) << "master cells written outside the update window";
    EXPECT_EQ(block_cells_inside, block_drawn) << "the shared block's cells inside the window are drawn";
  };
  check(61, 61, 120, 120, 4);  // the block's corner inside, the layer's marks around (5, 5) too
  check(0, 0, 40, 40, 0);      // neither the block nor the scan
  check(0, 0, 200, 200, 9);    // the whole map
  check(70, 70, 60, 60, 0);    // inverted: nothing at all
}

// ObstacleLayer takes any range; the core refuses a negative one. Bad input: that source is skipped with an
// error naming it, never an exception out of updateMap (move_base would die).
TEST(PluginLayer, ASourceWithANegativeRangeIsSkippedNotACrash)
{
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  setSources("negative", { { "scan", true, true, -1.0, 3.0 } });
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, "negative", &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);
  placeLaser(tf, 5.0, 5.0);
  layer->feed(0, ring(360, 0.0));
  EXPECT_NO_THROW(costmap.updateMap(5.0, 5.0, 0.0));
  std::size_t lethal = 0;
  for (unsigned int i = 0; i < 200 * 200; ++i)
  {
    lethal += costmap.getCostmap()->getCharMap()[i] == costmap_2d::LETHAL_OBSTACLE;
  }
  EXPECT_EQ(0u, lethal);
}

// --- issue 28: /diagnostics and dynamic_reconfigure ---

namespace
{
using sharing_layer_test::contains;
using sharing_layer_test::countOf;
using sharing_layer_test::DiagnosticsListener;
using sharing_layer_test::valueOf;

/// Calls a dynamic_reconfigure set_parameters service from another thread while this one spins (the server answers
/// on the global callback queue), at most 15 s. @return false when the call failed or timed out
bool reconfigure(const std::string& service, dynamic_reconfigure::Reconfigure& srv)
{
  if (!ros::service::waitForService(service, ros::Duration(10.0)))
  {
    return false;
  }
  std::future<bool> done = std::async(std::launch::async, [&] { return ros::service::call(service, srv); });
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(15.0);
  while (done.wait_for(std::chrono::milliseconds(10)) != std::future_status::ready)
  {
    ros::spinOnce();
    if (ros::WallTime::now() > end)
    {
      return false;
    }
  }
  return done.get();
}

double doubleIn(const dynamic_reconfigure::Config& config, const std::string& name)
{
  for (const dynamic_reconfigure::DoubleParameter& p : config.doubles)
  {
    if (p.name == name)
    {
      return p.value;
    }
  }
  return std::nan("");
}

int intIn(const dynamic_reconfigure::Config& config, const std::string& name)
{
  for (const dynamic_reconfigure::IntParameter& p : config.ints)
  {
    if (p.name == name)
    {
      return p.value;
    }
  }
  return -12345;
}
}  // namespace

// The layer's set-up warnings were log lines only: /diagnostics names them, with the reason.
TEST(PluginLayer, DiagnosticsNameAMissingObservationSourceAsAnError)
{
  DiagnosticsListener diagnostics;
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  setSources("diag_blind", {});
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, "diag_blind", &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);
  const std::string name = "sharing_layer: robot_0 (diag_blind)";
  const std::string parameter = ros::this_node::getName() + "/diag_blind/observation_sources";
  EXPECT_TRUE(diagnostics.waitFor(name,
                                  [&](const diagnostic_msgs::DiagnosticStatus& s) {
                                    return s.level == diagnostic_msgs::DiagnosticStatus::ERROR &&
                                           contains(s.message, "no observation source") &&
                                           contains(s.message, parameter) &&
                                           valueOf(s, "observation sources") == "none";
                                  },
                                  [&] { costmap.updateMap(5.0, 5.0, 0.0); }))
      << diagnostics.describe(name);
  EXPECT_EQ("robot_0", diagnostics.latest[name].hardware_id);
}

TEST(PluginLayer, DiagnosticsReportTheMapOnceReceivedAndCountObstaclesAndProposals)
{
  DiagnosticsListener diagnostics;
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  setSources("diag", { { "scan", true, true, 2.5, 3.0 } });
  ros::param::set("~diag/map_topic", std::string("diag_map"));
  ros::param::set("~diag/plan_topics", std::string("diag_plan"));
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, "diag", &tf);
  const std::string name = "sharing_layer: robot_0 (diag)";
  // No map yet, no plan publisher: WARN, with the reasons.
  EXPECT_TRUE(diagnostics.waitFor(name, [](const diagnostic_msgs::DiagnosticStatus& s) {
    return s.level == diagnostic_msgs::DiagnosticStatus::WARN && contains(s.message, "waiting for the map") &&
           contains(s.message, "no map on [diag_map]") && contains(s.message, "nothing publishes the global plan") &&
           valueOf(s, "map received") == "False" && valueOf(s, "observation sources") == "scan" &&
           valueOf(s, "plan trigger alive") == "False";
  })) << diagnostics.describe(name);

  // The map arrives (its topic, then the static layer's first full update) and a planner publishes.
  ros::NodeHandle nh;
  ros::Publisher map_pub = nh.advertise<nav_msgs::OccupancyGrid>("diag_map", 1, true);
  nav_msgs::OccupancyGrid map;
  map.header.frame_id = "map";
  map.info.resolution = 0.05f;
  map.info.width = map.info.height = 200;
  map.info.origin.orientation.w = 1.0;
  map.data.assign(200 * 200, 0);
  map_pub.publish(map);
  ros::Publisher plan_pub = nh.advertise<nav_msgs::Path>("diag_plan", 1);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);
  layer->updateCosts(*costmap.getCostmap(), 0, 0, 200, 200);  // as after the static layer drew the whole map
  EXPECT_TRUE(diagnostics.waitFor(name,
                                  [](const diagnostic_msgs::DiagnosticStatus& s) {
                                    return s.level == diagnostic_msgs::DiagnosticStatus::OK &&
                                           valueOf(s, "map received") == "True" &&
                                           valueOf(s, "map topic") == "diag_map (received)" &&
                                           valueOf(s, "plan trigger alive") == "True";
                                  },
                                  [&] { costmap.updateMap(5.0, 5.0, 0.0); }))
      << diagnostics.describe(name);

  // A shared obstacle is held, a bad one rejected, and a stuck trigger proposes what the laser marked.
  ASSERT_TRUE(shareBlockAt3m(costmap, 5.0, 5.0));
  ros::Publisher shared_pub = nh.advertise<sharing_msgs::SharedObstacle>("shared_obstacles", 1, true);
  sharing_msgs::SharedObstacle bad;
  bad.header.frame_id = "map";
  bad.uuid = "bad-one";
  bad.source = "robot_1";
  bad.resolution = 0.05f;
  bad.size_x = bad.size_y = 200;
  bad.marked_indexes.push_back(200 * 200 + 7);  // off the grid
  bad.rectangle_shape = { 2.9f, 2.9f, 3.3f, 3.3f };
  bad.deadline = 600;
  bad.version = 1;
  shared_pub.publish(bad);
  ros::Publisher stuck_pub = nh.advertise<std_msgs::Empty>("stuck_feedback", 10);
  placeLaser(tf, 5.0, 5.0);
  EXPECT_TRUE(diagnostics.waitFor(name,
                                  [](const diagnostic_msgs::DiagnosticStatus& s) {
                                    return countOf(s, "shared obstacles held") == 1 &&
                                           countOf(s, "fleet messages applied") == 1 &&
                                           countOf(s, "fleet messages rejected") >= 1 &&
                                           countOf(s, "proposals published") >= 1 &&
                                           contains(valueOf(s, "last rejection"), "bad-one");
                                  },
                                  [&] {
                                    layer->feed(0, ring(360, 0.0));
                                    stuck_pub.publish(std_msgs::Empty());
                                    costmap.updateMap(5.0, 5.0, 0.0);
                                  }))
      << diagnostics.describe(name);
}

// The sharing parameters in <layer>/sharing (the layer's own namespace is ObstacleLayer's server): applied at the
// next cycle, a bad value refused with the previous configuration kept.
TEST(PluginLayer, DynamicReconfigureAppliesAtTheNextCycleAndRefusesABadValue)
{
  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  setSources("reconf", { { "scan", true, true, 2.5, 3.0 } });
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new FedSharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, "reconf", &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);
  const std::string ours = ros::this_node::getName() + "/reconf/sharing/set_parameters";
  EXPECT_TRUE(ros::service::waitForService(ros::this_node::getName() + "/reconf/set_parameters", ros::Duration(5.0)))
      << "ObstacleLayer's own server stays where it was";

  dynamic_reconfigure::Reconfigure change;
  dynamic_reconfigure::DoubleParameter radius;
  radius.name = "trigger_radius";
  radius.value = 1.5;
  change.request.config.doubles.push_back(radius);
  dynamic_reconfigure::IntParameter tolerance;
  tolerance.name = "static_tolerance";
  tolerance.value = 5;
  change.request.config.ints.push_back(tolerance);
  dynamic_reconfigure::BoolParameter memory;
  memory.name = "memory_on_stuck_feedback";
  memory.value = true;
  change.request.config.bools.push_back(memory);
  ASSERT_TRUE(reconfigure(ours, change)) << ours;
  EXPECT_EQ(1.5, doubleIn(change.response.config, "trigger_radius"));
  EXPECT_EQ(5, intIn(change.response.config, "static_tolerance"));
  EXPECT_EQ(4.0, layer->sharingParams().trigger_radius) << "applied at the next cycle, not before";
  costmap.updateMap(5.0, 5.0, 0.0);
  EXPECT_EQ(1.5, layer->sharingParams().trigger_radius);
  EXPECT_EQ(5, layer->sharingParams().static_tolerance);
  EXPECT_TRUE(layer->sharingParams().memory_on_stuck_feedback);
  EXPECT_EQ(3u, layer->sharingParams().clearing_scans) << "what was not sent stays";

  // A bad value (validate() refuses clearing_scans 0) with a good one: neither applies; the server answers with the
  // previous configuration.
  dynamic_reconfigure::Reconfigure bad;
  dynamic_reconfigure::IntParameter scans;
  scans.name = "clearing_scans";
  scans.value = 0;
  bad.request.config.ints.push_back(scans);
  dynamic_reconfigure::DoubleParameter time;
  time.name = "clearing_time";
  time.value = 4.0;
  bad.request.config.doubles.push_back(time);
  ASSERT_TRUE(reconfigure(ours, bad));
  EXPECT_EQ(3, intIn(bad.response.config, "clearing_scans"));
  EXPECT_EQ(1.0, doubleIn(bad.response.config, "clearing_time"));
  EXPECT_EQ(1.5, doubleIn(bad.response.config, "trigger_radius"));
  costmap.updateMap(5.0, 5.0, 0.0);
  EXPECT_EQ(3u, layer->sharingParams().clearing_scans);
  EXPECT_EQ(1.0, layer->sharingParams().clearing_time);
  EXPECT_EQ(1.5, layer->sharingParams().trigger_radius);

  // The fleet robots' parameters too (FleetRobotParams::validate()).
  dynamic_reconfigure::Reconfigure timeout;
  dynamic_reconfigure::DoubleParameter negative;
  negative.name = "robot_timeout";
  negative.value = -1.0;
  timeout.request.config.doubles.push_back(negative);
  ASSERT_TRUE(reconfigure(ours, timeout));
  EXPECT_EQ(3.0, doubleIn(timeout.response.config, "robot_timeout"));
  negative.name = "robot_exclusion_margin";
  negative.value = 0.5;
  timeout.request.config.doubles = { negative };
  ASSERT_TRUE(reconfigure(ours, timeout));
  costmap.updateMap(5.0, 5.0, 0.0);
  EXPECT_EQ(3.0, layer->fleetRobotParams().timeout);
  EXPECT_EQ(0.5, layer->fleetRobotParams().margin);
}

int main(int argc, char** argv)
{
  ros::init(argc, argv, "plugin_layer_tests");
  testing::InitGoogleTest(&argc, argv);
  ros::NodeHandle nh;  // keeps the node up for every test
  return RUN_ALL_TESTS();
}
