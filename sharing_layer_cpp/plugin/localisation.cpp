// The layer's check of odometry against localisation (sharing_layer/localisation_watch.h says why): members of
// SharingLayer that read tf, kept apart from the cycle so that each file reads as one concern.
#include "sharing_layer.h"

#include <cstdio>

#include <tf2/LinearMath/Matrix3x3.h>
#include <tf2/LinearMath/Quaternion.h>
#include <tf2/exceptions.h>

namespace sharing_layer
{
namespace
{
Pose2 toPose(const geometry_msgs::TransformStamped& t)
{
  const geometry_msgs::Quaternion& q = t.transform.rotation;
  double roll = 0.0, pitch = 0.0, yaw = 0.0;
  tf2::Matrix3x3(tf2::Quaternion(q.x, q.y, q.z, q.w)).getRPY(roll, pitch, yaw);
  return Pose2{ t.transform.translation.x, t.transform.translation.y, yaw };
}
}  // namespace

bool SharingLayer::findOdometryFrame()
{
  // The frame just below the global frame on the way up from the robot: what the localisation corrects (odom).
  std::string child = robot_base_frame_, parent;
  for (int depth = 0; depth < 32; ++depth)
  {
    if (!tf_->_getParent(child, ros::Time(0), parent))
    {
      return false;  // not in tf (yet)
    }
    if (parent == global_frame_)
    {
      odometry_frame_none_ = child == robot_base_frame_;
      odometry_frame_ = child;
      ROS_INFO("SharingLayer (%s): %s", params_.robot_name.c_str(),
               odometry_frame_none_ ? ("the robot frame " + robot_base_frame_ + " hangs straight from " +
                                       global_frame_ + ": no odometry to compare the localisation with").c_str() :
                                      ("comparing the odometry (" + odometry_frame_ + ") with the localisation (" +
                                       global_frame_ + "): nothing is shared while they disagree").c_str());
      return true;
    }
    child = parent;
  }
  return false;
}

void SharingLayer::watchLocalisation()
{
  if (rolling_window_ || odometry_frame_none_ || (odometry_frame_.empty() && !findOdometryFrame()) ||
      odometry_frame_none_)
  {
    return;
  }
  geometry_msgs::TransformStamped in_global, in_odom;
  try
  {
    in_global = tf_->lookupTransform(global_frame_, robot_base_frame_, ros::Time(0));
    in_odom = tf_->lookupTransform(odometry_frame_, robot_base_frame_, in_global.header.stamp);
  }
  catch (const tf2::TransformException& e)
  {
    ROS_WARN_THROTTLE(10.0, "SharingLayer (%s): cannot compare the odometry with the localisation: %s",
                      params_.robot_name.c_str(), e.what());
    return;
  }
  std::lock_guard<std::mutex> lock(core_mutex_);
  localisation_watch_.add(in_global.header.stamp.toSec(), toPose(in_global), toPose(in_odom));
  const bool steady = localisation_watch_.steady();
  const LocalisationLimits& limits = localisation_watch_.limits();
  if (!steady && localisation_steady_)
  {
    ++disagreements_;
    ROS_WARN("SharingLayer (%s): odometry (%s) and localisation (%s) disagree on the robot's motion by %.2f m/s and "
             "%.2f rad/s over %.1f s (limits %.2f m/s, %.2f rad/s: max_correction_speed, max_correction_turn): "
             "nothing is shared until they agree again (wheels slipping or spinning against an obstacle, or the "
             "localisation jumping)",
             params_.robot_name.c_str(), odometry_frame_.c_str(), global_frame_.c_str(), localisation_watch_.speed(),
             localisation_watch_.turnRate(), limits.window, limits.max_speed, limits.max_turn);
  }
  else if (steady && !localisation_steady_)
  {
    ROS_INFO("SharingLayer (%s): odometry and localisation agree again; sharing resumes (%zu monitoring updates and "
             "%zu triggers withheld so far)",
             params_.robot_name.c_str(), updates_withheld_, triggers_withheld_);
  }
  localisation_steady_ = steady;
}

bool SharingLayer::localisationAgrees()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return localisation_steady_;
}

std::size_t SharingLayer::updatesWithheld()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return updates_withheld_;
}

std::size_t SharingLayer::sharedObstacleCount()
{
  std::lock_guard<std::mutex> lock(core_mutex_);
  return core_ ? core_->sharedObstacles().size() : 0;
}

void SharingLayer::diagnoseLocalisation(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  using diagnostic_msgs::DiagnosticStatus;
  if (odometry_frame_none_ || odometry_frame_.empty())
  {
    status.add("odometry against localisation", odometry_frame_none_ ? "no odometry frame" : "waiting for tf");
    return;
  }
  char text[160];
  std::snprintf(text, sizeof(text), "%s: %.3f m/s, %.3f rad/s apart over %.1f s", odometry_frame_.c_str(),
                localisation_watch_.speed(), localisation_watch_.turnRate(), localisation_watch_.limits().window);
  status.add("odometry against localisation", text);
  status.add("times they disagreed", disagreements_);
  status.add("monitoring updates withheld", updates_withheld_);
  status.add("triggers withheld", triggers_withheld_);
  if (!localisation_steady_)
  {
    status.mergeSummary(DiagnosticStatus::WARN, "odometry and localisation disagree: nothing shared from what the "
                                                "robot sees now (check wheel slip, odometry and the localisation)");
  }
}

}  // namespace sharing_layer
