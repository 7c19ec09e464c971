// What fires the layer's triggers besides its sensors: move_base's stuck and recovery signals, its goal status and
// the global plan (with the warning for a plan the local planner will drop), and what a trigger's report becomes.
// Members of SharingLayer; the cycle itself is in sharing_layer.cpp.
#include "sharing_layer.h"

#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "messages.h"

namespace sharing_layer
{
void SharingLayer::stuckCallback(const std_msgs::Empty::ConstPtr&)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!stuck_pending_)
  {
    stuck_source_ = TriggerSource::StuckFeedback;
  }
  stuck_pending_ = true;
  stuck_stamp_ = ros::Time::now();
}

void SharingLayer::recoveryCallback(const ros::MessageEvent<topic_tools::ShapeShifter const>&)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (!stuck_pending_)
  {
    stuck_source_ = TriggerSource::RecoveryStatus;
  }
  stuck_pending_ = true;
  stuck_stamp_ = ros::Time::now();
}

void SharingLayer::goalStatusCallback(const actionlib_msgs::GoalStatusArray::ConstPtr& msg)
{
  bool active = false;
  for (const actionlib_msgs::GoalStatus& status : msg->status_list)
  {
    active |= status.status == actionlib_msgs::GoalStatus::PENDING ||
              status.status == actionlib_msgs::GoalStatus::ACTIVE ||
              status.status == actionlib_msgs::GoalStatus::PREEMPTING;
  }
  std::lock_guard<std::mutex> lock(core_mutex_);
  if (goal_active_ && !active && core_)
  {
    core_->setPlan({});  // the goal ended: its plan no longer says where the robot is going
  }
  goal_active_ = active;
}

void SharingLayer::checkPlanPublishers(const ros::TimerEvent&)
{
  for (const ros::Subscriber& sub : plan_subs_)
  {
    if (sub.getNumPublishers() > 0)
    {
      return;
    }
  }
  std::string topics;
  for (const std::string& topic : plan_topics_)
  {
    topics += (topics.empty() ? "" : " ") + topic;
  }
  ROS_WARN("SharingLayer %s (%s): nothing publishes the global plan on [%s] after 15 s: the plan-blocked trigger "
           "is off until something does (set ~%s/plan_topics to your planner's plan topic)",
           name_.c_str(), params_.robot_name.c_str(), topics.c_str(), name_.c_str());
}

void SharingLayer::planCallback(const nav_msgs::Path::ConstPtr& msg)
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  ++plans_received_;
  last_plan_ = ros::Time::now();
  if (!core_)
  {
    return;
  }
  if (!goal_active_)
  {
    return;  // a make_plan request while move_base has no goal: not where this robot is going
  }
  const std::string frame = msg->header.frame_id.empty() || msg->header.frame_id[0] != '/' ?
                                msg->header.frame_id :
                                msg->header.frame_id.substr(1);
  if (!msg->poses.empty() && !frame.empty() && frame != global_frame_)
  {
    ROS_WARN_THROTTLE(10.0, "SharingLayer (%s): ignoring a plan in frame %s; the plan trigger needs it in %s",
                      params_.robot_name.c_str(), frame.c_str(), global_frame_.c_str());
    return;
  }
  std::vector<std::pair<double, double>> poses;
  poses.reserve(msg->poses.size());
  for (const auto& pose : msg->poses)
  {
    poses.emplace_back(pose.pose.position.x, pose.pose.position.y);  // non-finite ones are dropped by the core
  }
  core_->setPlan(poses);
  warnPlanOutOfReach(poses);
}

void SharingLayer::warnPlanOutOfReach(const std::vector<std::pair<double, double>>& poses)
{
  if (!have_robot_pose_ || poses.empty())
  {
    return;
  }
  const double gap = nearestPlanDistance(poses, robot_x_, robot_y_);
  if (!outOfLocalPlannerReach(gap))
  {
    return;
  }
  ++plans_out_of_reach_;
  ROS_WARN_THROTTLE(30.0,
                    "SharingLayer (%s): the global plan (%zu poses, first at (%.2f, %.2f)) passes no nearer than "
                    "%.2f m to the robot at (%.2f, %.2f): move_base's local planner keeps a plan only from a pose "
                    "within %.1f m, so the robot will not move and move_base aborts (\"no valid control\"). NavfnROS "
                    "returns a route longer than twice the global costmap's width cut short like this, and a shared "
                    "obstacle can make the route that long: use global_planner/GlobalPlanner, or a global costmap at "
                    "least half as wide as the longest route [%lu such plans]",
                    params_.robot_name.c_str(), poses.size(), poses.front().first, poses.front().second, gap, robot_x_,
                    robot_y_, kLocalPlannerPlanReach, plans_out_of_reach_);
}

void SharingLayer::handleTrigger(const TriggerReport& report, double now)
{
  if (report.log)
  {
    ROS_INFO("SharingLayer (%s): %s [%s]", params_.robot_name.c_str(), report.message.c_str(),
             triggerReasonName(report.reason));
  }
  for (const Proposal& proposal : report.proposals)
  {
    ObstacleUpdate value;
    value.marked = proposal.cells;
    value.rectangle = proposal.rectangle;
    value.source = params_.robot_name;
    value.geometry = core_->geometry();
    value.stamp = now;
    proposals_pub_.publish(toMessage(value, global_frame_));
    ++proposals_published_;
  }
}
}  // namespace sharing_layer
