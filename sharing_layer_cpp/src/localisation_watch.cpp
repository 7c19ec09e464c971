#include "sharing_layer/localisation_watch.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace sharing_layer
{
namespace
{
void checkNonNegative(double value, const char* name, const char* unit)
{
  if (!std::isfinite(value) || value < 0.0)
  {
    std::ostringstream out;
    out << name << " must be finite and >= 0 " << unit << ", got " << value;
    throw std::invalid_argument(out.str());
  }
}

double wrapAngle(double a)
{
  return std::atan2(std::sin(a), std::cos(a));
}

bool finite(const Pose2& p)
{
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.yaw);
}

/// The motion from a to b, in a's frame.
Pose2 motion(const Pose2& a, const Pose2& b)
{
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  const double dx = b.x - a.x, dy = b.y - a.y;
  return Pose2{ c * dx + s * dy, -s * dx + c * dy, wrapAngle(b.yaw - a.yaw) };
}
}  // namespace

void LocalisationLimits::validate() const
{
  checkNonNegative(max_speed, "max_correction_speed", "m/s");
  checkNonNegative(max_turn, "max_correction_turn", "rad/s");
  if (!std::isfinite(window) || window <= 0.0)
  {
    std::ostringstream out;
    out << "correction_window must be finite and > 0 s, got " << window;
    throw std::invalid_argument(out.str());
  }
}

LocalisationWatch::LocalisationWatch(const LocalisationLimits& limits)
{
  setLimits(limits);
}

void LocalisationWatch::setLimits(const LocalisationLimits& limits)
{
  limits.validate();
  limits_ = limits;
  measure();
}

void LocalisationWatch::clear()
{
  has_last_ = false;
  steps_.clear();
  speed_ = turn_rate_ = 0.0;
}

void LocalisationWatch::add(double t_s, const Pose2& in_global, const Pose2& in_odom)
{
  if (!std::isfinite(t_s) || !finite(in_global) || !finite(in_odom) || (has_last_ && t_s <= last_t_))
  {
    return;  // a broken transform, or tf's latest again: nothing new about the two
  }
  if (has_last_)
  {
    const Pose2 by_global = motion(last_global_, in_global);
    const Pose2 by_odom = motion(last_odom_, in_odom);
    steps_.push_back(Step{ t_s, std::hypot(by_global.x - by_odom.x, by_global.y - by_odom.y),
                           std::fabs(wrapAngle(by_global.yaw - by_odom.yaw)) });
  }
  has_last_ = true;
  last_t_ = t_s;
  last_global_ = in_global;
  last_odom_ = in_odom;
  measure();
}

void LocalisationWatch::measure()
{
  while (!steps_.empty() && steps_.front().t <= last_t_ - limits_.window)
  {
    steps_.pop_front();
  }
  double distance = 0.0, angle = 0.0;
  for (const Step& step : steps_)
  {
    distance += step.distance;
    angle += step.angle;
  }
  // Per whole window, also while the steps span less of it: one jump counts as that much per window.
  speed_ = distance / limits_.window;
  turn_rate_ = angle / limits_.window;
}

bool LocalisationWatch::steady() const
{
  return (limits_.max_speed <= 0.0 || speed_ <= limits_.max_speed) &&
         (limits_.max_turn <= 0.0 || turn_rate_ <= limits_.max_turn);
}

}  // namespace sharing_layer
