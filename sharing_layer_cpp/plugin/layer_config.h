#ifndef SHARING_LAYER_PLUGIN_LAYER_CONFIG_H
#define SHARING_LAYER_PLUGIN_LAYER_CONFIG_H

#include <string>
#include <vector>

#include <ros/ros.h>

#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/layer_params.h"
#include "sharing_layer/localisation_watch.h"

namespace sharing_layer
{
/// @brief Everything the plugin reads from the parameter server at onInitialize, checked, before any topic is wired.
struct LayerConfig
{
  LayerParams params;                ///< the core's parameters (ranges, triggers, evidence, leases)
  FleetRobotParams fleet;            ///< robot_exclusion_margin, robot_timeout, robot_exclusion_trail
  LocalisationLimits localisation;   ///< max_correction_speed, max_correction_turn, correction_window
  bool inscribed_from_footprint = true;  ///< ~inscribed_radius not set: follow the footprint
  std::string plan_topics;           ///< space-separated; "none" or empty switches the plan trigger off
  std::string map_topic;             ///< the a-priori map, for its unknown cells
  std::string fleet_robots_topic;    ///< the footprints the bridge hears
  std::vector<std::string> source_names;  ///< observation_sources, in the order ObstacleLayer makes its buffers
};

/**
 * @brief Reads the layer's parameters from its private namespace, with costmap_2d's and the project's defaults.
 * @param footprint_inscribed the costmap's inscribed radius (0: none known), the default of ~inscribed_radius
 * @param node this node's name (move_base's global planners publish their plans under it)
 * @param robot_namespace the node's namespace, the default robot_name
 * @throws std::invalid_argument naming the parameter and its value; `config` then holds what was read (its
 * robot_name, for the log)
 */
void readLayerConfig(const ros::NodeHandle& private_nh, double footprint_inscribed, const std::string& node,
                     const std::string& robot_namespace, LayerConfig& config);

/**
 * @brief With the tutorials' pre-Hydro files the observation sources sit in the costmap's namespace, and
 * costmap_2d copies them only into a plugin of type costmap_2d::ObstacleLayer: copies them into the layer's
 * namespace (layer_name: "<costmap>/<layer>") so that the layer is not blind. Call before ObstacleLayer reads them.
 * @return the names copied (empty when the layer has its own)
 */
std::vector<std::string> adoptParentObservationSources(const std::string& layer_name);

}  // namespace sharing_layer

#endif  // SHARING_LAYER_PLUGIN_LAYER_CONFIG_H
