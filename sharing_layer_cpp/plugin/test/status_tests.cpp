// The plugin's run-time face (issue 28): /diagnostics names a missing observation source, reports the map and
// counts obstacles and proposals; dynamic_reconfigure applies at the next cycle and refuses a bad value.
// Needs a ROS master: plugin_status.test.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <future>
#include <string>
#include <vector>

#include <costmap_2d/layered_costmap.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <nav_msgs/OccupancyGrid.h>
#include <ros/ros.h>
#include <sharing_msgs/SharedObstacle.h>
#include <std_msgs/Empty.h>
#include <tf2_ros/buffer.h>

#include "../sharing_layer.h"
#include "diagnostics_listener.h"
#include "plugin_fixture.h"
namespace
{
using sharing_layer_test::placeLaser;
using sharing_layer_test::ring;
using sharing_layer_test::setSources;
using sharing_layer_test::shareBlockAt3m;
using sharing_layer_test::Source;
using FedSharingLayer = sharing_layer_test::Fed<sharing_layer::SharingLayer>;
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
  negative.name = "robot_exclusion_trail";
  negative.value = sharing_layer::kMaxTrail + 0.5;
  timeout.request.config.doubles = { negative };
  ASSERT_TRUE(reconfigure(ours, timeout));
  EXPECT_EQ(1.0, doubleIn(timeout.response.config, "robot_exclusion_trail")) << "refused: longer than kMaxTrail";
  negative.value = 0.5;
  timeout.request.config.doubles = { negative };
  ASSERT_TRUE(reconfigure(ours, timeout));
  costmap.updateMap(5.0, 5.0, 0.0);
  EXPECT_EQ(0.5, layer->fleetRobotParams().trail);
}

int main(int argc, char** argv)
{
  ros::init(argc, argv, "plugin_status_tests");
  testing::InitGoogleTest(&argc, argv);
  ros::NodeHandle nh;  // keeps the node up for every test
  return RUN_ALL_TESTS();
}
