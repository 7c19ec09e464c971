// Bad input gets a clear error (exception or a false result with a reason), no crash, state intact.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/sharing_core.h"

using namespace sharing_layer;

namespace
{
const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

GridGeometry grid()
{
  return GridGeometry(0.1, 0.0, 0.0, 20, 20);
}

ObstacleUpdate validUpdate()
{
  ObstacleUpdate u;
  u.uuid = "0f8e2c1a-3b4d-4e5f-8a9b-c0d1e2f3a4b5";
  u.marked = { 45, 46 };
  u.deadline = 30;
  u.rectangle = Subsection(0.4, 0.1, 0.8, 0.4);
  u.source = "robot_1";
  u.geometry = grid();
  u.version = 1;
  return u;
}

std::string messageOf(const std::function<void()>& f)
{
  try
  {
    f();
  }
  catch (const std::invalid_argument& e)
  {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(BadInput, NaNInfAndNegativeRangesAreRejectedByName)
{
  for (double bad : { kNaN, kInf, -1.0 })
  {
    LayerParams p;
    p.limits.obstacle_range = bad;
    EXPECT_NE(std::string::npos, messageOf([&] { SharingCore(grid(), p); }).find("obstacle_range"));
    p = LayerParams();
    p.limits.raytrace_range = bad;
    EXPECT_NE(std::string::npos, messageOf([&] { SharingCore(grid(), p); }).find("raytrace_range"));
  }
  LayerParams p;
  p.limits.min_obstacle_height = 1.0;
  p.limits.max_obstacle_height = 0.5;
  EXPECT_NE(std::string::npos, messageOf([&] { SharingCore(grid(), p); }).find("min_obstacle_height"));
  p = LayerParams();
  p.static_tolerance = -1;
  EXPECT_NE(std::string::npos, messageOf([&] { SharingCore(grid(), p); }).find("static_tolerance"));
  EXPECT_NE(std::string::npos, messageOf([&] { parseProposalStrategy("diagonal"); }).find("diagonal"));
  EXPECT_NE(std::string::npos, messageOf([&] { GridGeometry(0.0, 0, 0, 10, 10); }).find("resolution"));
  EXPECT_NE(std::string::npos, messageOf([&] { TriggerDebounce trigger(kNaN); }).find("trigger_debounce"));
}

TEST(BadInput, NonFinitePointsAreCountedAndSkipped)
{
  SharingCore core(grid(), LayerParams());
  Observation obs;
  obs.origin = Point3{ 0.05, 0.05, 0.0 };
  obs.points = { { kNaN, 0.5, 0.0 }, { 0.5, kInf, 0.0 }, { 0.55, 0.05, 0.0 } };
  const ScanOutcome outcome = core.processScan(obs, 1.0);
  EXPECT_EQ(2u, outcome.touch.rejected_points);
  EXPECT_EQ((std::vector<std::uint32_t>{ 5 }), outcome.touch.marked);
}

TEST(BadInput, ScanWithZeroBeamsChangesNothing)
{
  SharingCore core(grid(), LayerParams());
  core.obstacleGrid().set(3, LETHAL_OBSTACLE);
  Observation obs;
  obs.origin = Point3{ 0.05, 0.05, 0.0 };
  const ScanOutcome outcome = core.processScan(obs, 1.0);
  EXPECT_TRUE(outcome.touch.marked.empty());
  EXPECT_TRUE(outcome.updates.empty());
  EXPECT_EQ(LETHAL_OBSTACLE, core.obstacleGrid().at(3));
}

TEST(BadInput, SensorOriginOffTheMapOrNotFiniteClearsNothing)
{
  SharingCore core(grid(), LayerParams());
  core.obstacleGrid().set(3, LETHAL_OBSTACLE);
  for (Point3 origin : { Point3{ -5.0, 0.05, 0.0 }, Point3{ kNaN, 0.05, 0.0 }, Point3{ 0.05, 0.05, kInf } })
  {
    Observation obs;
    obs.origin = origin;
    obs.points = { { 0.55, 0.05, 0.0 } };
    const ScanOutcome outcome = core.processScan(obs, 1.0);
    EXPECT_FALSE(outcome.touch.origin_in_map);
    EXPECT_EQ(LETHAL_OBSTACLE, core.obstacleGrid().at(3));
  }
}

TEST(BadInput, BadUpdatesAreRejectedWithAReasonAndStateIntact)
{
  SharingCore core(grid(), LayerParams());
  ASSERT_TRUE(core.applyShared(validUpdate(), 0.0).ok);
  const auto before = core.sharedCells(validUpdate().uuid);

  ObstacleUpdate out_of_range = validUpdate();
  out_of_range.version = 2;
  out_of_range.marked = { 47, 400 };
  ApplyResult r = core.applyShared(out_of_range, 1.0);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(std::string::npos, r.error.find("index 400"));

  ObstacleUpdate other_grid = validUpdate();
  other_grid.geometry = GridGeometry(0.05, 0.0, 0.0, 40, 40);
  r = core.applyShared(other_grid, 1.0);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(std::string::npos, r.error.find("differs"));

  ObstacleUpdate huge = validUpdate();
  huge.uuid = "1f8e2c1a-3b4d-4e5f-8a9b-c0d1e2f3a4b5";
  huge.marked.assign(2000000, 7);
  r = core.applyShared(huge, 1.0);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(std::string::npos, r.error.find("max_update_cells"));

  ObstacleUpdate flipped = validUpdate();
  flipped.uuid = "2f8e2c1a-3b4d-4e5f-8a9b-c0d1e2f3a4b5";
  flipped.rectangle.min_x = 1.0;  // built without the checking constructor: min_x > max_x
  r = core.applyShared(flipped, 1.0);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(std::string::npos, r.error.find("min_x > max_x"));

  ObstacleUpdate no_uuid = validUpdate();
  no_uuid.uuid.clear();
  EXPECT_FALSE(core.applyShared(no_uuid, 1.0).ok);

  ObstacleUpdate zero_deadline = validUpdate();
  zero_deadline.uuid = "3f8e2c1a-3b4d-4e5f-8a9b-c0d1e2f3a4b5";
  zero_deadline.deadline = 0;
  EXPECT_FALSE(core.applyShared(zero_deadline, 1.0).ok);

  EXPECT_EQ(before, core.sharedCells(validUpdate().uuid));
  EXPECT_EQ(1u, core.sharedObstacles().size());
}

TEST(BadInput, RectangleWithMinAboveMaxThrowsNamingTheCall)
{
  EXPECT_EQ("Subsection: min_x > max_x in [2, 0, 1, 1]", messageOf([] { Subsection(2.0, 0.0, 1.0, 1.0); }));
  EXPECT_NE(std::string::npos, messageOf([] { Subsection(0.0, 0.0, kNaN, 1.0); }).find("finite"));
}

TEST(BadInput, MismatchedStaticMapAndMasterSizesThrow)
{
  SharingCore core(grid(), LayerParams());
  std::vector<std::uint8_t> small(10, 0);
  EXPECT_NE(std::string::npos, messageOf([&] { core.setStaticMap(small.data(), small.size()); }).find("10 cells"));
  EXPECT_NE(std::string::npos, messageOf([&] { core.drawShared(small.data(), small.size()); }).find("10 cells"));
}
