// Fleet robots are never shared (issue 12, part 5): footprint rasterisation, validation, timeout, and the
// exclusion on every path of the core (stuck / recovery / manual triggers, trigger memory, plan trigger,
// monitoring updates).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "ascii_grid.h"
#include "sharing_layer/fleet_robots.h"
#include "sharing_layer/sharing_core.h"
#include "sim_scan.h"

using namespace sharing_layer;
using namespace sharing_layer::test;

namespace
{
using Polygon = std::vector<std::pair<double, double>>;

/// Cells whose centre lies in [x0, x1] x [y0, y1].
std::size_t countWithin(const std::vector<std::uint32_t>& cells, double x0, double y0, double x1, double y1)
{
  const GridGeometry g = grid();
  return static_cast<std::size_t>(std::count_if(cells.begin(), cells.end(), [&](std::uint32_t index) {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    return wx >= x0 && wx <= x1 && wy >= y0 && wy <= y1;
  }));
}

/// The tutorials' PR2 footprint (0.65 m square) at (x, y), axis-aligned.
Polygon square(double x, double y, double half = 0.325)
{
  return { { x - half, y - half }, { x + half, y - half }, { x + half, y + half }, { x - half, y + half } };
}

FleetRobot robot(const std::string& name, const Polygon& footprint, double stamp)
{
  FleetRobot r;
  r.name = name;
  r.footprint = footprint;
  r.stamp = stamp;
  return r;
}

/// The scene of the stuck trigger: the stuck robot at (5, 3) facing north (+y), a block 1.5 m ahead of it,
/// and a second robot (a 0.65 m square body) waiting 1.5 m to its right, inside obstacle_range.
struct Scene
{
  SimWorld world = walledWorld();
  Scene()
  {
    world.box(4.02, 4.5, 6.02, 4.8);     // the block
    world.box(6.18, 2.68, 6.82, 3.32);   // robot_1's body, centred at (6.5, 3.0)
  }
  static Polygon waitingRobot() { return square(6.5, 3.0); }
};
}  // namespace

TEST(FleetRobotsRaster, FootprintPlusMarginGolden)
{
  // 0.1 m cells; a triangle with vertices (0.2, 0.2), (1.0, 0.2), (0.2, 0.6): a cell is covered when its
  // centre lies inside or within the margin of the outline.
  const GridGeometry g(0.1, 0.0, 0.0, 12, 8);
  const Polygon triangle{ { 0.2, 0.2 }, { 1.0, 0.2 }, { 0.2, 0.6 } };
  EXPECT_EQ(picture({ "............",
                      "............",
                      "..#.........",
                      "..###.......",
                      "..#####.....",
                      "..#######...",
                      "............",
                      "............" }),
            drawCells(FleetRobots::rasterize(g, triangle, 0.0), 12, 8));
  EXPECT_EQ(picture({ "............",
                      ".##.........",
                      ".####.......",
                      ".######.....",
                      ".########...",
                      ".##########.",
                      ".##########.",
                      "............" }),
            drawCells(FleetRobots::rasterize(g, triangle, 0.1), 12, 8));
  // A single point with a margin is a disc, here clipped by the grid's east edge.
  EXPECT_EQ(picture({ "............",
                      "............",
                      "............",
                      "............",
                      "............",
                      "...........#",
                      "...........#",
                      "............" }),
            drawCells(FleetRobots::rasterize(g, { { 1.2, 0.2 } }, 0.1), 12, 8));
  EXPECT_TRUE(FleetRobots::rasterize(g, square(-5.0, -5.0), 0.2).empty());
}

TEST(FleetRobotsTable, BadRobotsAreRefusedAndChangeNothing)
{
  const GridGeometry g = grid();
  FleetRobots robots(g);
  robots.update(robot("robot_1", square(5.0, 5.0), 1.0));
  const std::vector<std::uint32_t> before = robots.excludedCells();
  ASSERT_FALSE(before.empty());
  const double nan = std::nan("");
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<FleetRobot> bad{
    robot("", square(1.0, 1.0), 1.0),                                // no name
    robot("robot_2", {}, 1.0),                                       // no vertex
    robot("robot_2", { { 1.0, nan }, { 2.0, 1.0 }, { 1.0, 2.0 } }, 1.0),
    robot("robot_2", { { inf, 1.0 }, { 2.0, 1.0 }, { 1.0, 2.0 } }, 1.0),
    robot("robot_2", square(1.0, 1.0), nan),                         // stamp
    robot("robot_2", square(5.0, 5.0, 30.0), 1.0),                   // 60 m wide: not a robot
    robot("robot_2", Polygon(kMaxFootprintPoints + 1, { 1.0, 1.0 }), 1.0),
  };
  for (const FleetRobot& r : bad)
  {
    EXPECT_THROW(robots.update(r), std::invalid_argument) << r.name;
    EXPECT_THROW(robots.replaceAll({ robot("robot_3", square(2.0, 2.0), 1.0), r }), std::invalid_argument);
    EXPECT_EQ(std::vector<std::string>{ "robot_1" }, robots.names());
    EXPECT_EQ(before, robots.excludedCells());
  }
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ -0.1, 3.0 }), std::invalid_argument);
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ nan, 3.0 }), std::invalid_argument);
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ 0.2, -1.0 }), std::invalid_argument);
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ 0.2, inf }), std::invalid_argument);
  EXPECT_THROW(robots.setParams(FleetRobotParams{ 100.0, 3.0 }), std::invalid_argument);
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ 0.2, 3.0, -0.01 }), std::invalid_argument);
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ 0.2, 3.0, nan }), std::invalid_argument);
  EXPECT_THROW(FleetRobots(g, FleetRobotParams{ 0.2, 3.0, kMaxTrail + 0.01 }), std::invalid_argument);
  EXPECT_NO_THROW(FleetRobots(g, FleetRobotParams{ 0.2, 3.0, kMaxTrail }));
  EXPECT_NO_THROW(FleetRobots(g, FleetRobotParams{ 0.2, 3.0, 0.0 }));
}

TEST(FleetRobotsTable, MovesReplacesExpiresAndOverlaps)
{
  const GridGeometry g = grid();
  FleetRobots robots(g, FleetRobotParams{ 0.2, 3.0 });
  robots.update(robot("robot_1", square(2.0, 2.0), 10.0));
  robots.update(robot("robot_2", square(2.3, 2.0), 10.0));  // overlapping footprints
  const std::uint32_t shared_cell = g.getIndex(43, 40);      // (2.175, 2.025): covered by both
  EXPECT_EQ((std::vector<std::string>{ "robot_1", "robot_2" }), robots.robotsAt(shared_cell));
  robots.forget("robot_2");
  EXPECT_TRUE(robots.excludes(shared_cell)) << "robot_1 still covers it";
  // A robot that moves leaves no trace where it stood.
  robots.update(robot("robot_1", square(7.0, 7.0), 11.0));
  EXPECT_FALSE(robots.excludes(shared_cell));
  EXPECT_EQ(FleetRobots::rasterize(g, square(7.0, 7.0), 0.2), robots.excludedCells());
  // replaceAll: the message lists the whole set.
  robots.replaceAll({ robot("robot_3", square(3.0, 3.0), 12.0) });
  EXPECT_EQ(std::vector<std::string>{ "robot_3" }, robots.names());
  EXPECT_EQ(FleetRobots::rasterize(g, square(3.0, 3.0), 0.2), robots.excludedCells());
  // Timeout: kept at exactly 3 s, forgotten after; a stamp from far in the future (clock restarted) too.
  EXPECT_TRUE(robots.expire(15.0).empty());
  EXPECT_EQ(std::vector<std::string>{ "robot_3" }, robots.expire(15.01));
  EXPECT_TRUE(robots.excludedCells().empty());
  robots.update(robot("robot_4", square(3.0, 3.0), 100.0));
  EXPECT_EQ(std::vector<std::string>{ "robot_4" }, robots.expire(1.0));
  // Timeout 0 keeps robots until they are replaced or forgotten.
  robots.setParams(FleetRobotParams{ 0.0, 0.0 });
  robots.update(robot("robot_5", square(3.0, 3.0), 1.0));
  EXPECT_TRUE(robots.expire(1e9).empty());
  EXPECT_EQ(FleetRobots::rasterize(g, square(3.0, 3.0), 0.0), robots.excludedCells());
}

TEST(FleetRobotsTable, ADrivingRobotsFrontIsCoveredUntilItsNextAdvert)
{
  // Adverts come at 2 Hz: a robot driving at 0.5 m/s is up to 0.25 m (plus transit) ahead of its last one, and
  // the cells its front covers there were shared as an obstacle in the fleet bench. The move between its last
  // two adverts is excluded once more ahead.
  // No trail here: what is behind is the next test's.
  const GridGeometry g = grid();
  FleetRobots robots(g, FleetRobotParams{ 0.2, 3.0, 0.0 });
  unsigned int mx = 0, my = 0;
  ASSERT_TRUE(g.worldToMap(3.0 + 0.325 + 0.2 + 0.1, 2.0, mx, my));  // 0.1 m beyond footprint + margin, ahead
  const std::uint32_t ahead = g.getIndex(mx, my);
  robots.replaceAll({ robot("robot_1", square(2.75, 2.0), 10.0) });
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 10.5) });  // drove 0.25 m along +x
  EXPECT_TRUE(robots.excludes(ahead)) << "the cells the robot drives into before its next advert";
  ASSERT_TRUE(g.worldToMap(3.0 - 0.325 - 0.2 - 0.1, 2.0, mx, my));
  EXPECT_FALSE(robots.excludes(g.getIndex(mx, my))) << "nothing is extrapolated backwards";
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 10.5) });  // the same advert passed on again
  EXPECT_TRUE(robots.excludes(ahead));
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 11.0) });  // a new advert: it stopped
  EXPECT_FALSE(robots.excludes(ahead));
  EXPECT_EQ(FleetRobots::rasterize(g, square(3.0, 2.0), 0.2), robots.excludedCells());
  robots.update(robot("robot_1", square(6.0, 2.0), 11.5));  // a 3 m jump (relocalised): not extrapolated
  EXPECT_EQ(FleetRobots::rasterize(g, square(6.0, 2.0), 0.2), robots.excludedCells());
}

/// The cell holding (x, y).
std::uint32_t cellAt(const GridGeometry& g, double x, double y)
{
  unsigned int mx = 0, my = 0;
  EXPECT_TRUE(g.worldToMap(x, y, mx, my));
  return g.getIndex(mx, my);
}

TEST(FleetRobotsTable, ADrivingRobotsTrailStaysExcludedForTheTrailTime)
{
  // A layer marks a scan at its next costmap update against the newest footprint: a robot driving away has
  // moved on since the scan saw its back. In the ten-robot fleet bench its back was shared 0.05-0.08 m beyond
  // footprint + margin. Each footprint holds from its stamp until the next one's, and is excluded until the
  // next one is `trail` old.
  const GridGeometry g = grid();
  FleetRobots robots(g, FleetRobotParams{ 0.2, 3.0, 1.0 });
  const std::uint32_t behind = cellAt(g, 2.0 - 0.325 - 0.2 + 0.03, 2.0);  // inside the first footprint's margin
  robots.replaceAll({ robot("robot_1", square(2.0, 2.0), 10.0) });
  robots.replaceAll({ robot("robot_1", square(2.5, 2.0), 10.5) });    // drove 0.5 m along +x
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 11.0) });
  EXPECT_TRUE(robots.excludes(behind)) << "where it was 1 s ago";
  EXPECT_TRUE(robots.excludes(cellAt(g, 2.5, 2.0)));
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 11.49) });   // stopped; the 2.0 footprint held until 10.5
  EXPECT_TRUE(robots.excludes(behind)) << "10.5 is 0.99 s before 11.49: inside the trail";
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 11.51) });
  EXPECT_FALSE(robots.excludes(behind)) << "10.5 is 1.01 s before 11.51: outside the trail";
  EXPECT_TRUE(robots.excludes(cellAt(g, 2.5 - 0.325, 2.0))) << "the 2.5 footprint held until 11.0";
  robots.replaceAll({ robot("robot_1", square(3.0, 2.0), 12.01) });
  EXPECT_EQ(FleetRobots::rasterize(g, square(3.0, 2.0), 0.2), robots.excludedCells());

  // The trail survives a new margin and a moved grid, re-rasterized; it ends with the robot.
  robots.replaceAll({ robot("robot_1", square(3.5, 2.0), 12.5) });
  robots.setParams(FleetRobotParams{ 0.1, 3.0, 1.0 });
  EXPECT_TRUE(robots.excludes(cellAt(g, 3.0 - 0.325 - 0.1 + 0.03, 2.0)));
  EXPECT_FALSE(robots.excludes(cellAt(g, 3.0 - 0.325 - 0.1 - 0.03, 2.0))) << "the old margin";
  robots.setGeometry(g);
  EXPECT_TRUE(robots.excludes(cellAt(g, 3.0 - 0.325 - 0.1 + 0.03, 2.0)));
  robots.forget("robot_1");
  robots.replaceAll({ robot("robot_1", square(3.5, 2.0), 12.6) });
  EXPECT_EQ(FleetRobots::rasterize(g, square(3.5, 2.0), 0.1), robots.excludedCells()) << "forgotten with it";
  robots.replaceAll({ robot("robot_1", square(4.0, 2.0), 12.7) });
  robots.replaceAll({});
  robots.replaceAll({ robot("robot_1", square(4.0, 2.0), 12.8) });
  EXPECT_EQ(FleetRobots::rasterize(g, square(4.0, 2.0), 0.1), robots.excludedCells()) << "left the message";
}

TEST(FleetRobotsTable, TrailEndsAtAJumpAClockGoingBackAndItsLength)
{
  const GridGeometry g = grid();
  FleetRobots robots(g, FleetRobotParams{ 0.2, 3.0, 1.0 });
  robots.update(robot("robot_1", square(2.0, 2.0), 10.0));
  robots.update(robot("robot_1", square(4.1, 2.0), 10.1));  // 2.1 m in 0.1 s: relocalised, not driven
  EXPECT_EQ(FleetRobots::rasterize(g, square(4.1, 2.0), 0.2), robots.excludedCells());
  robots.update(robot("robot_1", square(4.3, 2.0), 10.2));  // 0.2 m (within 2 m): driven
  robots.update(robot("robot_1", square(4.3, 2.0), 9.0));   // a restarted simulation
  EXPECT_EQ(FleetRobots::rasterize(g, square(4.3, 2.0), 0.2), robots.excludedCells());

  // At most kMaxTrailFootprints footprints, the current one among them, however long the trail (0.1 m per 0.05 s,
  // 2 m/s: one trail).
  FleetRobots longTrail(g, FleetRobotParams{ 0.2, 3.0, kMaxTrail });
  const std::uint32_t first = cellAt(g, 1.0 - 0.325 - 0.2 + 0.03, 2.0);
  longTrail.update(robot("robot_2", square(1.0, 2.0), 20.0));
  for (std::size_t i = 1; i < kMaxTrailFootprints; ++i)
  {
    longTrail.update(robot("robot_2", square(1.0 + 0.1 * i, 2.0), 20.0 + 0.05 * i));
  }
  EXPECT_TRUE(longTrail.excludes(first)) << kMaxTrailFootprints << " footprints kept";
  longTrail.update(robot("robot_2", square(1.0 + 0.1 * kMaxTrailFootprints, 2.0), 20.0 + 0.05 * kMaxTrailFootprints));
  EXPECT_FALSE(longTrail.excludes(first)) << "one more: the first dropped";

  // Trail 0: a robot that moves leaves nothing behind (the exclusion before the trail).
  FleetRobots none(g, FleetRobotParams{ 0.2, 3.0, 0.0 });
  none.update(robot("robot_1", square(2.0, 2.0), 10.0));
  none.update(robot("robot_1", square(2.5, 2.0), 10.5));
  EXPECT_FALSE(none.excludes(cellAt(g, 2.0 - 0.325 - 0.2 + 0.03, 2.0)));
}

TEST(FleetRobotsTable, TrailEndsAtAStepNoRobotDrives)
{
  // A peer's login does not make its footprint true: one whose adverts race about must not leave a trail along
  // the path it made up. A footprint farther from a kept one than kMaxTrailSpeed allows in the time between them
  // (plus kTrailSlack) starts the trail anew.
  const GridGeometry g = grid();
  FleetRobots robots(g, FleetRobotParams{ 0.2, 3.0, 1.0 });
  const double reach = kMaxTrailSpeed * 0.2 + kTrailSlack;  // 0.2 s after the first footprint
  const std::uint32_t behind = cellAt(g, 1.0 - 0.325 - 0.2 + 0.03, 2.0);
  robots.update(robot("robot_1", square(1.0, 2.0), 10.0));
  robots.update(robot("robot_1", square(1.0 + reach - 0.01, 2.0), 10.2));
  EXPECT_TRUE(robots.excludes(behind)) << "just inside what a robot drives in 0.2 s";
  robots.update(robot("robot_2", square(1.0, 5.0), 10.0));
  robots.update(robot("robot_2", square(1.0 + reach + 0.01, 5.0), 10.2));
  EXPECT_FALSE(robots.excludes(cellAt(g, 1.0 - 0.325 - 0.2 + 0.03, 5.0))) << "just outside: the trail starts anew";
  EXPECT_TRUE(robots.excludes(cellAt(g, 1.0 + reach + 0.01, 5.0))) << "where it is now stays excluded";

  // Against every footprint kept, not only the last: the slack does not add up over steps with no time between.
  robots.update(robot("robot_3", square(1.0, 8.0), 10.0));
  robots.update(robot("robot_3", square(1.0 + 0.45, 8.0), 10.0));
  EXPECT_TRUE(robots.excludes(cellAt(g, 1.0 - 0.325 - 0.2 + 0.03, 8.0))) << "0.45 m: within the slack";
  robots.update(robot("robot_3", square(1.0 + 0.9, 8.0), 10.0));
  EXPECT_FALSE(robots.excludes(cellAt(g, 1.0 - 0.325 - 0.2 + 0.03, 8.0))) << "0.9 m from the first in no time";
  EXPECT_FALSE(robots.excludes(cellAt(g, 1.45 - 0.325 - 0.2 + 0.03, 8.0))) << "0.45 m from the last, but one trail";
}

TEST(FleetRobotsTable, TrailCellsAreTheUnionOfItsFootprints)
{
  // The trail's cells are gathered through a bit per cell over the rows it spans, or sorted when those rows
  // are far apart (a wide grid, a robot driving along y): both must give the plain union.
  for (const GridGeometry& g : { grid(), GridGeometry(0.05, 0.0, 0.0, 20000, 200) })
  {
    FleetRobots robots(g, FleetRobotParams{ 0.2, 3.0, 1.0 });
    std::vector<Polygon> held;
    for (int k = 0; k < 12; ++k)
    {
      const Polygon now = square(2.0 + 0.02 * k, 2.0 + 0.13 * k);
      robots.update(robot("robot_1", now, 10.0 + 0.1 * k + (k == 11 ? 0.05 : 0.0)));
      held.push_back(now);
    }
    // Stamps 10.0 .. 11.0, then 11.15: the footprint of 10.0 held until 10.1, 1.05 s before: dropped.
    std::vector<std::uint32_t> expected;
    for (std::size_t k = 1; k < held.size(); ++k)
    {
      const std::vector<std::uint32_t> cells = FleetRobots::rasterize(g, held[k], 0.2);
      expected.insert(expected.end(), cells.begin(), cells.end());
    }
    Polygon ahead = held.back();
    for (auto& p : ahead)
    {
      p.first += 0.02;
      p.second += 0.13;
    }
    const std::vector<std::uint32_t> more = FleetRobots::rasterize(g, ahead, 0.2);
    expected.insert(expected.end(), more.begin(), more.end());
    std::sort(expected.begin(), expected.end());
    expected.erase(std::unique(expected.begin(), expected.end()), expected.end());
    EXPECT_EQ(expected, robots.excludedCells()) << "grid " << g.size_x << " x " << g.size_y;
  }
}

TEST(FleetRobotsCore, StuckTriggerDoesNotShareAWaitingRobot)
{
  Scene scene;
  // Without knowing robot_1, the stuck robot shares it with the block: this test can fail.
  {
    SharingCore plain = makeCore();
    plain.processScan(scene.world.scan(5.0, 3.0, M_PI / 2), 1.0);
    const TriggerReport report = plain.trigger(TriggerSource::StuckFeedback, 1.05, 5.0, 3.0);
    ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
    EXPECT_GT(countWithin(allCells(report.proposals), 6.1, 2.6, 6.9, 3.4), 0u) << "robot_1 was not seen";
  }
  SharingCore core = makeCore();
  double now = 1.0;
  for (TriggerSource source : { TriggerSource::StuckFeedback, TriggerSource::RecoveryStatus, TriggerSource::Manual })
  {
    core.fleetRobots().update(robot("robot_1", Scene::waitingRobot(), now));  // its bridge's latest advert
    core.processScan(scene.world.scan(5.0, 3.0, M_PI / 2), now);
    EXPECT_EQ(0u, countWithin(core.shareableCells(), 6.1, 2.6, 6.9, 3.4));
    EXPECT_EQ(0u, countWithin(core.rememberedCells(), 6.1, 2.6, 6.9, 3.4));
    const TriggerReport report = core.trigger(source, now + 0.05, 5.0, 3.0);
    ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
    const std::vector<std::uint32_t> cells = allCells(report.proposals);
    EXPECT_EQ(0u, countWithin(cells, 6.1, 2.6, 6.9, 3.4)) << triggerSourceName(source) << ": robot_1 shared";
    EXPECT_EQ(cells.size(), countWithin(cells, 4.0, 4.45, 6.05, 4.85)) << "only the block";
    EXPECT_GT(cells.size(), 20u);
    now += 3.0;  // past trigger_debounce
  }
}

TEST(FleetRobotsCore, OnlyARobotInViewSaysSoAndTheTimeoutForgetsIt)
{
  SimWorld world = walledWorld();
  world.box(6.18, 2.68, 6.82, 3.32);  // robot_1's body, nothing else
  SharingCore core = makeCore();
  core.fleetRobots().update(robot("robot_1", square(6.5, 3.0), 1.0));
  core.processScan(world.scan(5.0, 3.0, M_PI / 2), 1.0);
  const TriggerReport report = core.trigger(TriggerSource::Manual, 1.1, 5.0, 3.0);
  EXPECT_EQ(TriggerReason::FleetRobot, report.reason) << report.message;
  EXPECT_TRUE(report.proposals.empty());
  EXPECT_NE(report.message.find("robot_1"), std::string::npos) << report.message;
  EXPECT_STREQ("fleet_robot", triggerReasonName(report.reason));

  // robot_1's bridge stops advertising: 3 s later the layer forgets it, and the body is an obstacle again
  // (an unknown thing standing there, as it would be for a robot outside the fleet).
  core.processScan(world.scan(5.0, 3.0, M_PI / 2), 4.0);
  EXPECT_EQ(1u, core.fleetRobots().size());
  core.processScan(world.scan(5.0, 3.0, M_PI / 2), 4.2);
  EXPECT_TRUE(core.fleetRobots().empty());
  EXPECT_GT(countWithin(core.shareableCells(), 6.1, 2.6, 6.9, 3.4), 0u);
  const TriggerReport later = core.trigger(TriggerSource::Manual, 4.3, 5.0, 3.0);
  EXPECT_EQ(TriggerReason::Proposed, later.reason) << later.message;
}

TEST(FleetRobotsCore, TrailOfADepartedRobotIsNotProposedFromMemory)
{
  // robot_1 stands 1.5 m to the right, then drives out of view while the stuck robot backs off; a late
  // recovery_status trigger uses the trigger memory, which must not hold robot_1's old cells.
  SimWorld world = walledWorld();
  world.box(4.02, 4.5, 6.02, 4.8);
  world.box(6.18, 2.68, 6.82, 3.32);
  SharingCore core = makeCore();
  core.fleetRobots().update(robot("robot_1", square(6.5, 3.0), 1.0));
  core.processScan(world.scan(5.0, 3.0, M_PI / 2), 1.0);
  world.box(6.18, 2.68, 6.82, 3.32, 0);  // robot_1 leaves
  core.fleetRobots().update(robot("robot_1", square(9.0, 9.0), 1.5));
  core.processScan(world.scan(5.0, 1.0, M_PI / 2), 2.0);  // backed off 2 m; the block is now beyond 2.5 m
  const TriggerReport report = core.trigger(TriggerSource::RecoveryStatus, 2.1, 5.0, 1.0);
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  EXPECT_EQ(0u, countWithin(allCells(report.proposals), 6.1, 2.6, 6.9, 3.4)) << report.message;
  EXPECT_GT(countWithin(allCells(report.proposals), 4.0, 4.45, 6.05, 4.85), 0u) << report.message;
}

TEST(FleetRobotsCore, RobotOnThePlanDoesNotFireThePlanTrigger)
{
  // The plan runs north from (5, 1) through where robot_1 waits at (5, 3.5).
  SimWorld world = walledWorld();
  world.box(4.68, 3.18, 5.32, 3.82);
  std::vector<std::pair<double, double>> plan;
  for (int i = 0; i <= 160; ++i)
  {
    plan.emplace_back(5.0, 1.0 + 0.05 * i);
  }
  const auto drive = [&](SharingCore& core, bool advertised) {
    core.setPlan(plan);
    TriggerReport report;
    double now = 1.0;
    for (double y = 0.6; y < 1.6; y += 0.05)
    {
      core.processScan(world.scan(5.0, y, M_PI / 2), now += 0.1);
      report = core.checkPlan(5.0, y, now);
      if (report.reason != TriggerReason::None)
      {
        break;
      }
      if (advertised)
      {
        core.fleetRobots().update(robot("robot_1", square(5.0, 3.5), now));
      }
    }
    return report;
  };
  SharingCore plain = makeCore();
  EXPECT_EQ(TriggerReason::Proposed, drive(plain, false).reason) << "without exclusion robot_1 blocks the plan";
  SharingCore core = makeCore();
  core.fleetRobots().update(robot("robot_1", square(5.0, 3.5), 1.0));
  const TriggerReport report = drive(core, true);
  EXPECT_EQ(TriggerReason::None, report.reason) << report.message;
}

TEST(FleetRobotsCore, MonitoringUpdatesDoNotMarkARobotInsideASharedRectangle)
{
  // A shared obstacle's rectangle covers the block and the space in front of it, where robot_1 now waits.
  SimWorld world = walledWorld();
  world.box(4.02, 4.5, 6.02, 4.8);
  world.box(5.18, 3.68, 5.82, 4.32);  // robot_1, centred at (5.5, 4.0), inside the rectangle
  const GridGeometry g = grid();
  const auto apply = [&](SharingCore& core) {
    ASSERT_TRUE(
        core.applyShared(sharedUpdate("block", { g.getIndex(100, 92) }, Subsection(3.9, 3.5, 6.1, 4.9), 1, "robot_2"), 1.0)
            .ok);
  };
  const auto marked = [&](SharingCore& core) {
    std::vector<std::uint32_t> cells;
    for (int i = 0; i < 3; ++i)
    {
      for (const ObstacleUpdate& update : core.processScan(world.scan(5.0, 2.6, M_PI / 2), 2.0 + 0.1 * i).updates)
      {
        cells.insert(cells.end(), update.marked.begin(), update.marked.end());
      }
    }
    return cells;
  };
  SharingCore plain = makeCore();
  apply(plain);
  EXPECT_GT(countWithin(marked(plain), 5.1, 3.6, 5.9, 4.4), 0u) << "without exclusion robot_1 is marked";
  SharingCore core = makeCore();
  apply(core);
  core.fleetRobots().update(robot("robot_1", square(5.5, 4.0), 2.0));
  const std::vector<std::uint32_t> cells = marked(core);
  EXPECT_EQ(0u, countWithin(cells, 5.1, 3.6, 5.9, 4.4));
  EXPECT_GT(countWithin(cells, 4.0, 4.45, 6.05, 4.85), 0u) << "the block's visible face is still marked";
}
