// Leases and growing rectangles in the core (issue 12 parts 3 and 4): a robot that sees a shared obstacle's cells
// occupied again sends them as marked (an observation, which renews the obstacle's deadline in the handler), at
// most every lease_renewal_interval per obstacle fleet-wide; a robot that cannot see it sends nothing; a rectangle
// grown by merging is monitored as a whole.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/sharing_core.h"
#include "sim_scan.h"

using namespace sharing_layer;
using namespace sharing_layer::test;

namespace
{
/// A 0.45 m x 0.95 m block with its west face at x = 5.02.
SimWorld blockWorld()
{
  SimWorld world = walledWorld();
  world.box(5.02, 4.53, 5.47, 5.48);
  return world;
}

/// Robot_0 at (3.6, 5.0) sees the block's face and proposes it; it is authorised at t = 1 s.
std::vector<std::uint32_t> shareFace(SharingCore& core, const SimWorld& world)
{
  core.processScan(world.scan(3.6, 5.0, 0.0), 1.0);
  const TriggerReport report = core.trigger(TriggerSource::StuckFeedback, 1.0, 3.6, 5.0);
  EXPECT_EQ(1u, report.proposals.size()) << report.message;
  if (report.proposals.empty())
  {
    return {};
  }
  EXPECT_TRUE(core.applyShared(sharedUpdate("block", report.proposals[0].cells, report.proposals[0].rectangle, 1, "robot_0"),
                               1.0)
                  .ok);
  return report.proposals[0].cells;
}

std::vector<ObstacleUpdate> scanAt(SharingCore& core, const SimWorld& world, double x, double y, double yaw, double t)
{
  return core.processScan(world.scan(x, y, yaw), t).updates;
}
}  // namespace

TEST(Leases, ASeenObstacleIsRenewedOncePerIntervalWithTheCellsSeenOccupied)
{
  const SimWorld world = blockWorld();
  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareFace(core, world);
  ASSERT_GE(face.size(), 15u);
  ASSERT_EQ(5.0, defaults().lease_renewal_interval);

  EXPECT_TRUE(scanAt(core, world, 3.6, 5.0, 0.0, 2.0).empty()) << "renewed 1 s after the share";
  EXPECT_TRUE(scanAt(core, world, 3.6, 5.0, 0.0, 5.9).empty());
  const std::vector<ObstacleUpdate> renewal = scanAt(core, world, 3.6, 5.0, 0.0, 6.0);
  ASSERT_EQ(1u, renewal.size());
  EXPECT_EQ("block", renewal[0].uuid);
  EXPECT_TRUE(renewal[0].cleared.empty());
  EXPECT_EQ(2u, renewal[0].version);
  EXPECT_GE(renewal[0].marked.size(), face.size() / 2);
  for (std::uint32_t index : renewal[0].marked)
  {
    EXPECT_TRUE(std::binary_search(face.begin(), face.end(), index)) << "renewal holds cell " << index << " off the face";
  }
  EXPECT_TRUE(scanAt(core, world, 3.6, 5.0, 0.0, 6.5).empty()) << "one renewal per interval";
  EXPECT_EQ(face, core.sharedCells("block"));
}

TEST(Leases, AnotherRobotsObservationResetsTheInterval)
{
  const SimWorld world = blockWorld();
  SharingCore core = makeCore();
  const std::vector<std::uint32_t> face = shareFace(core, world);
  ASSERT_FALSE(face.empty());
  // robot_1 renewed it at t = 4: the fleet heard of an observation, so robot_0 waits until t = 9.
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", { face[0] }, Subsection(5.0, 4.5, 5.1, 5.5), 2, "robot_1"), 4.0).ok);
  EXPECT_TRUE(scanAt(core, world, 3.6, 5.0, 0.0, 6.0).empty());
  EXPECT_TRUE(scanAt(core, world, 3.6, 5.0, 0.0, 8.9).empty());
  const std::vector<ObstacleUpdate> renewal = scanAt(core, world, 3.6, 5.0, 0.0, 9.0);
  ASSERT_EQ(1u, renewal.size());
  EXPECT_EQ(3u, renewal[0].version);
  // An update that only clears is no observation: it does not reset the interval.
  ASSERT_TRUE(core.applyShared([&] {
                ObstacleUpdate u = sharedUpdate("block", {}, Subsection(5.0, 4.5, 5.1, 5.5), 4, "robot_1");
                u.cleared = { 0 };
                return u;
              }(),
                               12.0)
                  .ok);
  EXPECT_EQ(1u, scanAt(core, world, 3.6, 5.0, 0.0, 14.0).size());
}

TEST(Leases, ARobotThatCannotSeeTheObstacleNeverRenewsIt)
{
  const SimWorld world = blockWorld();
  SharingCore core = makeCore();
  ASSERT_FALSE(shareFace(core, world).empty());
  // Facing away from it, then beyond obstacle_range (2.5 m) but within raytrace_range of it, then far away.
  for (double t = 7.0; t < 30.0; t += 0.5)
  {
    EXPECT_TRUE(scanAt(core, world, 3.6, 5.0, 3.14159, t).empty()) << "t " << t;
  }
  for (double t = 30.0; t < 60.0; t += 0.5)
  {
    EXPECT_TRUE(scanAt(core, world, 2.3, 5.0, 0.0, t).empty()) << "2.7 m from the face, t " << t;
    EXPECT_TRUE(scanAt(core, world, 1.0, 1.0, 0.0, t + 0.25).empty()) << "far away, t " << t;
  }
}

TEST(Leases, TheIntervalParameterIsValidated)
{
  LayerParams p = defaults();
  p.lease_renewal_interval = -1.0;
  EXPECT_THROW(SharingCore(grid(), p), std::invalid_argument);
  p.lease_renewal_interval = 0.0;  // renew on every scan that sees it
  SharingCore core = makeCore(p);
  const SimWorld world = blockWorld();
  ASSERT_FALSE(shareFace(core, world).empty());
  EXPECT_EQ(1u, scanAt(core, world, 3.6, 5.0, 0.0, 1.1).size());
  EXPECT_EQ(1u, scanAt(core, world, 3.6, 5.0, 0.0, 1.2).size());
}

TEST(MergedRectangles, AGrownRectangleIsMonitoredAndItsCellsAreNoLongerProposed)
{
  const SimWorld world = blockWorld();
  SharingCore core = makeCore();
  // The handler authorised only the south half of the face (another robot's partial view).
  const Subsection south(5.0, 4.5, 5.1, 4.95);
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", { grid().getIndex(100, 91) }, south, 1, "robot_1"), 1.0).ok);
  core.processScan(world.scan(3.6, 5.0, 0.0), 2.0);
  const std::vector<std::uint32_t> candidates = core.shareableCells();
  ASSERT_FALSE(candidates.empty()) << "the north half lies outside the rectangle: this robot's candidates";

  // A merge grew the rectangle over the whole face: monitoring takes the north half over.
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", { grid().getIndex(100, 91) }, Subsection(5.0, 4.5, 5.1, 5.5), 2,
                                      "robot_1"),
                               3.0)
                  .ok);
  EXPECT_TRUE(core.shareableCells().empty());
  const Subsection& r = core.sharedObstacles().at("block").rectangle;
  EXPECT_EQ(5.5, r.max_y);
  const std::vector<ObstacleUpdate> updates = scanAt(core, world, 3.6, 5.0, 0.0, 3.5);
  ASSERT_EQ(1u, updates.size());
  for (std::uint32_t index : candidates)
  {
    EXPECT_TRUE(std::binary_search(updates[0].marked.begin(), updates[0].marked.end(), index))
        << "north cell " << index << " not added to the obstacle";
  }
  // A smaller rectangle in a later update never shrinks it.
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", { grid().getIndex(100, 91) }, south, 9, "robot_2"), 4.0).ok);
  EXPECT_EQ(5.5, core.sharedObstacles().at("block").rectangle.max_y);
}

TEST(Growing, APartlySharedBlockGrowsOverItsWholeFaceAsTheRobotSeesIt)
{
  // The plan trigger fires on the first cells of a block seen on the plan: only the middle of its face is
  // shared. The robot keeps seeing the face: cells marked steadily that touch the obstacle join it.
  const SimWorld world = blockWorld();
  SharingCore core = makeCore();
  const GridGeometry g = grid();
  std::vector<std::uint32_t> middle;
  for (unsigned int y = 98; y <= 101; ++y)
  {
    middle.push_back(g.getIndex(100, y));
  }
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", middle, Subsection(5.0, 4.9, 5.05, 5.1), 1, "robot_0"), 1.0).ok);

  std::vector<std::uint32_t> added;
  double t = 1.0;
  std::vector<ObstacleUpdate> first = scanAt(core, world, 3.6, 5.0, 0.0, t);
  EXPECT_TRUE(first.empty()) << "one scan is not steady: nothing grows";
  for (int i = 0; i < 15; ++i)
  {
    t += 0.1;
    for (const ObstacleUpdate& u : scanAt(core, world, 3.6, 5.0, 0.0, t))
    {
      EXPECT_TRUE(u.cleared.empty());
      added.insert(added.end(), u.marked.begin(), u.marked.end());
      EXPECT_EQ(core.sharedObstacles().at("block").rectangle.min_y, u.rectangle.min_y);
    }
  }
  const std::vector<std::uint32_t> cells = core.sharedCells("block");
  // The whole west face (rows 91..109 of column 100, y 4.55..5.5), the same cells the robot's own view marks.
  for (unsigned int y = 91; y <= 109; ++y)
  {
    EXPECT_TRUE(std::binary_search(cells.begin(), cells.end(), g.getIndex(100, y))) << "face row " << y << " missing";
  }
  for (std::uint32_t index : cells)
  {
    EXPECT_EQ(100u, index % g.size_x) << "cell off the face: (" << index % g.size_x << ", " << index / g.size_x << ")";
  }
  EXPECT_FALSE(added.empty());
  const Subsection& r = core.sharedObstacles().at("block").rectangle;
  EXPECT_LE(r.min_y, 4.55);
  EXPECT_GE(r.max_y, 5.45);
  EXPECT_TRUE(core.shareableCells().empty()) << "the face is the obstacle's now, not a candidate";
}

TEST(Growing, NeitherWallsNorSeparateObjectsJoin)
{
  // A second box 0.3 m north of the block (beyond cluster_gap) and the outer wall stay out of the obstacle.
  SimWorld world = blockWorld();
  world.box(5.02, 5.8, 5.3, 6.2);
  SharingCore core = makeCore();
  const GridGeometry g = grid();
  std::vector<std::uint32_t> face;  // the block's west face only (a thesis sectors proposal would take both)
  for (unsigned int y = 91; y <= 109; ++y)
  {
    face.push_back(g.getIndex(100, y));
  }
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", face, Subsection(5.0, 4.5, 5.05, 5.5), 1, "robot_0"), 1.0).ok);
  for (double t = 1.1; t < 4.0; t += 0.1)
  {
    scanAt(core, world, 3.6, 5.4, 0.0, t);
  }
  EXPECT_FALSE(core.shareableCells().empty()) << "the other box is seen: a candidate of its own";
  for (std::uint32_t index : core.sharedCells("block"))
  {
    EXPECT_LE(index / g.size_x, 110u) << "a cell of the other box joined the block";
  }
}

TEST(PlanTrigger, ABlockFirstSeenAtObstacleRangeIsProposedWithTheFaceSeenBeyondIt)
{
  // A 3 m face 2.47 m ahead of the laser: its middle is within obstacle_range (2.5 m), its ends 2.5-2.9 m away
  // are beam endpoints the laser sees but costmap_2d does not mark. navfn's detour may keep the robot from ever
  // marking them: the plan trigger's cluster takes them along, so the whole face is shared.
  SimWorld world = walledWorld();
  world.box(5.02, 3.5, 5.3, 6.5);
  SharingCore core = makeCore();
  std::vector<std::pair<double, double>> plan;
  for (double x = 2.55; x <= 8.0; x += 0.05)
  {
    plan.emplace_back(x, 5.0);
  }
  core.setPlan(plan);
  core.processScan(world.scan(2.55, 5.0, 0.0), 1.0);
  const TriggerReport report = core.checkPlan(2.55, 5.0, 1.0);
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  ASSERT_EQ(1u, report.proposals.size()) << report.message;
  const Subsection& r = report.proposals[0].rectangle;
  EXPECT_LE(r.min_y, 3.65) << report.message;
  EXPECT_GE(r.max_y, 6.35) << report.message;
  const GridGeometry g = grid();
  for (std::uint32_t index : report.proposals[0].cells)
  {
    double x = 0.0, y = 0.0;
    g.mapToWorld(index % g.size_x, index / g.size_x, x, y);
    EXPECT_TRUE(x > 4.95 && x < 5.35 && y > 3.45 && y < 6.55) << "cell (" << x << ", " << y << ") is not the face";
  }
  // The obstacle grid keeps costmap_2d's rule: only the middle is marked.
  unsigned int mx = 0, my = 0;
  ASSERT_TRUE(g.worldToMap(5.04, 3.6, mx, my));
  EXPECT_NE(LETHAL_OBSTACLE, core.obstacleGrid().at(g.getIndex(mx, my)));
}
