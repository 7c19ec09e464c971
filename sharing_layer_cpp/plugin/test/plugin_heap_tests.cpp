// What the plugin holds on the heap beyond costmap_2d's ObstacleLayer, per cell (issues 29, 48): measured as
// bench_plugin_cycle measures it (mallinfo2 around building, feeding and warming up each costmap on the reference
// warehouse, 2000 x 2000 cells, with the map's unknown cells, a plan, 10 fleet robots and 100 shared obstacles), and
// as the layer counts it (SharingLayer::perCellBytes). Both stay within a byte per cell, as the grids' equality with
// ObstacleLayer and the writes inside the update window stay (plugin_layer.test). Needs a ROS master: plugin_heap.test.
#include <gtest/gtest.h>

#include <string>

#include <ros/ros.h>

#include "../bench/bench_fixture.h"

using namespace sharing_layer::bench;

TEST(PluginHeap, TheLayerHoldsAtMostAByteACellBeyondObstacleLayerWithAHundredObstaclesShared)
{
  ros::NodeHandle nh;
  Stage stage(nh);
  const double cells = static_cast<double>(stage.scene.geometry.cellCount());
  setSource("upstream", 30.0, 30.0);
  setSource("ours", 30.0, 30.0);
  const double heap0 = heapBytes();
  Subject<costmap_2d::ObstacleLayer> upstream(stage.master_map, "upstream", stage.tf, stage.scene.geometry);
  warmUp(stage, upstream);
  const double heap1 = heapBytes();
  Subject<sharing_layer::SharingLayer> ours(stage.master_map, "ours", stage.tf, stage.scene.geometry);
  ASSERT_EQ("", warmUp(stage, nh, ours, true));
  const double heap2 = heapBytes();
  const double beyond = ((heap2 - heap1) - (heap1 - heap0)) / cells;
  const double counted = static_cast<double>(ours.layer->perCellBytes()) / cells;
  RecordProperty("heap_beyond_obstacle_layer_bytes_per_cell", std::to_string(beyond));
  EXPECT_LE(beyond, 1.0) << "heap beyond ObstacleLayer";
  EXPECT_LE(counted, 1.0) << "what the layer counts";
  EXPECT_GT(counted, 0.0);
  EXPECT_LE(counted, beyond) << "the count leaves out what is not per cell, never more";
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "plugin_heap_tests");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
