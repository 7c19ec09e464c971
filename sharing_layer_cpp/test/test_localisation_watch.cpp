// LocalisationWatch: when odometry and localisation disagree on the robot's motion, nothing is shared from it.
#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

#include "sharing_layer/localisation_watch.h"

using sharing_layer::LocalisationLimits;
using sharing_layer::LocalisationWatch;
using sharing_layer::Pose2;

namespace
{
/// A pose turned by `turn` rad about its own position: a robot turning in place.
Pose2 turned(const Pose2& p, double turn)
{
  return Pose2{ p.x, p.y, p.yaw + turn };
}

/// The map pose of a robot whose odometry frame sits at `offset` in the map.
Pose2 inMap(const Pose2& offset, const Pose2& odom)
{
  const double c = std::cos(offset.yaw), s = std::sin(offset.yaw);
  return Pose2{ offset.x + c * odom.x - s * odom.y, offset.y + s * odom.x + c * odom.y, offset.yaw + odom.yaw };
}

/// Feeds `seconds` of samples every 0.1 s of a robot turning at `true_rate` while its odometry says `odom_rate`.
void turn(LocalisationWatch& watch, double& t, Pose2& map_pose, Pose2& odom_pose, double true_rate, double odom_rate,
          double seconds)
{
  for (int i = 0; i < static_cast<int>(std::lround(seconds / 0.1)); ++i)
  {
    t += 0.1;
    map_pose = turned(map_pose, true_rate * 0.1);
    odom_pose = turned(odom_pose, odom_rate * 0.1);
    watch.add(t, map_pose, odom_pose);
  }
}
}  // namespace

TEST(LocalisationWatch, AgreeingOdometryAndLocalisationAreSteadyFarFromTheMapOrigin)
{
  LocalisationWatch watch;
  const Pose2 offset{ 120.0, -80.0, 0.7 };  // odom frame far from the map's origin, turned
  double t = 0.0;
  Pose2 odom{ 1.0, 2.0, 0.3 };
  for (int i = 0; i < 50; ++i)
  {
    t += 0.1;
    odom = Pose2{ odom.x + 0.05 * std::cos(odom.yaw), odom.y + 0.05 * std::sin(odom.yaw), odom.yaw + 0.08 };
    watch.add(t, inMap(offset, odom), odom);
    EXPECT_TRUE(watch.steady()) << "at " << t << " s: " << watch.speed() << " m/s, " << watch.turnRate() << " rad/s";
  }
  EXPECT_NEAR(0.0, watch.speed(), 1e-9);
  EXPECT_NEAR(0.0, watch.turnRate(), 1e-9);
}

TEST(LocalisationWatch, OdometrySpinningWhileTheRobotStandsIsADisagreement)
{
  // Stage integrates the commanded turn into a stalled robot's odometry; the localisation holds it still.
  LocalisationWatch watch;
  double t = 0.0;
  Pose2 map_pose{ 12.1, 3.3, 1.5 }, odom_pose{ 0.0, 0.0, 0.0 };
  turn(watch, t, map_pose, odom_pose, 0.0, 0.0, 1.0);
  EXPECT_TRUE(watch.steady());
  turn(watch, t, map_pose, odom_pose, 0.0, 0.42, 1.0);
  EXPECT_FALSE(watch.steady());
  EXPECT_NEAR(0.42, watch.turnRate(), 1e-9);
  // agreeing again for a whole window: steady
  turn(watch, t, map_pose, odom_pose, 0.5, 0.5, 1.0);
  EXPECT_TRUE(watch.steady());
}

TEST(LocalisationWatch, TheTurnLimitHoldsJustInsideAndJustOutside)
{
  for (const double rate : { 0.24, 0.26 })
  {
    LocalisationWatch watch;
    double t = 0.0;
    Pose2 map_pose{ 0.0, 0.0, 0.0 }, odom_pose{ 0.0, 0.0, 0.0 };
    turn(watch, t, map_pose, odom_pose, 0.0, rate, 2.0);
    EXPECT_EQ(rate < 0.25, watch.steady()) << rate << " rad/s";
  }
}

TEST(LocalisationWatch, TheSpeedLimitHoldsJustInsideAndJustOutside)
{
  for (const double speed : { 0.24, 0.26 })
  {
    LocalisationWatch watch;
    double t = 0.0;
    for (int i = 0; i <= 20; ++i)  // the odometry says it drives on; the localisation holds it
    {
      t += 0.1;
      watch.add(t, Pose2{ 5.0, 5.0, 0.0 }, Pose2{ speed * t, 0.0, 0.0 });
    }
    EXPECT_EQ(speed < 0.25, watch.steady()) << speed << " m/s";
  }
}

TEST(LocalisationWatch, OneStepOfLagWhenATurnStartsIsNoDisagreement)
{
  // With fake_localization on Stage the map pose leads the odometry by one 0.1 s step: when a 0.8 rad/s turn starts
  // and ends the two differ by 0.08 rad once each.
  LocalisationWatch watch;
  double t = 0.0;
  Pose2 map_pose{ 13.6, 1.0, 1.57 }, odom_pose{ 0.0, 0.0, 0.0 };
  turn(watch, t, map_pose, odom_pose, 0.0, 0.0, 0.5);
  t += 0.1;
  map_pose = turned(map_pose, 0.08);
  watch.add(t, map_pose, odom_pose);  // the odometry one step behind
  turn(watch, t, map_pose, odom_pose, 0.8, 0.8, 0.3);
  t += 0.1;
  odom_pose = turned(odom_pose, 0.16);
  map_pose = turned(map_pose, 0.08);
  watch.add(t, map_pose, odom_pose);  // it stops: the odometry catches up
  EXPECT_TRUE(watch.steady()) << watch.turnRate() << " rad/s";
  EXPECT_NEAR(0.16, watch.turnRate(), 1e-6);
}

TEST(LocalisationWatch, AJumpOfTheLocalisationIsForgottenAfterAWindow)
{
  LocalisationWatch watch;
  watch.add(0.0, Pose2{ 1.0, 1.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  watch.add(0.1, Pose2{ 1.5, 1.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });  // relocalised by 0.5 m
  EXPECT_FALSE(watch.steady());
  watch.add(1.05, Pose2{ 1.5, 1.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  EXPECT_FALSE(watch.steady());  // 0.95 s after the jump: still within the window
  watch.add(1.15, Pose2{ 1.5, 1.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  EXPECT_TRUE(watch.steady());
}

TEST(LocalisationWatch, BadOrRepeatedSamplesAreIgnored)
{
  LocalisationWatch watch;
  const double nan = std::nan("");
  watch.add(1.0, Pose2{ 0.0, 0.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  watch.add(1.1, Pose2{ nan, 0.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  watch.add(1.1, Pose2{ 0.0, 0.0, 0.0 }, Pose2{ 0.0, 0.0, std::numeric_limits<double>::infinity() });
  watch.add(1.0, Pose2{ 9.0, 9.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });  // tf's latest again, or older
  watch.add(nan, Pose2{ 9.0, 9.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  EXPECT_TRUE(watch.steady());
  EXPECT_EQ(0.0, watch.speed());
  watch.add(1.2, Pose2{ 0.0, 0.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  EXPECT_TRUE(watch.steady());
}

TEST(LocalisationWatch, ZeroLimitsSwitchAChecksOffAndBadLimitsAreRefusedByName)
{
  LocalisationLimits off;
  off.max_speed = 0.0;
  off.max_turn = 0.0;
  LocalisationWatch watch(off);
  watch.add(0.0, Pose2{ 0.0, 0.0, 0.0 }, Pose2{ 0.0, 0.0, 0.0 });
  watch.add(0.1, Pose2{ 5.0, 0.0, 3.0 }, Pose2{ 0.0, 0.0, 0.0 });
  EXPECT_TRUE(watch.steady());
  for (const auto& field : { "max_correction_speed", "max_correction_turn", "correction_window" })
  {
    LocalisationLimits bad;
    if (std::string(field) == "max_correction_speed")
      bad.max_speed = -0.1;
    else if (std::string(field) == "max_correction_turn")
      bad.max_turn = std::nan("");
    else
      bad.window = 0.0;
    try
    {
      watch.setLimits(bad);
      FAIL() << field << " accepted";
    }
    catch (const std::invalid_argument& e)
    {
      EXPECT_NE(std::string::npos, std::string(e.what()).find(field)) << e.what();
    }
  }
  EXPECT_EQ(0.0, watch.limits().max_speed);  // the refused limits changed nothing
}
