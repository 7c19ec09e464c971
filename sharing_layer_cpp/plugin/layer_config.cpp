#include "layer_config.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

namespace sharing_layer
{
namespace
{
/// The core's parameters as costmap_2d's ObstacleLayer and the project name them.
void readCoreParams(const ros::NodeHandle& nh, LayerParams& p, std::string& strategy)
{
  nh.param("obstacle_range", p.limits.obstacle_range, 2.5);
  nh.param("raytrace_range", p.limits.raytrace_range, 3.0);
  nh.param("min_obstacle_height", p.limits.min_obstacle_height, 0.0);
  nh.param("max_obstacle_height", p.limits.max_obstacle_height, 2.0);
  nh.param("static_tolerance", p.static_tolerance, 3);
  int occupied = 254;
  nh.param("static_occupied_cost", occupied, 254);
  p.static_occupied_cost = static_cast<std::uint8_t>(std::min(255, std::max(1, occupied)));
  nh.param("proposal_strategy", strategy, std::string("sectors"));
  nh.param("trigger_debounce", p.trigger_debounce, 2.0);
  int gap = 1, min_cells = 1, max_cells = 1000000;
  nh.param("cluster_gap", gap, 1);
  nh.param("min_cluster_cells", min_cells, 1);
  nh.param("max_update_cells", max_cells, 1000000);
  p.cluster_gap = static_cast<unsigned int>(std::max(0, gap));
  p.min_cluster_cells = static_cast<std::size_t>(std::max(0, min_cells));
  p.max_update_cells = static_cast<std::size_t>(std::max(0, max_cells));
  nh.param("rectangle_padding", p.rectangle_padding, 0.0);
  // Evidence-based clearing, trigger memory, plan-blocked trigger.
  nh.param("clearing_margin", p.clearing_margin, 0.1);
  int clearing_scans = 3, clearing_neighbours = 8;
  nh.param("clearing_scans", clearing_scans, 3);
  nh.param("clearing_neighbours", clearing_neighbours, 8);
  // Negative values stay out of range after the cast (validate() names them), instead of wrapping.
  p.clearing_scans = clearing_scans < 0 ? 0u : static_cast<unsigned int>(clearing_scans);
  p.clearing_neighbours = clearing_neighbours < 0 ? 100000u : static_cast<unsigned int>(clearing_neighbours);
  nh.param("clearing_time", p.clearing_time, 1.0);
  nh.param("trigger_memory", p.trigger_memory, 30.0);
  nh.param("trigger_radius", p.trigger_radius, 4.0);
  nh.param("memory_on_stuck_feedback", p.memory_on_stuck_feedback, false);
  nh.param("lease_renewal_interval", p.lease_renewal_interval, 5.0);
}
}  // namespace

void readLayerConfig(const ros::NodeHandle& nh, double footprint_inscribed, const std::string& node,
                     const std::string& robot_namespace, LayerConfig& c)
{
  c = LayerConfig();
  std::string own_sources;
  nh.param("observation_sources", own_sources, std::string(""));
  std::istringstream source_names(own_sources);
  for (std::string name; source_names >> name;)
  {
    c.source_names.push_back(name);
  }
  std::string strategy;
  readCoreParams(nh, c.params, strategy);
  // The robot's inscribed radius from its footprint (onFootprintChanged) unless set here.
  c.inscribed_from_footprint = !nh.hasParam("inscribed_radius");
  nh.param("inscribed_radius", c.params.inscribed_radius, footprint_inscribed > 0.0 ? footprint_inscribed : 0.25);
  // The layer runs inside move_base: its global planner publishes under this node's name, whatever it is (the
  // tutorials' launch names it move_base_node).
  nh.param("plan_topics", c.plan_topics, node + "/NavfnROS/plan " + node + "/GlobalPlanner/plan");
  nh.param("map_topic", c.map_topic, std::string("map"));
  std::string robot_name = robot_namespace;
  robot_name.erase(std::remove(robot_name.begin(), robot_name.end(), '/'), robot_name.end());
  nh.param("robot_name", c.params.robot_name, robot_name.empty() ? std::string("robot") : robot_name);
  // Fleet robots are never shared.
  nh.param("robot_exclusion_margin", c.fleet.margin, 0.2);
  nh.param("robot_timeout", c.fleet.timeout, 3.0);
  nh.param("robot_exclusion_trail", c.fleet.trail, 1.0);
  nh.param("fleet_robots_topic", c.fleet_robots_topic, std::string("fleet_robots"));
  // Odometry against localisation: how much they may disagree before nothing is shared.
  nh.param("max_correction_speed", c.localisation.max_speed, 0.25);
  nh.param("max_correction_turn", c.localisation.max_turn, 0.25);
  nh.param("correction_window", c.localisation.window, 1.0);
  c.params.strategy = parseProposalStrategy(strategy);
  c.params.validate();
  c.fleet.validate();
  c.localisation.validate();
}

std::vector<std::string> adoptParentObservationSources(const std::string& layer_name)
{
  // layer_name is "<costmap>/<layer>" (e.g. global_costmap/sharing_layer): the costmap's namespace is its parent.
  const std::size_t slash = layer_name.rfind('/');
  ros::NodeHandle private_nh("~/" + layer_name),
      parent_nh(slash == std::string::npos ? "~" : "~/" + layer_name.substr(0, slash));
  std::vector<std::string> copied;
  std::string sources;
  if (private_nh.hasParam("observation_sources") || !parent_nh.getParam("observation_sources", sources))
  {
    return copied;
  }
  private_nh.setParam("observation_sources", sources);
  copied.push_back("observation_sources");
  std::istringstream names(sources);
  for (std::string source; names >> source;)
  {
    XmlRpc::XmlRpcValue dict;
    if (!private_nh.hasParam(source) && parent_nh.getParam(source, dict))
    {
      private_nh.setParam(source, dict);
      copied.push_back(source);
    }
  }
  for (const char* key : { "obstacle_range", "raytrace_range", "max_obstacle_height", "min_obstacle_height" })
  {
    XmlRpc::XmlRpcValue value;
    if (!private_nh.hasParam(key) && parent_nh.getParam(key, value))
    {
      private_nh.setParam(key, value);
      copied.push_back(key);
    }
  }
  return copied;
}

}  // namespace sharing_layer
