// The plugin beside costmap_2d's own ObstacleLayer (issue 13): both fed the same clouds through their real
// observation buffers, their grids must be byte-identical and their update bounds equal, for a source that marks
// and clears, for marking-only and clearing-only sources with their own ranges, and in a rolling window. Shared
// obstacles must keep their place in the world when the map is resized or moved, or the window rolls.
// Needs a ROS master (parameters, topics): plugin_layer.test.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <set>
#include <utility>
#include <string>
#include <vector>

#include <costmap_2d/cost_values.h>
#include <costmap_2d/layered_costmap.h>
#include <costmap_2d/obstacle_layer.h>
#include <costmap_2d/observation_buffer.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <sharing_msgs/SharedObstacle.h>
#include <tf2_ros/buffer.h>

#include "../sharing_layer.h"
#include "plugin_fixture.h"

namespace
{
using sharing_layer_test::costAt;
using sharing_layer_test::placeLaser;
using sharing_layer_test::ring;
using sharing_layer_test::setSources;
using sharing_layer_test::shareBlockAt3m;
using sharing_layer_test::Source;
using FedObstacleLayer = sharing_layer_test::Fed<costmap_2d::ObstacleLayer>;
using FedSharingLayer = sharing_layer_test::Fed<sharing_layer::SharingLayer>;

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

int main(int argc, char** argv)
{
  ros::init(argc, argv, "plugin_layer_tests");
  testing::InitGoogleTest(&argc, argv);
  ros::NodeHandle nh;  // keeps the node up for every test
  return RUN_ALL_TESTS();
}
