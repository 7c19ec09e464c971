// Evidence-based clearing of shared obstacles (issue 12 A): with upstream defaults (raytrace_range 3.0 >
// obstacle_range 2.5) a robot driving past or away from a shared block must not erode it, and a block that
// is really removed must still be cleared and the clearing shared.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <random>
#include <string>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/sharing_core.h"
#include "sim_scan.h"

using namespace sharing_layer;
using namespace sharing_layer::test;

namespace
{
/// The block: 0.45 m x 0.95 m, its west face at x = 5.02 (inside a 5 cm cell, not on its border).
void block(SimWorld& world, std::uint8_t value = 1)
{
  world.box(5.02, 4.53, 5.47, 5.48, value);
}

/// A robot at (3.6, 5.0) facing the block 1.42 m ahead proposes it; the handler authorises it.
std::vector<std::uint32_t> shareBlock(SharingCore& core, const SimWorld& world)
{
  core.processScan(world.scan(3.6, 5.0, 0.0), 1.0);
  const TriggerReport report = core.trigger(TriggerSource::StuckFeedback, 1.0, 3.6, 5.0);
  EXPECT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  if (report.proposals.size() != 1)
  {
    ADD_FAILURE() << "expected one proposal (the block), got " << report.message;
    return {};
  }
  const ObstacleUpdate authorised =
      sharedUpdate("block", report.proposals[0].cells, report.proposals[0].rectangle, 1, "robot_0", 600);
  EXPECT_TRUE(core.applyShared(authorised, 1.0).ok);
  return authorised.marked;
}

/// Scans through the removed block at 2.0, 2.5 and 3.0 s (the defaults clear after 3 scans over 1 s): the first two
/// send nothing. @return the third scan's outcome
ScanOutcome scanUntilCleared(SharingCore& core, const Observation& through)
{
  EXPECT_TRUE(core.processScan(through, 2.0).updates.empty());
  EXPECT_TRUE(core.processScan(through, 2.5).updates.empty());
  return core.processScan(through, 3.0);
}

struct DriveResult
{
  std::size_t updates = 0;
  std::size_t cleared = 0;
  std::size_t marked = 0;
};

/// Scans at 10 Hz along a straight drive, with a seeded localisation error of up to 2 cm and 0.6 degrees.
DriveResult drive(SharingCore& core, const SimWorld& world, double x0, double y0, double x1, double y1, double yaw,
                  double& now, unsigned int seed)
{
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> shift(-0.02, 0.02), turn(-0.01, 0.01);
  const double length = std::hypot(x1 - x0, y1 - y0);
  const int steps = static_cast<int>(length / 0.02);
  DriveResult result;
  for (int i = 0; i <= steps; ++i)
  {
    const double t = steps == 0 ? 0.0 : static_cast<double>(i) / steps;
    now += 0.1;
    const ScanOutcome outcome =
        core.processScan(world.scan(x0 + t * (x1 - x0), y0 + t * (y1 - y0), yaw, shift(rng), shift(rng), turn(rng)),
                         now);
    for (const ObstacleUpdate& u : outcome.updates)
    {
      if (std::getenv("SIM_DEBUG") && !u.cleared.empty())
      {
        std::printf("seed %u step %d pose (%.2f, %.2f): cleared", seed, i, x0 + t * (x1 - x0), y0 + t * (y1 - y0));
        for (std::uint32_t c : u.cleared)
        {
          std::printf(" (%u,%u)", c % 200, c / 200);
        }
        std::printf("\n");
      }
      ++result.updates;
      result.cleared += u.cleared.size();
      result.marked += u.marked.size();
    }
  }
  return result;
}

/// The drives of the erosion report: backing away from the block through 2.5-3 m, and driving past it.
DriveResult driveAwayAndPast(SharingCore& core, const SimWorld& world)
{
  double now = 2.0;
  DriveResult total;
  for (const DriveResult& r :
       { drive(core, world, 3.6, 5.0, 1.0, 5.0, 0.0, now, 1),        // backing off, facing the block
         drive(core, world, 2.9, 5.3, 1.5, 6.2, 0.3, now, 2),        // backing off at an angle
         drive(core, world, 1.0, 3.9, 9.0, 3.9, 0.0, now, 3),        // driving past, 0.6 m from its south face
         drive(core, world, 9.0, 6.4, 1.0, 6.4, 3.14159, now, 4),    // past the north face, the other way
         drive(core, world, 4.8, 3.5, 4.8, 1.0, -1.5708, now, 5) })  // driving away from it, block behind
  {
    total.updates += r.updates;
    total.cleared += r.cleared;
    total.marked += r.marked;
  }
  return total;
}
}  // namespace

TEST(EvidenceClearing, ScanReportsFreeEvidenceOnlyMarginBeforeTheEndpoint)
{
  // One beam along row 2 of a 0.1 m grid from x = 0.05 to 0.85: cells 0..7 are cleared, 8 is marked. With a
  // margin of 0.3 m only cells whose centres lie at least 0.3 m before the endpoint (0..5) are evidence.
  CostGrid g(GridGeometry(0.1, 0.0, 0.0, 12, 5), LETHAL_OBSTACLE);
  ScanWatch watch;
  for (std::uint32_t x = 0; x < 12; ++x)
  {
    watch.cells.push_back(2 * 12 + x);
  }
  watch.free_margin = 0.3;
  Observation obs;
  obs.origin = Point3{ 0.05, 0.25, 0.0 };
  obs.points = { Point3{ 0.85, 0.25, 0.0 } };
  const ScanTouch touch = applyScan(g, obs, ScanLimits(), watch);
  EXPECT_EQ((std::vector<std::uint32_t>{ 24, 25, 26, 27, 28, 29, 30, 31 }), touch.watched_cleared);
  EXPECT_EQ((std::vector<std::uint32_t>{ 24, 25, 26, 27, 28, 29 }), touch.watched_free);
  // The grid is what costmap_2d leaves: cleared up to the endpoint, endpoint lethal, the rest untouched.
  for (std::uint32_t x = 0; x < 12; ++x)
  {
    EXPECT_EQ(x < 8 ? FREE_SPACE : LETHAL_OBSTACLE, g.at(24 + x)) << "cell " << x;
  }
  watch.free_margin = -0.1;
  EXPECT_THROW(applyScan(g, obs, ScanLimits(), watch), std::invalid_argument);
}

TEST(EvidenceClearing, BlockSurvivesRobotsDrivingPastAndAwayWithUpstreamDefaults)
{
  SimWorld world = walledWorld();
  block(world);

  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareBlock(core, world);
  ASSERT_GE(face.size(), 15u);  // the 0.95 m face is 19-20 cells

  const DriveResult result = driveAwayAndPast(core, world);
  EXPECT_EQ(0u, result.cleared) << "cleared cells sent for a block that never moved (" << result.updates
                                << " updates)";
  const std::vector<std::uint32_t> now_shared = core.sharedCells("block");
  for (std::uint32_t index : face)
  {
    EXPECT_TRUE(std::binary_search(now_shared.begin(), now_shared.end(), index)) << "face cell " << index << " lost";
  }
  // Driving past, the robot saw the block's other faces: they joined it (growing), and nothing else did.
  EXPECT_GE(now_shared.size(), face.size());
  const GridGeometry g = grid();
  for (std::uint32_t index : now_shared)
  {
    double x = 0.0, y = 0.0;
    g.mapToWorld(index % g.size_x, index / g.size_x, x, y);
    EXPECT_TRUE(x > 5.02 - 0.05 && x < 5.47 + 0.05 && y > 4.53 - 0.05 && y < 5.48 + 0.05)
        << "shared cell (" << x << ", " << y << ") is not the block's";
  }
}

TEST(EvidenceClearing, SameDrivesErodeTheBlockWithSingleScanRaytraceClearing)
{
  // The scenario reproduces the reported erosion when every raytraced cell counts (margin 0, one scan): so the
  // test above fails if the evidence rule stops holding.
  SimWorld world = walledWorld();
  block(world);
  LayerParams p = defaults();
  p.clearing_margin = 0.0;
  p.clearing_scans = 1;
  p.clearing_time = 0.0;
  p.clearing_neighbours = 0;
  SharingCore core = makeCore(p);
  shareBlock(core, world);
  EXPECT_GT(driveAwayAndPast(core, world).cleared, 5u);
}

TEST(EvidenceClearing, RemovedBlockIsClearedAfterClearingScansAndTheUpdateShared)
{
  SimWorld world = walledWorld();
  block(world);
  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareBlock(core, world);
  ASSERT_FALSE(face.empty());

  block(world, 0);  // removed while in the robot's view (thesis Test 2)
  const Observation through = world.scan(3.6, 5.0, 0.0);
  ASSERT_EQ(3u, defaults().clearing_scans);
  ASSERT_EQ(1.0, defaults().clearing_time);
  const ScanOutcome outcome = scanUntilCleared(core, through);
  ASSERT_EQ(1u, outcome.updates.size());
  EXPECT_EQ("block", outcome.updates[0].uuid);
  EXPECT_EQ(face, outcome.updates[0].cleared);
  EXPECT_TRUE(outcome.updates[0].marked.empty());
  EXPECT_TRUE(core.sharedCells("block").empty());
  // Emptied, not deleted: only the deadline removes it.
  EXPECT_EQ(1u, core.sharedObstacles().count("block"));
}

TEST(EvidenceClearing, APeersObstacleArrivingBetweenScansIsMonitoredToo)
{
  // The robot has scanned before the peer's obstacle arrives, and never marked its cells itself (no trigger memory
  // of them): only the obstacle's own monitoring can see them free.
  SimWorld world = walledWorld();
  block(world);
  SharingCore peer = makeCore();
  const std::vector<std::uint32_t> face = shareBlock(peer, world);
  ASSERT_FALSE(face.empty());
  const SharedObstacle& shared = peer.sharedObstacles().at("block");

  block(world, 0);
  SharingCore core = makeCore();
  const Observation through = world.scan(3.6, 5.0, 0.0);
  EXPECT_TRUE(core.processScan(through, 1.0).updates.empty());
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", face, shared.rectangle, 1, "robot_1", 600), 1.5).ok);
  const ScanOutcome outcome = scanUntilCleared(core, through);
  ASSERT_EQ(1u, outcome.updates.size());
  EXPECT_EQ(face, outcome.updates[0].cleared);
}

TEST(EvidenceClearing, TheStreakNeedsClearingScansAndClearingTime)
{
  SimWorld world = walledWorld();
  block(world);
  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareBlock(core, world);
  ASSERT_FALSE(face.empty());
  block(world, 0);
  const Observation through = world.scan(3.6, 5.0, 0.0);
  // Five scans within 0.4 s are not enough time; two scans 1.5 s apart are not enough scans.
  for (double t : { 2.0, 2.1, 2.2, 2.3, 2.4 })
  {
    EXPECT_TRUE(core.processScan(through, t).updates.empty()) << "t = " << t;
  }
  EXPECT_TRUE(core.processScan(world.scan(9.0, 9.0, 0.0), 2.7).updates.empty());  // out of view: no effect
  const ScanOutcome outcome = core.processScan(through, 3.0);
  ASSERT_EQ(1u, outcome.updates.size());
  EXPECT_EQ(face, outcome.updates[0].cleared);

  LayerParams p = defaults();
  p.clearing_time = 0.0;
  p.clearing_scans = 3;
  SharingCore two = makeCore(p);
  block(world, 1);
  shareBlock(two, world);
  EXPECT_TRUE(two.processScan(through, 2.0).updates.empty());
  EXPECT_TRUE(two.processScan(through, 3.5).updates.empty());
  EXPECT_EQ(1u, two.processScan(through, 3.6).updates.size());
}

TEST(EvidenceClearing, AHitInBetweenStartsTheEvidenceAgain)
{
  SimWorld world = walledWorld();
  block(world);
  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareBlock(core, world);
  ASSERT_FALSE(face.empty());
  const Observation with_block = world.scan(3.6, 5.0, 0.0);
  block(world, 0);
  const Observation without = world.scan(3.6, 5.0, 0.0);

  EXPECT_TRUE(core.processScan(without, 2.0).updates.empty());
  EXPECT_TRUE(core.processScan(without, 2.5).updates.empty());
  EXPECT_TRUE(core.processScan(with_block, 2.7).updates.empty());  // seen again: the streak restarts
  EXPECT_TRUE(core.processScan(without, 3.0).updates.empty());
  EXPECT_TRUE(core.processScan(without, 3.5).updates.empty());
  const ScanOutcome outcome = core.processScan(without, 4.0);
  ASSERT_EQ(1u, outcome.updates.size());
  EXPECT_EQ(face, outcome.updates[0].cleared);
}

TEST(EvidenceClearing, OwnObstacleGridKeepsCostmapSemantics)
{
  // The layer's own grid still clears what raytracing passes, as costmap_2d's ObstacleLayer: a block face
  // 2.7 m away (beyond obstacle_range, within raytrace_range) is cleared there and not re-marked, while the
  // shared obstacle keeps it.
  SimWorld world = walledWorld();
  block(world);
  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareBlock(core, world);
  ASSERT_FALSE(face.empty());
  for (int i = 0; i < 5; ++i)
  {
    EXPECT_TRUE(core.processScan(world.scan(2.32, 5.0, 0.0), 2.0 + 0.1 * i).updates.empty());
  }
  std::size_t lethal = 0;
  for (std::uint32_t index : face)
  {
    lethal += core.obstacleGrid().at(index) == LETHAL_OBSTACLE;
  }
  EXPECT_EQ(0u, lethal);
  EXPECT_EQ(face, core.sharedCells("block"));
}

TEST(EvidenceClearing, BadParametersAreRejectedByName)
{
  LayerParams p = defaults();
  p.clearing_scans = 0;
  EXPECT_THROW(
      {
        try
        {
          p.validate();
        }
        catch (const std::invalid_argument& e)
        {
          EXPECT_NE(std::string(e.what()).find("clearing_scans"), std::string::npos);
          throw;
        }
      },
      std::invalid_argument);
  p = defaults();
  p.clearing_margin = std::nan("");
  EXPECT_THROW(SharingCore(grid(), p), std::invalid_argument);
  p = defaults();
  p.trigger_memory = -1.0;
  EXPECT_THROW(SharingCore(grid(), p), std::invalid_argument);
  p = defaults();
  p.trigger_radius = std::numeric_limits<double>::infinity();
  EXPECT_THROW(SharingCore(grid(), p), std::invalid_argument);
  p = defaults();
  p.inscribed_radius = -0.1;
  EXPECT_THROW(SharingCore(grid(), p), std::invalid_argument);
}

namespace
{
/// A shared one-column obstacle (cells x = 100, y = 98..102: 5.00..5.05 m by 4.90..5.15 m) seen from (3.6, 5.0) through
/// three scans over 1 s. The world holds no block there, only a wall whose face lies `gap` metres beyond the column's far
/// edge (5.05 m): every beam through the column ends `gap` + 0.05 m beyond the column's near side (x = 5.00).
/// @return how many of the column's 5 cells the scans cleared
std::size_t clearedBeforeAWall(const LayerParams& p, double gap)
{
  SimWorld world = walledWorld();
  world.box(5.05 + gap, 4.0, 6.0, 6.0);
  SharingCore core = makeCore(p);
  const GridGeometry g = grid();
  std::vector<std::uint32_t> column;
  for (unsigned int y = 98; y <= 102; ++y)
  {
    column.push_back(g.getIndex(100, y));
  }
  EXPECT_TRUE(core.applyShared(sharedUpdate("column", column, Subsection(5.0, 4.9, 5.05, 5.15)), 1.0).ok);
  const Observation scan = world.scan(3.6, 5.0, 0.0);
  std::size_t cleared = 0;
  for (double t : { 2.0, 2.5, 3.0 })
  {
    for (const ObstacleUpdate& u : core.processScan(scan, t).updates)
    {
      cleared += u.cleared.size();
    }
  }
  return cleared;
}
}  // namespace

TEST(EvidenceClearing, TheMarginFromLayerParamsDecidesJustInsideAndJustOutside)
{
  // A beam is evidence for a cell only when it ends at least clearing_margin beyond where it entered it (the column's
  // near side, x = 5.00): ending 0.01 m short of the margin keeps the cells, 0.01 m past it clears them. With the
  // default 0.1 m and with 0.2 m, so that it is the parameter, through the scan pass, that decides.
  for (double margin : { 0.1, 0.2 })
  {
    LayerParams p = defaults();
    p.clearing_margin = margin;
    ASSERT_EQ(8u, p.clearing_neighbours);  // the other guards as shipped: they hold nothing back here
    const double near_side_to_end_inside = margin - 0.01, near_side_to_end_outside = margin + 0.01;
    EXPECT_EQ(0u, clearedBeforeAWall(p, near_side_to_end_inside - 0.05)) << "margin " << margin;
    EXPECT_EQ(5u, clearedBeforeAWall(p, near_side_to_end_outside - 0.05)) << "margin " << margin;
  }
}
