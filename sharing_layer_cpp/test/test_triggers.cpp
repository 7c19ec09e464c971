// Unknown map cells (issue 12 B), trigger memory (C), the plan-blocked trigger and trigger reasons (D).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/sharing_core.h"
#include "sim_scan.h"

using namespace sharing_layer;
using namespace sharing_layer::test;

namespace
{
/// Whether every cell lies in the world rectangle [x0, x1] x [y0, y1] (cell centres).
bool allWithin(const std::vector<std::uint32_t>& cells, double x0, double y0, double x1, double y1)
{
  const GridGeometry g = grid();
  return std::all_of(cells.begin(), cells.end(), [&](std::uint32_t index) {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    return wx >= x0 && wx <= x1 && wy >= y0 && wy <= y1;
  });
}

/// A straight plan at 5 cm spacing.
std::vector<std::pair<double, double>> line(double x0, double y0, double x1, double y1)
{
  std::vector<std::pair<double, double>> poses;
  const int n = static_cast<int>(std::hypot(x1 - x0, y1 - y0) / 0.05);
  for (int i = 0; i <= n; ++i)
  {
    poses.emplace_back(x0 + (x1 - x0) * i / n, y0 + (y1 - y0) * i / n);
  }
  return poses;
}
}  // namespace

// --- B: unknown map cells -------------------------------------------------------------------------------

TEST(UnknownMap, CellsInOrNearUnknownMapAreasAreNeverShared)
{
  // A wall stands in an area the map does not know (x >= 7: grey in the map), and a crate stands in a known
  // free area. Only the crate may be shared, in proposals and in monitoring updates.
  SimWorld world = walledWorld();
  world.box(7.12, 3.0, 7.32, 7.0);  // the unmapped wall, 0.12 m inside the unknown area
  world.box(5.52, 4.8, 5.72, 5.2);  // the crate
  SharingCore core = makeCore();
  const GridGeometry g = grid();
  std::vector<std::uint8_t> unknown(g.cellCount(), 0);
  for (unsigned int y = 0; y < g.size_y; ++y)
  {
    for (unsigned int x = 140; x < g.size_x; ++x)  // x >= 7.0 m
    {
      unknown[g.getIndex(x, y)] = 1;
    }
  }
  core.setUnknownMap(unknown.data(), unknown.size());

  core.processScan(world.scan(5.0, 5.0, 0.0), 1.0);
  core.processScan(world.scan(5.5, 4.0, 0.0), 1.1);  // the unmapped wall comes within obstacle_range
  const std::vector<std::uint32_t> shareable = core.shareableCells();
  ASSERT_FALSE(shareable.empty());
  EXPECT_TRUE(allWithin(shareable, 5.4, 4.7, 5.8, 5.3)) << "only the crate is shareable";
  const TriggerReport report = core.trigger(TriggerSource::StuckFeedback, 1.2, 5.5, 4.0);
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  EXPECT_TRUE(allWithin(allCells(report.proposals), 5.4, 4.7, 5.8, 5.3)) << report.message;
  EXPECT_TRUE(allWithin(core.rememberedCells(), 5.4, 4.7, 5.8, 5.3));

  // Without the unknown mask the unmapped wall would be shared: the test above can fail.
  SharingCore plain = makeCore();
  plain.processScan(world.scan(5.0, 5.0, 0.0), 1.0);
  plain.processScan(world.scan(5.5, 4.0, 0.0), 1.1);
  EXPECT_FALSE(allWithin(plain.shareableCells(), 5.4, 4.7, 5.8, 5.3));

  // Monitoring: a shared obstacle whose rectangle reaches into the unknown area gets no cells there.
  ASSERT_TRUE(core.applyShared(sharedUpdate("wide", { g.getIndex(131, 60) }, Subsection(6.5, 3.0, 7.5, 7.0)), 2.0).ok);
  for (int i = 0; i < 3; ++i)
  {
    for (const ObstacleUpdate& update : core.processScan(world.scan(6.2, 5.0, 0.0), 2.1 + i).updates)
    {
      EXPECT_TRUE(update.marked.empty()) << "marked " << update.marked.size() << " cells of the unmapped wall";
    }
  }
}

TEST(UnknownMap, ToleranceAroundUnknownAndSizeChecks)
{
  SharingCore core(grid(), defaults());  // static_tolerance 3
  const GridGeometry g = grid();
  std::vector<std::uint8_t> unknown(g.cellCount(), 0);
  unknown[g.getIndex(100, 100)] = 1;
  core.setUnknownMap(unknown.data(), unknown.size());
  Observation obs;
  obs.origin = Point3{ 4.0, 5.0, 0.3 };
  for (unsigned int x = 98; x <= 106; ++x)
  {
    obs.points.push_back(Point3{ x * 0.05 + 0.025, 5.025, 0.3 });
  }
  core.processScan(obs, 1.0);
  // Cells 98..103 are within 3 cells of the unknown cell 100; 104..106 are shareable.
  ASSERT_EQ(3, defaults().static_tolerance);
  std::vector<std::uint32_t> expected;
  for (unsigned int x = 104; x <= 106; ++x)
  {
    expected.push_back(g.getIndex(x, 100));
  }
  EXPECT_EQ(expected, core.shareableCells());
  EXPECT_THROW(core.setUnknownMap(unknown.data(), unknown.size() - 1), std::invalid_argument);
  core.setUnknownMap(nullptr, 0);  // forgotten: nothing is static any more
  core.processScan(obs, 2.0);
  EXPECT_EQ(9u, core.shareableCells().size());
}

// --- C: trigger memory ------------------------------------------------------------------------------------

TEST(TriggerMemory, LateTriggerAfterBackingOffProposesTheBlock)
{
  // A block closes the way 1.4 m ahead; the robot fails, backs off 2.4 m (the block is then 3.8 m away,
  // beyond obstacle_range), and only then does recovery_status come.
  SimWorld world = walledWorld();
  world.box(5.02, 4.0, 5.32, 6.0);
  SharingCore core = makeCore();
  double now = 1.0;
  for (double x = 3.0; x <= 3.6; x += 0.05)
  {
    core.processScan(world.scan(x, 5.0, 0.0), now += 0.1);
  }
  for (double x = 3.6; x >= 1.2; x -= 0.05)
  {
    core.processScan(world.scan(x, 5.0, 0.0), now += 0.1);
  }
  EXPECT_TRUE(core.shareableCells().empty()) << "beyond obstacle_range: the thesis rule has nothing left";
  const TriggerReport report = core.trigger(TriggerSource::RecoveryStatus, now, 1.2, 5.0);
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  const std::vector<std::uint32_t> cells = allCells(report.proposals);
  EXPECT_GE(cells.size(), 30u);  // the 2 m face is 40 cells
  EXPECT_TRUE(allWithin(cells, 5.0, 4.0, 5.1, 6.0)) << report.message;
  EXPECT_NE(report.message.find("recovery_status"), std::string::npos) << report.message;
  EXPECT_TRUE(report.log);

  // With no memory the same late trigger proposes nothing, and says why.
  LayerParams p = defaults();
  p.trigger_memory = 0.0;
  SharingCore forgetful = makeCore(p);
  now = 1.0;
  for (double x = 3.0; x <= 3.6; x += 0.05)
  {
    forgetful.processScan(world.scan(x, 5.0, 0.0), now += 0.1);
  }
  for (double x = 3.6; x >= 1.2; x -= 0.05)
  {
    forgetful.processScan(world.scan(x, 5.0, 0.0), now += 0.1);
  }
  const TriggerReport nothing = forgetful.trigger(TriggerSource::RecoveryStatus, now, 1.2, 5.0);
  EXPECT_TRUE(nothing.proposals.empty());
  EXPECT_NE(TriggerReason::Proposed, nothing.reason);
}

TEST(TriggerMemory, CellsAreForgottenAfterTriggerMemoryOrBeyondTriggerRadius)
{
  SimWorld world = walledWorld();
  world.box(5.02, 4.0, 5.32, 6.0);
  LayerParams p = defaults();
  p.trigger_memory = 5.0;
  p.trigger_radius = 3.0;
  SharingCore core = makeCore(p);
  core.processScan(world.scan(3.6, 5.0, 0.0), 1.0);
  ASSERT_FALSE(core.rememberedCells().empty());
  // 3.5 m away: remembered, but beyond trigger_radius.
  core.processScan(world.scan(1.5, 5.0, 0.0), 2.0);
  TriggerReport report = core.trigger(TriggerSource::RecoveryStatus, 2.0, 1.5, 5.0);
  EXPECT_EQ(TriggerReason::OutOfRange, report.reason) << report.message;
  EXPECT_NE(report.message.find("trigger_radius"), std::string::npos) << report.message;
  // 2.5 m away but 6 s later: forgotten (the scan, facing the west wall, marks only the wall).
  core.processScan(world.scan(2.52, 5.0, 3.14159), 7.5);
  EXPECT_TRUE(core.rememberedCells().empty());
  report = core.trigger(TriggerSource::RecoveryStatus, 7.5, 2.52, 5.0);
  EXPECT_EQ(TriggerReason::Static, report.reason) << report.message;
  // Nothing in range at all.
  core.processScan(world.scan(5.0, 8.0, 0.0, 0.0, 0.0, 0.0, 1.0), 8.0);  // a 1 m laser sees nothing
  report = core.trigger(TriggerSource::RecoveryStatus, 20.0, 5.0, 8.0);
  EXPECT_EQ(TriggerReason::NothingMarked, report.reason) << report.message;
}

TEST(TriggerMemory, StuckFeedbackKeepsTheCurrentViewSoABystanderIsNotShared)
{
  // Thesis Test 3's start: another robot waits 1.4 m beside this one. This robot drives off and gets stuck at
  // a block 3.8 m from the waiting robot; stuck_feedback comes at once, with the block in view. Only the block
  // is proposed; the waiting robot, remembered from the start, is not (unless memory_on_stuck_feedback).
  SimWorld world = walledWorld();
  world.box(6.25, 1.75, 6.75, 2.25);  // the waiting robot
  world.box(3.0, 4.8, 5.0, 5.1);      // the block across the corridor
  for (bool memory : { false, true })
  {
    LayerParams p = defaults();
    p.memory_on_stuck_feedback = memory;
    SharingCore core = makeCore(p);
    double now = 1.0;
    for (double t = 0.0; t <= 1.0; t += 0.05)  // from (5.0, 2.0) to (4.0, 3.9), facing the block
    {
      core.processScan(world.scan(5.0 - t, 2.0 + 1.9 * t, 1.5708), now += 0.1);
    }
    const TriggerReport report = core.trigger(TriggerSource::StuckFeedback, now, 4.0, 3.9);
    ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
    // Without the memory only the block; with it the waiting robot comes in too (the test can fail).
    EXPECT_EQ(!memory, allWithin(allCells(report.proposals), 3.0, 4.75, 5.0, 5.15))
        << "memory_on_stuck_feedback " << memory << ": " << report.message;
  }
}

TEST(TriggerMemory, RemovedObstacleLeavesTheMemoryOnEvidence)
{
  SimWorld world = walledWorld();
  world.box(5.02, 4.0, 5.32, 6.0);
  SharingCore core = makeCore();
  core.processScan(world.scan(3.6, 5.0, 0.0), 1.0);
  ASSERT_FALSE(core.rememberedCells().empty());
  world.box(5.02, 4.0, 5.32, 6.0, 0);
  for (double t : { 2.0, 2.5, 3.0 })
  {
    core.processScan(world.scan(3.6, 5.0, 0.0), t);
  }
  EXPECT_TRUE(core.rememberedCells().empty());
  const TriggerReport report = core.trigger(TriggerSource::StuckFeedback, 3.0, 3.6, 5.0);
  EXPECT_TRUE(report.proposals.empty()) << report.message;
}

TEST(TriggerMemory, CellsRememberedByLaterScansBelowEarlierOnesAreFoundAndForgotten)
{
  // The memory is kept sorted and walked along each scan's sorted lists: cells a later scan adds below, between and
  // above the remembered ones must all be found again, by findRemembered and by the evidence that forgets them.
  CellFlags flags;
  flags.assign(100);
  ObservedCells observed;
  const ScanTouch no_touch;
  const unsigned int clearing_scans = 2;
  const double clearing_time = 0.5, trigger_memory = 10.0;
  observed.remember(no_touch, { 50, 60 }, {}, 1.0f, 2.0f, 1.0, trigger_memory, clearing_scans, clearing_time, flags);
  observed.remember(no_touch, { 10, 55, 70 }, {}, 3.0f, 4.0f, 1.1, trigger_memory, clearing_scans, clearing_time,
                    flags);
  EXPECT_EQ((std::vector<std::uint32_t>{ 10, 50, 55, 60, 70 }), observed.rememberedSorted());
  for (std::uint32_t index : { 10u, 50u, 55u, 60u, 70u })
  {
    const RememberedCell* cell = observed.findRemembered(index, flags);
    ASSERT_NE(nullptr, cell) << "cell " << index;
    EXPECT_EQ(index == 50 || index == 60 ? 1.0f : 3.0f, cell->sensor_x) << "cell " << index;
    EXPECT_TRUE(flags.has(index, CellFlags::kRemembered)) << "cell " << index;
  }
  EXPECT_EQ(nullptr, observed.findRemembered(11, flags));
  // Seen free in two scans over clearing_time: 10 and 60 are forgotten, the rest stay.
  ScanTouch free_10_60;
  free_10_60.watched_free = { 10, 60 };
  for (double t : { 2.0, 3.0 })
  {
    observed.remember(free_10_60, {}, {}, 0.0f, 0.0f, t, trigger_memory, clearing_scans, clearing_time, flags);
  }
  EXPECT_EQ((std::vector<std::uint32_t>{ 50, 55, 70 }), observed.rememberedSorted());
  EXPECT_FALSE(flags.has(10, CellFlags::kRemembered));
  EXPECT_FALSE(flags.has(60, CellFlags::kRemembered));
  EXPECT_EQ(nullptr, observed.findRemembered(60, flags));
  ASSERT_NE(nullptr, observed.findRemembered(70, flags));
}

TEST(TriggerMemory, OntoAnotherGridTheNewestOfTwoCellsLandingOnOneWins)
{
  CellFlags flags;
  flags.assign(100);
  ObservedCells observed;
  const ScanTouch no_touch;
  observed.remember(no_touch, { 10, 20 }, {}, 1.0f, 0.0f, 1.0, 10.0, 2, 0.5, flags);
  observed.remember(no_touch, { 11 }, {}, 2.0f, 0.0f, 2.0, 10.0, 2, 0.5, flags);
  // 10 and 11 land on cell 5 of the new grid (the older of them first, by index); 20 falls off it.
  const auto mover = [](std::uint32_t index, std::uint32_t& moved) {
    moved = 5;
    return index != 20;
  };
  CellFlags new_flags;
  new_flags.assign(50);
  observed.moveTo(mover, false, new_flags);
  EXPECT_EQ((std::vector<std::uint32_t>{ 5 }), observed.rememberedSorted());
  const RememberedCell* cell = observed.findRemembered(5, new_flags);
  ASSERT_NE(nullptr, cell);
  EXPECT_EQ(2.0, cell->time);
  EXPECT_EQ(2.0f, cell->sensor_x);
}

// --- trigger reasons ----------------------------------------------------------------------------------------

TEST(TriggerReasons, DebouncedStaticAndAlreadyShared)
{
  SimWorld world = walledWorld();
  SharingCore core = makeCore();
  // Only the outer wall in range: static.
  core.processScan(world.scan(1.0, 1.0, 3.14159), 1.0);
  TriggerReport report = core.trigger(TriggerSource::StuckFeedback, 1.0, 1.0, 1.0);
  EXPECT_EQ(TriggerReason::Static, report.reason) << report.message;
  EXPECT_TRUE(report.log);
  // The 10 Hz repeats of the same failure: debounced, logged once per burst.
  report = core.trigger(TriggerSource::StuckFeedback, 1.1, 1.0, 1.0);
  EXPECT_EQ(TriggerReason::Debounced, report.reason);
  EXPECT_TRUE(report.log);
  report = core.trigger(TriggerSource::RecoveryStatus, 1.2, 1.0, 1.0);
  EXPECT_EQ(TriggerReason::Debounced, report.reason);
  EXPECT_FALSE(report.log);
  EXPECT_NE(report.message.find("recovery_status"), std::string::npos);

  // A block, shared: a later trigger near it has nothing new.
  world.box(3.02, 4.0, 3.32, 6.0);
  core.processScan(world.scan(2.0, 5.0, 0.0), 10.0);
  report = core.trigger(TriggerSource::StuckFeedback, 10.0, 2.0, 5.0);
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  ASSERT_EQ(1u, report.proposals.size());
  ASSERT_TRUE(core.applyShared(
                      sharedUpdate("block", report.proposals[0].cells, report.proposals[0].rectangle, 1, "robot_0"), 10.0)
                  .ok);
  core.processScan(world.scan(2.0, 5.0, 0.0), 20.0);
  report = core.trigger(TriggerSource::StuckFeedback, 20.0, 2.0, 5.0);
  EXPECT_EQ(TriggerReason::AlreadyShared, report.reason) << report.message;
  EXPECT_TRUE(report.proposals.empty());

  EXPECT_EQ(std::string("already_shared"), triggerReasonName(TriggerReason::AlreadyShared));
  EXPECT_EQ(TriggerSource::PlanBlocked, parseTriggerSource("plan_blocked"));
  EXPECT_THROW(parseTriggerSource("bogus"), std::invalid_argument);
  // Bad input: a non-finite pose is ignored with a message, not a crash.
  report = core.trigger(TriggerSource::StuckFeedback, 30.0, std::nan(""), 5.0);
  EXPECT_TRUE(report.proposals.empty());
  EXPECT_NE(report.message.find("not finite"), std::string::npos);
}

// --- D: plan-blocked trigger ------------------------------------------------------------------------------

// The dead-end world, five robots, seed 2, sharing on: NavfnROS cut robot_1's 36 m detour at 1,280 half-cell steps,
// so its plan began at (14.02, 1.96), 1.37 m from the robot at (15.0, 1.0), and went left from there.
TEST(PlanReach, APlanCutShortBeforeTheRobotIsOutOfTheLocalPlannersReach)
{
  std::vector<std::pair<double, double>> cut;
  for (double x = 14.02; x > 2.0; x -= 0.05)
  {
    cut.emplace_back(x, 1.96);
  }
  EXPECT_NEAR(nearestPlanDistance(cut, 15.0, 1.0), std::hypot(0.98, 0.96), 1e-9);
  EXPECT_TRUE(outOfLocalPlannerReach(nearestPlanDistance(cut, 15.0, 1.0)));
  std::vector<std::pair<double, double>> whole = {{15.0, 1.0}, {14.5, 1.5}};
  whole.insert(whole.end(), cut.begin(), cut.end());
  EXPECT_DOUBLE_EQ(nearestPlanDistance(whole, 15.0, 1.0), 0.0);
  EXPECT_FALSE(outOfLocalPlannerReach(nearestPlanDistance(whole, 15.0, 1.0)));
}

TEST(PlanReach, TheReachIsOneMetreAndPosesThatAreNotFiniteDoNotCount)
{
  EXPECT_FALSE(outOfLocalPlannerReach(kLocalPlannerPlanReach));         // just inside: base_local_planner keeps it
  EXPECT_TRUE(outOfLocalPlannerReach(kLocalPlannerPlanReach + 1e-6));   // just outside
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(std::isinf(nearestPlanDistance({}, 0.0, 0.0)));
  EXPECT_TRUE(std::isinf(nearestPlanDistance({{nan, 0.0}, {0.0, std::numeric_limits<double>::infinity()}}, 0.0, 0.0)));
  EXPECT_DOUBLE_EQ(nearestPlanDistance({{nan, 0.0}, {3.0, 4.0}, {6.0, 8.0}}, 0.0, 0.0), 5.0);
}

TEST(PlanTrigger, NewCellsOnThePlanAheadProposeTheClusterOnThePlan)
{
  // The plan runs east along y = 5 through a block; a crate stands beside the plan (0.6 m off it).
  SimWorld world = walledWorld();
  world.box(5.02, 4.6, 5.32, 5.4);   // on the plan
  world.box(4.02, 5.9, 4.22, 6.1);   // beside it
  SharingCore core = makeCore();
  core.setPlan(line(1.0, 5.0, 9.0, 5.0));
  double now = 1.0;
  TriggerReport report;
  double x = 1.0;
  // Driving along the plan: nothing until the block comes within obstacle_range.
  for (; x < 4.0; x += 0.05)
  {
    core.processScan(world.scan(x, 5.0, 0.0), now += 0.1);
    report = core.checkPlan(x, 5.0, now);
    if (report.reason != TriggerReason::None)
    {
      break;
    }
  }
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
  EXPECT_EQ(TriggerSource::PlanBlocked, report.source);
  EXPECT_TRUE(report.log);
  EXPECT_GE(x, 5.02 - 2.5 - 0.1);  // the block was marked within obstacle_range
  ASSERT_EQ(1u, report.proposals.size()) << report.message;
  EXPECT_TRUE(allWithin(report.proposals[0].cells, 5.0, 4.6, 5.35, 5.4)) << report.message;
  EXPECT_NE(report.message.find("plan_blocked"), std::string::npos);

  // The next scans see the same cells again (not new) or flicker inside the debounce window: no new proposal.
  for (int i = 0; i < 5; ++i)
  {
    core.processScan(world.scan(x, 5.0, 0.0), now += 0.1);
    EXPECT_NE(TriggerReason::Proposed, core.checkPlan(x, 5.0, now).reason);
  }
}

TEST(PlanTrigger, FiresWhenTheLaserSitsAheadOfTheRobotCentre)
{
  // Stage's PR2 and most AGVs carry the laser ahead of the base: cells are first marked at
  // obstacle_range from the laser, which is farther than obstacle_range from the robot's centre.
  // Seen again they are no longer new, so the range must be measured from the laser.
  SimWorld world = walledWorld();
  world.box(5.02, 4.6, 5.32, 5.4);
  SharingCore core = makeCore();
  core.setPlan(line(1.0, 5.0, 9.0, 5.0));
  double now = 1.0;
  TriggerReport report;
  for (double x = 1.0; x < 4.0 && report.reason == TriggerReason::None; x += 0.05)
  {
    core.processScan(world.scan(x + 0.3, 5.0, 0.0), now += 0.1);
    report = core.checkPlan(x, 5.0, now);
  }
  ASSERT_EQ(TriggerReason::Proposed, report.reason) << report.message;
}

TEST(PlanTrigger, CellsBesideOrBehindThePlanOrBeyondRangeDoNotFire)
{
  SimWorld world = walledWorld();
  world.box(5.02, 4.6, 5.32, 5.4);
  // The plan passes 0.9 m south of the block: more than the inscribed radius.
  {
    SharingCore core = makeCore();
    core.setPlan(line(3.0, 4.0, 9.0, 4.0));
    core.processScan(world.scan(3.5, 4.0, 0.0), 1.0);
    EXPECT_EQ(TriggerReason::None, core.checkPlan(3.5, 4.0, 1.0).reason);
  }
  // The plan goes west, away from the block behind the robot.
  {
    SharingCore core = makeCore();
    core.setPlan(line(9.0, 5.0, 1.0, 5.0));
    core.processScan(world.scan(3.5, 5.0, 0.0), 1.0);
    EXPECT_EQ(TriggerReason::None, core.checkPlan(3.5, 5.0, 1.0).reason);
    // Same scan, plan reversed (block ahead): fires. Shows the scene is one that can fire.
    SharingCore ahead = makeCore();
    ahead.setPlan(line(1.0, 5.0, 9.0, 5.0));
    ahead.processScan(world.scan(3.5, 5.0, 0.0), 1.0);
    EXPECT_EQ(TriggerReason::Proposed, ahead.checkPlan(3.5, 5.0, 1.0).reason);
  }
  // No plan: never fires.
  {
    SharingCore core = makeCore();
    core.processScan(world.scan(3.5, 5.0, 0.0), 1.0);
    EXPECT_EQ(TriggerReason::None, core.checkPlan(3.5, 5.0, 1.0).reason);
    core.setPlan({ { std::nan(""), 1.0 } });  // bad poses are dropped
    EXPECT_TRUE(core.plan().empty());
  }
}

TEST(PlanTrigger, AlreadySharedCellsOnThePlanAreReportedNotProposed)
{
  SimWorld world = walledWorld();
  world.box(5.02, 4.6, 5.32, 5.4);
  SharingCore core = makeCore();
  ASSERT_TRUE(core.applyShared(sharedUpdate("known", { grid().getIndex(100, 100) }, Subsection(4.9, 4.5, 5.5, 5.5)), 0.5)
                  .ok);
  core.setPlan(line(1.0, 5.0, 9.0, 5.0));
  core.processScan(world.scan(3.5, 5.0, 0.0), 1.0);
  const TriggerReport report = core.checkPlan(3.5, 5.0, 1.0);
  EXPECT_EQ(TriggerReason::AlreadyShared, report.reason) << report.message;
  EXPECT_TRUE(report.proposals.empty());
  EXPECT_TRUE(report.log);
}

// --- observation sources with their own limits (issue 13) ------------------------------------------------

TEST(ObservationSources, AClearingOnlySourceNeitherMarksNorFiresThePlanTrigger)
{
  SimWorld world = walledWorld();
  world.box(5.02, 4.6, 5.32, 5.4);  // 1.5 m ahead on the plan
  SharingCore core = makeCore();
  core.setPlan(line(1.0, 5.0, 9.0, 5.0));
  ScanLimits clearing_only = defaults().limits;
  clearing_only.marking = false;
  const ScanOutcome outcome = core.processScan(world.scan(3.5, 5.0, 0.0), 1.0, clearing_only);
  EXPECT_TRUE(outcome.touch.marked.empty());
  EXPECT_EQ(TriggerReason::None, core.checkPlan(3.5, 5.0, 1.0).reason);
  // The same scan from a source that marks: fires (the scene is one that can).
  core.processScan(world.scan(3.5, 5.0, 0.0), 1.1);
  EXPECT_EQ(TriggerReason::Proposed, core.checkPlan(3.5, 5.0, 1.1).reason);
}

TEST(ObservationSources, ASourceWithItsOwnObstacleRangeMarksFartherThanTheLayers)
{
  SimWorld world = walledWorld();
  world.box(7.02, 4.6, 7.32, 5.4);  // 3.5 m from the robot: beyond the layer's obstacle_range 2.5
  SharingCore core = makeCore();
  const GridGeometry g = grid();
  unsigned int mx = 0, my = 0;
  ASSERT_TRUE(g.worldToMap(7.03, 5.0, mx, my));  // the block's face, where the beam ends
  core.processScan(world.scan(3.5, 5.0, 0.0), 1.0);
  EXPECT_NE(LETHAL_OBSTACLE, core.obstacleGrid().getCost(mx, my));
  ScanLimits long_range = defaults().limits;
  long_range.obstacle_range = 4.0;
  long_range.raytrace_range = 4.5;
  const ScanOutcome outcome = core.processScan(world.scan(3.5, 5.0, 0.0), 2.0, long_range);
  EXPECT_EQ(LETHAL_OBSTACLE, core.obstacleGrid().getCost(mx, my));
  EXPECT_GE(outcome.touch.max_x, 7.0);
  ScanLimits bad = long_range;
  bad.obstacle_range = -1.0;
  EXPECT_THROW(core.processScan(world.scan(3.5, 5.0, 0.0), 3.0, bad), std::invalid_argument);
}
