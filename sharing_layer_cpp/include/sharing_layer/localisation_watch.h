#ifndef SHARING_LAYER_LOCALISATION_WATCH_H
#define SHARING_LAYER_LOCALISATION_WATCH_H

#include <deque>

namespace sharing_layer
{
/// @brief How much odometry and localisation may disagree before the layer stops sharing what it sees.
struct LocalisationLimits
{
  double max_speed = 0.25;  ///< m/s the two may disagree on the robot's motion; 0: not checked
  double max_turn = 0.25;   ///< rad/s the two may disagree on its turning; 0: not checked
  double window = 1.0;      ///< s over which the disagreement is summed (and after which it is forgotten)

  /// @throws std::invalid_argument naming the parameter (max_correction_speed, max_correction_turn,
  /// correction_window) and its value
  void validate() const;
};

/// @brief A planar pose: x, y in m, yaw in rad.
struct Pose2
{
  double x, y, yaw;
};

/**
 * @brief Says whether the robot's odometry and its localisation agree on how it moves.
 *
 * Fed, once per cycle, the robot's pose in the costmap's global frame (map: the localisation's word) and in the
 * odometry frame (odom) at the same time. Between two samples each gives a motion of the robot in its own frame;
 * while they agree the two are the same but for the localisation's small corrections (AMCL's steps, a simulator's
 * one step of lag when a turn starts). When the wheels slip, or spin against a wall while the localisation holds the
 * robot (Stage integrates the commanded motion into the odometry of a stalled robot), or the localisation jumps,
 * they differ: a scan transformed through the map then lands where it was not taken, and its marks lie in free
 * space. The layer then keeps marking and clearing as ObstacleLayer does, but proposes nothing and sends no
 * monitoring update from it.
 *
 * The disagreement is measured in the robot's frame, so it does not depend on how far the robot is from the map's
 * origin, and summed over the window (path length, not net: a disagreement that goes back and forth counts).
 * Pure: time is an argument.
 */
class LocalisationWatch
{
public:
  explicit LocalisationWatch(const LocalisationLimits& limits = LocalisationLimits());

  /// @brief The robot's pose by the localisation (global frame) and by the odometry at time t_s. Samples with a
  /// value that is not finite, or not newer than the last, are ignored.
  void add(double t_s, const Pose2& in_global, const Pose2& in_odom);
  /// @brief Whether odometry and localisation agreed within the limits over the window ending at the last sample
  /// (true before two samples).
  bool steady() const;
  /// @brief Their disagreement over the window, in m/s and rad/s (for diagnostics).
  double speed() const { return speed_; }
  double turnRate() const { return turn_rate_; }
  void setLimits(const LocalisationLimits& limits);
  const LocalisationLimits& limits() const { return limits_; }
  /// @brief Forgets every sample (a reset, a jump of the robot that is no motion).
  void clear();

private:
  struct Step
  {
    double t;             ///< time of the later sample
    double distance;      ///< m the two motions differ by
    double angle;         ///< rad they differ by
  };
  void measure();

  LocalisationLimits limits_;
  bool has_last_ = false;
  double last_t_ = 0.0;
  Pose2 last_global_{ 0.0, 0.0, 0.0 }, last_odom_{ 0.0, 0.0, 0.0 };
  std::deque<Step> steps_;
  double speed_ = 0.0;
  double turn_rate_ = 0.0;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_LOCALISATION_WATCH_H
