#ifndef SHARING_LAYER_PLUGIN_SHARING_LAYER_H
#define SHARING_LAYER_PLUGIN_SHARING_LAYER_H

#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <actionlib_msgs/GoalStatusArray.h>
#include <boost/thread/recursive_mutex.hpp>
#include <costmap_2d/obstacle_layer.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <nav_msgs/OccupancyGrid.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <sharing_msgs/RobotFootprintArray.h>
#include <sharing_msgs/SharedObstacle.h>
#include <std_msgs/Empty.h>
#include <std_msgs/String.h>
#include <topic_tools/shape_shifter.h>

#include <sharing_layer_cpp/SharingLayerConfig.h>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/localisation_watch.h"
#include "sharing_layer/sharing_core.h"
#include "layer_config.h"

namespace sharing_layer
{
/**
 * @brief costmap_2d plugin: an ObstacleLayer whose marking, clearing, proposals and monitoring are done by
 * the ROS-free SharingCore. This class only reads parameters, converts messages and calls the core.
 *
 * Topics (in the robot's namespace): subscribes stuck_feedback (std_msgs/Empty),
 * move_base/recovery_status (any type: each message counts as a stuck signal), shared_obstacles
 * (sharing_msgs/SharedObstacle), expired_obstacles (std_msgs/String), the global plan (nav_msgs/Path,
 * ~plan_topics, default <this node>/NavfnROS/plan and <this node>/GlobalPlanner/plan) for the plan-blocked
 * trigger while move_base/status has an active goal, the a-priori map (nav_msgs/OccupancyGrid, ~map_topic, default map) for its unknown cells, and
 * the fleet robots its Coaty bridge hears (sharing_msgs/RobotFootprintArray, ~fleet_robots_topic, default
 * fleet_robots), whose footprints plus ~robot_exclusion_margin are never shared;
 * publishes obstacle_proposals and obstacle_updates (sharing_msgs/SharedObstacle). Every trigger is logged
 * once at INFO with its source and what it proposed, or why nothing.
 *
 * /diagnostics (1 Hz): one status "sharing_layer: <robot_name> (<layer name>)" with the observation sources, the plan
 * trigger, the a-priori map, and counts of proposals and updates published, shared obstacles held and fleet messages
 * rejected; the set-up's warnings are there with their reason. dynamic_reconfigure: the sharing parameters
 * (SharingLayer.cfg) in <layer name>/sharing (the layer's own namespace has ObstacleLayer's server), checked with
 * LayerParams::validate() and applied at the next updateBounds.
 */
class SharingLayer : public costmap_2d::ObstacleLayer
{
public:
  SharingLayer() = default;
  ~SharingLayer() override = default;

  void onInitialize() override;
  void updateBounds(double robot_x, double robot_y, double robot_yaw, double* min_x, double* min_y, double* max_x,
                    double* max_y) override;
  void updateCosts(costmap_2d::Costmap2D& master_grid, int min_i, int min_j, int max_i, int max_j) override;
  void reset() override;
  void matchSize() override;
  void onFootprintChanged() override;
  /// @brief What clear_costmap_recovery calls (CostmapLayer::clearArea): the layer's own obstacle marks outside
  /// the window (or inside it, with invert_area) are cleared, and stop being this robot's candidates; shared
  /// obstacles stay.
  void clearArea(int start_x, int start_y, int end_x, int end_y, bool invert_area = false) override;
  /// @brief Whether the core clears and marks this layer's own costmap_ (one obstacle grid; false only while the
  /// two sizes differ, when the core keeps its own and the window is copied in updateCosts).
  bool sharesGridWithCore();
  /// @brief The sharing parameters in use: the core's (its last cycle's), or the layer's before the core exists.
  LayerParams sharingParams();
  /// @brief robot_exclusion_margin, robot_timeout and robot_exclusion_trail in use.
  FleetRobotParams fleetRobotParams();
  /// @brief Whether the layer left "waiting for the map" (/diagnostics' "map received": the static layer's map read
  /// from the master) and, when a map_topic is set, a map arrived on it.
  bool mapReceived();
  /// @brief Poses of the plan the plan trigger follows (0: none).
  std::size_t planPoses();
  /// @brief Shared obstacles the core holds (0 before the core exists).
  std::size_t sharedObstacleCount();
  /// @brief Whether odometry and localisation agree (localisation_watch.h): sharing goes on only then.
  bool localisationAgrees();
  /// @brief Monitoring updates not sent because odometry and localisation disagreed.
  std::size_t updatesWithheld();
  /// @brief Bytes the layer keeps per grid cell besides ObstacleLayer's grid, summed over the grid: the core's
  /// (SharingCore::perCellBytes) and the a-priori map's unknown cells it keeps to hand to a new or moved core.
  std::size_t perCellBytes();

private:
  void stuckCallback(const std_msgs::Empty::ConstPtr& msg);
  void recoveryCallback(const ros::MessageEvent<topic_tools::ShapeShifter const>& event);
  void sharedCallback(const sharing_msgs::SharedObstacle::ConstPtr& msg);
  void expiredCallback(const std_msgs::String::ConstPtr& msg);
  void planCallback(const nav_msgs::Path::ConstPtr& msg);
  /// @brief WARN (throttled) and count when no pose of the plan lies within kLocalPlannerPlanReach of the robot
  void warnPlanOutOfReach(const std::vector<std::pair<double, double>>& poses);
  void mapCallback(const nav_msgs::OccupancyGrid::ConstPtr& msg);
  void fleetRobotsCallback(const sharing_msgs::RobotFootprintArray::ConstPtr& msg);
  /// @brief move_base's action status: the plan trigger follows the global plan only while a goal is active
  /// (navfn also publishes the plans of make_plan service calls on the same topic).
  void goalStatusCallback(const actionlib_msgs::GoalStatusArray::ConstPtr& msg);
  /// @brief The WARNs and ERRORs of a set-up that shares nothing or less than expected: observation sources taken
  /// from the costmap's namespace (`adopted`), none at all, a rolling window.
  void warnAboutSetup(const std::vector<std::string>& adopted, const std::string& private_namespace);
  /// @brief Advertises and subscribes the layer's topics (onInitialize, after the parameters were read).
  void wireTopics(const LayerConfig& config);
  /// @brief WARN once when no plan topic has a publisher: the plan trigger would be silently off.
  void checkPlanPublishers(const ros::TimerEvent&);
  /// @brief Hands the last fleet_robots message to the core, in the global frame; core_mutex_ held.
  void applyFleetRobots();
  /// @brief Whether costmap_ has the size of g (then the core can use it as its obstacle grid on g).
  bool gridMatches(const GridGeometry& g) const;
  /// @brief Hands costmap_ to the core as its obstacle grid; core_mutex_ held.
  void shareGridWithCore();
  /// @brief core_->moveTo onto costmap_ as ObstacleLayer left it, or onto a grid of the core's own if the sizes
  /// differ; core_mutex_ held.
  MoveReport moveCore(const GridGeometry& geometry, bool keep_observations);
  /// @brief Publishes a trigger's proposals and logs it; call with core_mutex_ held.
  void handleTrigger(const TriggerReport& report, double now);
  /// @brief Hands the unknown cells of the last map to the core, in the master's geometry; core_mutex_ held.
  void applyUnknownMap();
  void rebuildCore();
  GridGeometry masterGeometry() const;
  /// @brief The /diagnostics status (diagnostic_updater task, 1 Hz timer): sources, plan trigger, map, counts.
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  /// @brief The plan trigger's and the map's part of diagnose; core_mutex_ held.
  void diagnosePlanAndMap(diagnostic_updater::DiagnosticStatusWrapper& status);
  /// @brief Starts the diagnostics and the dynamic_reconfigure server (onInitialize, after the parameters).
  void startDiagnosticsAndReconfigure(const ros::NodeHandle& private_nh);
  /// @brief dynamic_reconfigure's callback: the changed fields onto the parameters in use, validated; a bad value is
  /// refused (logged, `config` set back to the previous one). Accepted ones wait in pending_ for the next cycle.
  void reconfigure(sharing_layer_cpp::SharingLayerConfig& config, uint32_t level);
  /// @brief Applies the pending reconfiguration, if any; core_mutex_ held (updateBounds).
  void applyPendingReconfigure();

  LayerParams params_;
  std::unique_ptr<SharingCore> core_;
  std::mutex core_mutex_;
  bool stuck_pending_ = false;
  bool inscribed_from_footprint_ = true;  ///< ~inscribed_radius not set: follow the footprint
  TriggerSource stuck_source_ = TriggerSource::StuckFeedback;
  /// The last a-priori map's unknown (-1) cells, a bit per map cell, and where they lie (re-applied to a new or moved
  /// core). Not the message: its byte per cell stayed with the layer for the map's lifetime (issue 29).
  struct UnknownMap
  {
    nav_msgs::MapMetaData info;
    BitGrid unknown;
  };
  std::unique_ptr<UnknownMap> map_;
  FleetRobotParams fleet_params_;          ///< robot_exclusion_margin, robot_timeout, robot_exclusion_trail
  sharing_msgs::RobotFootprintArray::ConstPtr fleet_robots_;  ///< last fleet_robots, re-applied to a new core
  bool static_pending_ = false;  ///< the static map is read from the master at the next full update
  /// Scans processed while static_pending_: their cells were judged shareable without the static map
  /// (walls too), so they are replayed once it is read. At most kMaxPreStaticScans, the newest.
  std::deque<std::pair<Observation, ScanLimits>> pre_static_scans_;
  /// Moves the layer's and the core's grids with a rolling window (ObstacleLayer's updateOrigin).
  void followRollingWindow(double robot_x, double robot_y);
  /// This cycle's observations, each with its source's limits (ranges, marking, clearing), in ObstacleLayer's
  /// order as far as one pass per observation allows: clearing-only sources, then those that do both, then
  /// marking-only ones. @return false when a source is not current (ObstacleLayer's current_)
  struct SourceObservation
  {
    const costmap_2d::Observation* observation;  ///< in cycle_observations_ or ObstacleLayer's static ones
    ScanLimits limits;
    std::string source;  ///< its name in observation_sources, for logs
  };
  bool sourceObservations(std::vector<SourceObservation>& out);
  /// This cycle's observations, per buffer, filled in place (costmap_2d::Observation copies its whole cloud and has no
  /// move: each copy avoided is a cloud's allocation and copy per cycle).
  std::vector<std::vector<costmap_2d::Observation>> cycle_observations_;
  /// @brief One observation through the core: its monitoring updates published, the plan trigger checked, the
  /// bounds grown by what it touched; core_mutex_ held.
  void processObservation(const SourceObservation& source_observation, double now, double robot_x, double robot_y,
                          double* min_x, double* min_y, double* max_x, double* max_y);
  std::vector<std::string> source_names_;  ///< observation_sources, in the order of observation_buffers_
  static constexpr std::size_t kMaxPreStaticScans = 100;
  ros::Time stuck_stamp_;
  std::string global_frame_;
  // Odometry against localisation (localisation.cpp, core/localisation_watch.h): while they disagree the layer
  // marks and clears as ObstacleLayer does but proposes nothing and sends no monitoring update.
  void watchLocalisation();
  bool findOdometryFrame();
  void diagnoseLocalisation(diagnostic_updater::DiagnosticStatusWrapper& status);
  LocalisationWatch localisation_watch_;
  std::string robot_base_frame_;           ///< the costmap's robot_base_frame
  std::string odometry_frame_;             ///< the frame below global_frame_ on the way to it ("" until found)
  bool odometry_frame_none_ = false;       ///< the robot hangs straight from global_frame_: nothing to compare
  bool localisation_steady_ = true;
  std::size_t updates_withheld_ = 0;       ///< monitoring updates not sent while the two disagreed
  std::size_t triggers_withheld_ = 0;      ///< plan checks and stuck signals not acted on meanwhile
  std::size_t disagreements_ = 0;          ///< times they started to disagree
  ros::Publisher proposals_pub_;
  ros::Publisher updates_pub_;
  ros::Subscriber stuck_sub_;
  ros::Subscriber recovery_sub_;
  ros::Subscriber shared_sub_;
  ros::Subscriber expired_sub_;
  std::vector<ros::Subscriber> plan_subs_;
  std::vector<std::string> plan_topics_;
  ros::Subscriber goal_status_sub_;
  ros::Timer plan_publisher_check_;
  bool goal_active_ = true;  ///< until move_base's status says otherwise (none heard: follow every plan)
  ros::Subscriber map_sub_;
  ros::Subscriber fleet_robots_sub_;

  // What /diagnostics reports (core_mutex_).
  std::vector<std::string> adopted_;        ///< parameters taken from the costmap's namespace
  std::string private_namespace_;           ///< the layer's parameter namespace, for the reasons
  std::string map_topic_;                   ///< "" or "none": no a-priori map topic
  bool map_seen_ = false;                   ///< a valid map arrived on map_topic_
  bool static_seen_ = false;                ///< the static layer's map was read at least once
  bool sources_current_ = true;             ///< ObstacleLayer's current_ at the last cycle
  unsigned long plans_received_ = 0;
  unsigned long plans_out_of_reach_ = 0;    ///< plans with no pose within kLocalPlannerPlanReach of the robot
  bool have_robot_pose_ = false;            ///< robot_x_, robot_y_: the pose of the last updateBounds
  double robot_x_ = 0.0;
  double robot_y_ = 0.0;
  ros::Time last_plan_;
  unsigned long proposals_published_ = 0;
  unsigned long updates_published_ = 0;
  unsigned long fleet_rejected_ = 0;        ///< shared obstacles ignored (before the map, bad, refused by the core)
  unsigned long fleet_applied_ = 0;         ///< shared obstacles and expiries applied (the benches count on it)
  std::string last_rejection_;
  std::string last_refusal_;                ///< the last refused reconfiguration, with its reason
  // dynamic_reconfigure: accepted values wait here for the next updateBounds (core_mutex_).
  struct PendingReconfigure
  {
    LayerParams params;
    FleetRobotParams fleet;
    bool inscribed_set = false;  ///< inscribed_radius set: stop following the footprint
  };
  std::unique_ptr<PendingReconfigure> pending_;
  // Declared last: destroyed first, so that no callback of theirs runs on a half-destroyed layer.
  boost::recursive_mutex reconfigure_mutex_;           ///< the server's; guards reconfigure_config_ too
  sharing_layer_cpp::SharingLayerConfig reconfigure_config_;  ///< the last accepted configuration
  std::unique_ptr<dynamic_reconfigure::Server<sharing_layer_cpp::SharingLayerConfig>> reconfigure_server_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::Timer diagnostics_timer_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_PLUGIN_SHARING_LAYER_H
