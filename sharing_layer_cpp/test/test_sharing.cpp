// Shareable cells, trigger, proposals, monitoring and overlay of the sharing core.
#include <gtest/gtest.h>

#include <algorithm>

#include "ascii_grid.h"
#include "sharing_layer/cost_values.h"
#include "sharing_layer/proposals.h"
#include "sharing_layer/sharing_core.h"

using namespace sharing_layer;
using sharing_layer::test::drawCells;
using sharing_layer::test::picture;

namespace
{
/// 40 x 40 cells of 0.1 m at the origin.
GridGeometry grid40()
{
  return GridGeometry(0.1, 0.0, 0.0, 40, 40);
}

std::uint32_t cell(unsigned int x, unsigned int y)
{
  return y * 40 + x;
}

/// World centre of a cell of grid40().
Point3 centre(unsigned int x, unsigned int y)
{
  return Point3{ x * 0.1 + 0.05, y * 0.1 + 0.05, 0.0 };
}

Observation scan(Point3 origin, std::vector<Point3> points)
{
  Observation obs;
  obs.origin = origin;
  obs.points = std::move(points);
  return obs;
}

LayerParams params(ProposalStrategy strategy = ProposalStrategy::Sectors)
{
  LayerParams p;
  p.limits.obstacle_range = 2.5;
  p.limits.raytrace_range = 3.0;
  p.static_tolerance = 2;
  p.strategy = strategy;
  p.robot_name = "robot_0";
  return p;
}

ObstacleUpdate share(const std::string& uuid, std::vector<std::uint32_t> marked, Subsection rect,
                     std::uint64_t version = 1, const std::string& source = "robot_1")
{
  ObstacleUpdate u;
  u.uuid = uuid;
  u.marked = std::move(marked);
  u.deadline = 60;
  u.rectangle = rect;
  u.source = source;
  u.geometry = grid40();
  u.version = version;
  return u;
}
}  // namespace

TEST(Sectors, DiagonalsThroughTheRobotSplitThePlane)
{
  // The thesis's lines y = (x - rx) + ry and y = -(x - rx) + ry, robot at (2, 1).
  const double rx = 2.0, ry = 1.0;
  EXPECT_EQ(Sector::East, sectorOf(3.0, 1.5, rx, ry));
  EXPECT_EQ(Sector::North, sectorOf(2.5, 3.0, rx, ry));
  EXPECT_EQ(Sector::West, sectorOf(0.0, 0.5, rx, ry));
  EXPECT_EQ(Sector::South, sectorOf(1.5, -1.0, rx, ry));
  // On the lines themselves: y = (x - 2) + 1 at x = 4 is y = 3; y = -(x - 2) + 1 at x = 0 is y = 3.
  EXPECT_EQ(Sector::East, sectorOf(4.0, 3.0, rx, ry));
  EXPECT_EQ(Sector::West, sectorOf(0.0, 3.0, rx, ry));
  EXPECT_EQ(Sector::East, sectorOf(rx, ry, rx, ry));
}

TEST(Sectors, OneProposalPerNonEmptySectorWithItsBoundingRectangle)
{
  const GridGeometry g = grid40();
  // Robot at cell (20, 20). An obstacle in front (east) and an old one behind (west) must not merge.
  const std::vector<std::uint32_t> cells = { cell(25, 19), cell(25, 20), cell(25, 21), cell(12, 20), cell(13, 21) };
  const auto proposals = proposeBySectors(g, cells, 2.05, 2.05, 0.0);
  ASSERT_EQ(2u, proposals.size());
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(25, 19), cell(25, 20), cell(25, 21) }), proposals[0].cells);
  EXPECT_NEAR(2.5, proposals[0].rectangle.min_x, 1e-9);
  EXPECT_NEAR(1.9, proposals[0].rectangle.min_y, 1e-9);
  EXPECT_NEAR(2.6, proposals[0].rectangle.max_x, 1e-9);
  EXPECT_NEAR(2.2, proposals[0].rectangle.max_y, 1e-9);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(12, 20), cell(13, 21) }), proposals[1].cells);
  // Neither rectangle swallows the robot, which is what the sectors are for.
  EXPECT_FALSE(proposals[0].rectangle.withinRadius(2.05, 2.05, 0.0));
  EXPECT_FALSE(proposals[1].rectangle.withinRadius(2.05, 2.05, 0.0));
}

TEST(Clusters, ConnectedGroupsBecomeOneProposalEach)
{
  const GridGeometry g = grid40();
  const std::vector<std::uint32_t> cells = { cell(5, 5), cell(6, 6), cell(7, 7), cell(10, 5), cell(11, 5), cell(30, 30) };
  auto proposals = proposeByClusters(g, cells, 1, 1, 0.0);
  ASSERT_EQ(3u, proposals.size());
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(5, 5), cell(6, 6), cell(7, 7) }), proposals[0].cells);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(10, 5), cell(11, 5) }), proposals[1].cells);
  // A gap of 3 cells joins the first two groups; min_cells 2 drops the lone cell.
  proposals = proposeByClusters(g, cells, 3, 2, 0.0);
  ASSERT_EQ(1u, proposals.size());
  EXPECT_EQ(5u, proposals[0].cells.size());
}

TEST(Trigger, OnlyTheFirstSignalOfABurstFires)
{
  TriggerDebounce trigger(2.0);
  int fired = 0;
  for (int i = 0; i <= 50; ++i)  // 5 s stuck at 10 Hz
  {
    fired += trigger.signal(100.0 + 0.1 * i);
  }
  EXPECT_EQ(1, fired);
  EXPECT_FALSE(trigger.signal(106.9));  // 1.9 s after the last signal: same burst
  EXPECT_TRUE(trigger.signal(109.0));   // 2.1 s of silence: a new burst
  EXPECT_TRUE(trigger.signal(3.0));     // time went backwards: simulation restarted
}

TEST(StaticFilter, CellsWithinToleranceOfTheMapAreStatic)
{
  const GridGeometry g = grid40();
  std::vector<std::uint8_t> costs(g.cellCount(), FREE_SPACE);
  for (unsigned int y = 0; y < 40; ++y)
  {
    costs[cell(10, y)] = LETHAL_OBSTACLE;  // a wall along x = 10
  }
  const StaticMapFilter filter(g, costs.data(), costs.size(), 2, LETHAL_OBSTACLE);
  EXPECT_TRUE(filter.isStatic(cell(10, 5)));
  EXPECT_TRUE(filter.isStatic(cell(12, 5)));
  EXPECT_TRUE(filter.isStatic(cell(8, 39)));
  EXPECT_FALSE(filter.isStatic(cell(13, 5)));
  EXPECT_FALSE(filter.isStatic(cell(7, 0)));
  const StaticMapFilter exact(g, costs.data(), costs.size(), 0, LETHAL_OBSTACLE);
  EXPECT_TRUE(exact.isStatic(cell(10, 5)));
  EXPECT_FALSE(exact.isStatic(cell(11, 5)));
}

TEST(Shareable, NewCellsAwayFromWallsAreTrackedOnceAndDroppedWhenClearedOrOutOfRange)
{
  SharingCore core(grid40(), params());
  std::vector<std::uint8_t> costs(grid40().cellCount(), FREE_SPACE);
  for (unsigned int y = 0; y < 40; ++y)
  {
    costs[cell(10, y)] = LETHAL_OBSTACLE;
  }
  core.setStaticMap(costs.data(), costs.size());

  const Point3 origin = centre(15, 20);
  // (11, 20) is within 2 cells of the wall: never shareable. (18, 20) twice: tracked once.
  core.processScan(scan(origin, { centre(11, 22), centre(18, 20), centre(18, 20), centre(18, 24) }), 1.0);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(18, 20), cell(18, 24) }), core.shareableCells());

  // A beam through (18, 24) to a farther endpoint clears it.
  core.processScan(scan(origin, { centre(21, 29) }), 2.0);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(18, 20), cell(21, 29) }), core.shareableCells());

  // The robot drives off: cells farther than obstacle_range (2.5 m) are dropped.
  core.processScan(scan(centre(39, 0), {}), 3.0);
  EXPECT_TRUE(core.shareableCells().empty());
}

TEST(Monitoring, Figure45MovedObstacleSeenFromANewAngle)
{
  // Thesis Figure 4.5: an obstacle was shared as its west face (column 18, rows 18-22) plus one cell another
  // robot saw on its east side (28, 20). It has since moved five cells (0.5 m) east. A robot west of it now
  // sees the new west face (column 23, rows 17-22): the new face is marked at once; the old face, which the beams pass 0.5 m
  // before their endpoints (more than clearing_margin), is cleared after clearing_scans such scans; the
  // east cell, hidden behind the obstacle, is left alone.
  LayerParams p = params();
  ASSERT_EQ(3u, p.clearing_scans);
  ASSERT_EQ(1.0, p.clearing_time);
  SharingCore core(grid40(), p);
  std::vector<std::uint32_t> old_face;
  for (unsigned int y = 18; y <= 22; ++y)
  {
    old_face.push_back(cell(18, y));
  }
  std::vector<std::uint32_t> shared = old_face;
  shared.push_back(cell(28, 20));
  ASSERT_TRUE(core.applyShared(share("fig45", shared, Subsection(1.5, 1.5, 2.9, 2.5)), 0.0).ok);

  std::vector<Point3> beams;
  for (unsigned int y = 17; y <= 22; ++y)
  {
    beams.push_back(Point3{ 2.3 + 0.01, y * 0.1 + 0.05, 0.0 });
  }
  const Point3 origin{ 0.2, 1.95 + 0.05, 0.0 };
  std::vector<std::uint32_t> new_face;
  for (unsigned int y = 17; y <= 22; ++y)
  {
    new_face.push_back(cell(23, y));
  }
  ScanOutcome outcome = core.processScan(scan(origin, beams), 5.0);
  ASSERT_EQ(1u, outcome.updates.size());
  EXPECT_EQ("fig45", outcome.updates[0].uuid);
  EXPECT_EQ("robot_0", outcome.updates[0].source);
  EXPECT_EQ(2u, outcome.updates[0].version);
  EXPECT_EQ(new_face, outcome.updates[0].marked);
  EXPECT_TRUE(outcome.updates[0].cleared.empty());
  // The second scan is evidence too, but not enough yet: no update.
  EXPECT_TRUE(core.processScan(scan(origin, beams), 5.5).updates.empty());
  outcome = core.processScan(scan(origin, beams), 6.0);
  ASSERT_EQ(1u, outcome.updates.size());
  const ObstacleUpdate& update = outcome.updates[0];
  EXPECT_EQ(3u, update.version);
  EXPECT_TRUE(update.marked.empty());
  EXPECT_EQ(old_face, update.cleared);
  std::vector<std::uint32_t> expected = new_face;
  expected.push_back(cell(28, 20));
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(expected, core.sharedCells("fig45"));
  // The same scan again changes nothing: no update.
  EXPECT_TRUE(core.processScan(scan(origin, beams), 6.5).updates.empty());
}

TEST(Monitoring, ObstaclesOutOfRangeAreNotTouched)
{
  SharingCore core(grid40(), params());
  ASSERT_TRUE(core.applyShared(share("far", { cell(38, 38) }, Subsection(3.7, 3.7, 3.9, 3.9)), 0.0).ok);
  // Everything around (0.15, 0.15) is cleared out to 3 m; the obstacle is 5.2 m away.
  const ScanOutcome outcome = core.processScan(scan(centre(1, 1), { centre(39, 39), centre(38, 37) }), 1.0);
  EXPECT_TRUE(outcome.updates.empty());
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(38, 38) }), core.sharedCells("far"));
}

TEST(Monitoring, ACellMarkedInOneObstacleIsNotAnotherSideBySideInTheSameRows)
{
  // Two obstacles in the same rows, west at columns 16-21 and east at 25-29: a cell marked in east's rectangle
  // lies between west's first and last cell in index order, and must not become west's.
  SharingCore core(grid40(), params());
  ASSERT_TRUE(core.applyShared(share("west", { cell(18, 18), cell(18, 19) }, Subsection(1.6, 1.6, 2.1, 2.4)), 0.0).ok);
  ASSERT_TRUE(core.applyShared(share("east", { cell(28, 18), cell(28, 19) }, Subsection(2.5, 1.6, 3.0, 2.4)), 0.0).ok);
  const ScanOutcome outcome = core.processScan(scan(centre(27, 37), { centre(27, 20) }), 1.0);
  ASSERT_EQ(1u, outcome.updates.size());
  EXPECT_EQ("east", outcome.updates[0].uuid);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(27, 20) }), outcome.updates[0].marked);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(18, 18), cell(18, 19) }), core.sharedCells("west"));
}

TEST(Overlay, SharedCellsAreDrawnAloneAndSurviveTheObstacleReset)
{
  SharingCore core(grid40(), params());
  core.processScan(scan(centre(5, 5), { centre(8, 5) }), 0.0);
  ASSERT_TRUE(core.applyShared(share("a", { cell(30, 30), cell(31, 30) }, Subsection(2.9, 2.9, 3.3, 3.2)), 0.0).ok);
  std::vector<std::uint8_t> master(grid40().cellCount(), 7);
  master[cell(31, 30)] = NO_INFORMATION;
  core.drawShared(master.data(), master.size());
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(30, 30)]);
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(31, 30)]);
  EXPECT_EQ(7, master[cell(29, 30)]);
  EXPECT_EQ(static_cast<long>(master.size() - 2), std::count(master.begin(), master.end(), 7));

  const auto dirty = core.takeDirtyBounds();
  EXPECT_NEAR(3.0, dirty.min_x, 1e-9);
  EXPECT_NEAR(3.2, dirty.max_x, 1e-9);
  EXPECT_TRUE(core.takeDirtyBounds().empty());

  core.resetObstacleLayer();
  EXPECT_EQ(FREE_SPACE, core.obstacleGrid().at(cell(8, 5)));
  EXPECT_TRUE(core.shareableCells().empty());
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(30, 30), cell(31, 30) }), core.sharedCells("a"));
}

// costmap_2d's layer contract: updateCosts(master, min_i, min_j, max_i, max_j) writes the master only inside that
// window. Every cell outside it keeps its value, whatever is shared there; inside, shared cells are drawn.
TEST(Overlay, DrawingInAWindowWritesNothingOutsideIt)
{
  SharingCore core(grid40(), params());
  // One obstacle across the window's left edge, one wholly outside it, one inside.
  ASSERT_TRUE(core.applyShared(share("edge", { cell(9, 12), cell(10, 12), cell(11, 12) }, Subsection(0.9, 1.2, 1.2, 1.3)),
                               0.0).ok);
  ASSERT_TRUE(core.applyShared(share("out", { cell(30, 30), cell(5, 5), cell(15, 25) }, Subsection(0.5, 0.5, 3.1, 3.1)),
                               0.0).ok);
  ASSERT_TRUE(core.applyShared(share("in", { cell(12, 15) }, Subsection(1.2, 1.5, 1.3, 1.6)), 0.0).ok);
  const std::vector<std::uint8_t> before(grid40().cellCount(), 7);
  std::vector<std::uint8_t> master = before;
  core.drawShared(master.data(), master.size(), 10, 10, 20, 20);  // [10, 20) x [10, 20)
  std::size_t outside_written = 0;
  for (unsigned int y = 0; y < 40; ++y)
  {
    for (unsigned int x = 0; x < 40; ++x)
    {
      const bool inside = x >= 10 && x < 20 && y >= 10 && y < 20;
      if (!inside && master[cell(x, y)] != 7)
      {
        ++outside_written;
        ADD_FAILURE() << "cell (" << x << ", " << y << ") outside the window was written";
      }
    }
  }
  EXPECT_EQ(0u, outside_written);
  EXPECT_EQ(7, master[cell(9, 12)]);
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(10, 12)]);
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(11, 12)]);
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(12, 15)]);
  EXPECT_EQ(static_cast<long>(master.size() - 3), std::count(master.begin(), master.end(), 7));
  // Empty, inverted and off-grid windows draw nothing; a window larger than the grid is clipped to it.
  master = before;
  core.drawShared(master.data(), master.size(), 20, 20, 20, 30);
  core.drawShared(master.data(), master.size(), 30, 30, 10, 10);
  core.drawShared(master.data(), master.size(), 40, 0, 60, 40);
  EXPECT_EQ(before, master);
  core.drawShared(master.data(), master.size(), -5, -5, 50, 50);
  EXPECT_EQ(static_cast<long>(master.size() - 7), std::count(master.begin(), master.end(), 7));
}

TEST(Overlay, TheWindowsRightAndTopEdgesAreExclusive)
{
  // [10, 20) x [10, 20): column 19 and row 19 are the last inside, column 20 and row 20 the first outside.
  SharingCore core(grid40(), params());
  ASSERT_TRUE(core.applyShared(share("right", { cell(19, 15), cell(20, 15) }, Subsection(1.9, 1.5, 2.1, 1.6)), 0.0).ok);
  ASSERT_TRUE(core.applyShared(share("top", { cell(15, 19), cell(15, 20) }, Subsection(1.5, 1.9, 1.6, 2.1)), 0.0).ok);
  std::vector<std::uint8_t> master(grid40().cellCount(), 7);
  core.drawShared(master.data(), master.size(), 10, 10, 20, 20);
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(19, 15)]);
  EXPECT_EQ(7, master[cell(20, 15)]) << "column max_i is outside the window";
  EXPECT_EQ(LETHAL_OBSTACLE, master[cell(15, 19)]);
  EXPECT_EQ(7, master[cell(15, 20)]) << "row max_j is outside the window";
}

TEST(Overlay, ClearOutsideAWindowKeepsTheWindowAndSharedObstacles)
{
  // move_base's conservative reset around a robot at cell (20, 20): marks near it stay, far marks go.
  SharingCore core(grid40(), params());
  const Point3 robot = centre(20, 20);
  core.processScan(scan(robot, { centre(23, 20), centre(20, 38) }), 0.0);
  ASSERT_TRUE(core.applyShared(share("a", { cell(2, 2) }, Subsection(0.15, 0.15, 0.3, 0.3)), 0.0).ok);
  ASSERT_EQ(LETHAL_OBSTACLE, core.obstacleGrid().at(cell(20, 38)));
  ASSERT_EQ(2u, core.shareableCells().size());

  EXPECT_EQ(1u, core.clearObstaclesOutside(14, 14, 26, 26));
  EXPECT_EQ(LETHAL_OBSTACLE, core.obstacleGrid().at(cell(23, 20)));
  EXPECT_EQ(FREE_SPACE, core.obstacleGrid().at(cell(20, 38)));
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(23, 20) }), core.shareableCells());
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(2, 2) }), core.sharedCells("a"));
  // The window is open, as costmap_2d's clearArea: a mark on its border line is cleared too.
  core.processScan(scan(robot, { centre(26, 20) }), 1.0);
  EXPECT_EQ(1u, core.clearObstaclesOutside(14, 14, 26, 26));
  EXPECT_EQ(FREE_SPACE, core.obstacleGrid().at(cell(26, 20)));
}

TEST(Proposals, TriggerThenProposeFromShareableCells)
{
  SharingCore core(grid40(), params());
  const Point3 robot = centre(20, 20);
  core.processScan(scan(robot, { centre(25, 19), centre(25, 20), centre(25, 21), centre(14, 20) }), 1.0);
  EXPECT_TRUE(core.signalStuck(1.0));
  EXPECT_FALSE(core.signalStuck(1.1));
  const auto proposals = core.propose(robot.x, robot.y);
  ASSERT_EQ(2u, proposals.size());  // east and west sectors
  // Once authorised, the east cells are monitored, not proposed again.
  ObstacleUpdate authorised = share("east", proposals[0].cells, proposals[0].rectangle, 1, "robot_0");
  ASSERT_TRUE(core.applyShared(authorised, 1.2).ok);
  EXPECT_EQ((std::vector<std::uint32_t>{ cell(14, 20) }), core.shareableCells());
}
