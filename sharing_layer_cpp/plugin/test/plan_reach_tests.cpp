// The plugin's warning for a global plan the local planner cannot follow: a plan (received while move_base has a
// goal) that passes no nearer than the local planner's reach to the robot is counted in /diagnostics ("plans out
// of the local planner's reach") and logged. The gap itself is tested in test_triggers.cpp (PlanReach); this is the
// glue: the plan topic, the goal status and the robot pose from the costmap cycle. Needs a ROS master:
// plugin_plan_reach.test.
#include <gtest/gtest.h>

#include <string>
#include <utility>
#include <vector>

#include <actionlib_msgs/GoalStatusArray.h>
#include <costmap_2d/layered_costmap.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>

#include "../sharing_layer.h"
#include "diagnostics_listener.h"

namespace
{
using sharing_layer_test::countOf;
using sharing_layer_test::DiagnosticsListener;

/// A straight plan from (x0, y) to (x0 + 3, y) in the map frame.
nav_msgs::Path straightPlan(double x0, double y)
{
  nav_msgs::Path plan;
  plan.header.frame_id = "map";
  for (int i = 0; i <= 60; ++i)
  {
    geometry_msgs::PoseStamped pose;
    pose.header.frame_id = "map";
    pose.pose.position.x = x0 + 0.05 * i;
    pose.pose.position.y = y;
    pose.pose.orientation.w = 1.0;
    plan.poses.push_back(pose);
  }
  return plan;
}

actionlib_msgs::GoalStatusArray goalStatus(uint8_t status)
{
  actionlib_msgs::GoalStatusArray array;
  actionlib_msgs::GoalStatus goal;
  goal.goal_id.id = "goal-1";
  goal.status = status;
  array.status_list.push_back(goal);
  return array;
}
}  // namespace

TEST(PluginPlanReach, APlanBeyondTheLocalPlannersReachIsCountedOnlyWhileAGoalIsActive)
{
  ros::NodeHandle nh;
  const std::string layer_name = "reach";
  ros::param::set("~" + layer_name + "/observation_sources", std::string("scan"));
  ros::param::set("~" + layer_name + "/scan/topic", std::string("plan_reach_test_unused"));
  ros::param::set("~" + layer_name + "/scan/data_type", std::string("PointCloud2"));
  ros::param::set("~" + layer_name + "/robot_name", std::string("robot_0"));
  ros::param::set("~" + layer_name + "/map_topic", std::string("none"));
  ros::param::set("~" + layer_name + "/plan_topics", std::string("reach_plan"));
  ros::param::set("~" + layer_name + "/fleet_robots_topic", std::string("none"));

  tf2_ros::Buffer tf;
  tf.setUsingDedicatedThread(true);
  costmap_2d::LayeredCostmap costmap("map", false, false);
  auto* layer = new sharing_layer::SharingLayer();
  costmap.addPlugin(boost::shared_ptr<costmap_2d::Layer>(layer));
  layer->initialize(&costmap, layer_name, &tf);
  costmap.resizeMap(200, 200, 0.05, 0.0, 0.0);

  DiagnosticsListener diagnostics;
  const std::string name = "sharing_layer: robot_0 (" + layer_name + ")";
  ros::Publisher plans = nh.advertise<nav_msgs::Path>("reach_plan", 1);
  ros::Publisher status = nh.advertise<actionlib_msgs::GoalStatusArray>("move_base/status", 1);
  const auto counted = [&](long received, long out_of_reach) {
    return [&, received, out_of_reach](const diagnostic_msgs::DiagnosticStatus& s) {
      return countOf(s, "plans received") == received && countOf(s, "plans out of the local planner's reach") ==
                                                               out_of_reach;
    };
  };
  // A goal status and a plan go on two topics, whose callbacks may run in either order. This process's own
  // subscriber to move_base/status shares the layer's subscription: once it has run on a status, the layer's
  // callback on it has been queued too, ahead of any plan published after that.
  std::vector<uint8_t> heard;
  ros::Subscriber status_heard = nh.subscribe<actionlib_msgs::GoalStatusArray>(
      "move_base/status", 10,
      [&](const actionlib_msgs::GoalStatusArray::ConstPtr& msg) { heard.push_back(msg->status_list[0].status); });
  const auto cycle = [&] { costmap.updateMap(5.0, 5.0, 0.0); };  // the robot at (5, 5): the layer's pose
  ASSERT_TRUE(diagnostics.waitFor(name, counted(0, 0), cycle)) << diagnostics.describe(name);
  ASSERT_TRUE(diagnostics.waitFor(name, [&](const diagnostic_msgs::DiagnosticStatus&) {
    return plans.getNumSubscribers() > 0 && status.getNumSubscribers() > 0;
  })) << "the layer never subscribed to reach_plan and move_base/status";
  const auto applyStatus = [&](uint8_t goal) {
    const std::size_t before = heard.size();
    status.publish(goalStatus(goal));
    return diagnostics.waitFor(name, [&](const diagnostic_msgs::DiagnosticStatus&) { return heard.size() > before; });
  };

  ASSERT_TRUE(applyStatus(actionlib_msgs::GoalStatus::ACTIVE));
  plans.publish(straightPlan(5.95, 5.0));  // from 0.95 m ahead of the robot: within the reach
  EXPECT_TRUE(diagnostics.waitFor(name, counted(1, 0), cycle)) << diagnostics.describe(name);
  plans.publish(straightPlan(6.5, 5.0));  // from 1.5 m ahead (the bench's navfn plan began 1.37 m away): beyond it
  EXPECT_TRUE(diagnostics.waitFor(name, counted(2, 1), cycle)) << diagnostics.describe(name);
  // The goal ended: a plan then is a make_plan answer, not where the robot is going.
  ASSERT_TRUE(applyStatus(actionlib_msgs::GoalStatus::SUCCEEDED));
  plans.publish(straightPlan(6.5, 5.0));
  EXPECT_TRUE(diagnostics.waitFor(name, counted(3, 1), cycle)) << diagnostics.describe(name);
}

int main(int argc, char** argv)
{
  ros::init(argc, argv, "plan_reach_tests");
  testing::InitGoogleTest(&argc, argv);
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
