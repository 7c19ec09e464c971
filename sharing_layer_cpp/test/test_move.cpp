// Moving the layer onto another grid: costmap_2d's resize (matchSize) and a rolling window's origin move
// (updateOrigin). Shared obstacles, their stamps and monitoring, the own observations (when kept), the trigger
// memory and the fleet robots must stay where they are in the world; what falls off the new grid is dropped and
// counted.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <string>
#include <stdexcept>
#include <utility>
#include <vector>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/cell_flags.h"
#include "sharing_layer/cost_values.h"
#include "sharing_layer/sharing_core.h"
#include "sim_scan.h"
#include "../bench/reference_scene.h"

using namespace sharing_layer;
using namespace sharing_layer::test;

namespace
{
using WorldCell = std::pair<long, long>;  ///< a cell centre in centimetres (or per_metre)

/// per_metre 1000 where grids of different origins put one centre at 2.1749999 and 2.1750001.
std::set<WorldCell> worldCells(const GridGeometry& g, const std::vector<std::uint32_t>& cells,
                               double per_metre = 100.0)
{
  std::set<WorldCell> out;
  for (std::uint32_t index : cells)
  {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    out.emplace(std::lround(wx * per_metre), std::lround(wy * per_metre));
  }
  return out;
}

/// The outline cells of the square [x0, x0 + side] x [y0, y0 + side] on g.
std::vector<std::uint32_t> outline(const GridGeometry& g, double x0, double y0, double side)
{
  unsigned int ax = 0, ay = 0, bx = 0, by = 0;
  g.worldToMap(x0 + 0.001, y0 + 0.001, ax, ay);
  g.worldToMap(x0 + side - 0.001, y0 + side - 0.001, bx, by);
  std::vector<std::uint32_t> cells;
  for (unsigned int y = ay; y <= by; ++y)
  {
    for (unsigned int x = ax; x <= bx; ++x)
    {
      if (x == ax || x == bx || y == ay || y == by)
      {
        cells.push_back(g.getIndex(x, y));
      }
    }
  }
  return cells;
}

std::uint32_t indexAt(const GridGeometry& g, double wx, double wy)
{
  unsigned int mx = 0, my = 0;
  EXPECT_TRUE(g.worldToMap(wx, wy, mx, my)) << wx << ", " << wy;
  return g.getIndex(mx, my);
}
}  // namespace

TEST(MoveTo, AnOriginMoveKeepsSharedCellsWhereTheyAreInTheWorldAndDropsWhatFallsOff)
{
  SharingCore core = makeCore();
  const GridGeometry old = core.geometry();
  const std::vector<std::uint32_t> kept = outline(old, 6.0, 5.0, 0.4);
  const std::vector<std::uint32_t> lost = outline(old, 0.6, 0.6, 0.3);
  ASSERT_TRUE(core.applyShared(sharedUpdate("kept", kept, Subsection(5.8, 4.8, 6.6, 5.6)), 0.0).ok);
  ASSERT_TRUE(core.applyShared(sharedUpdate("lost", lost, Subsection(0.5, 0.5, 1.0, 1.0)), 0.0).ok);
  // A cleared cell (a tombstone with version 2): an older mark arriving after the move must not bring it back.
  ObstacleUpdate clear = sharedUpdate("kept", {}, Subsection(5.8, 4.8, 6.6, 5.6), 2);
  clear.cleared = { kept.front() };
  ASSERT_TRUE(core.applyShared(clear, 1.0).ok);
  const std::set<WorldCell> before = worldCells(old, core.sharedCells("kept"));
  ASSERT_EQ(before.size(), kept.size() - 1);

  const GridGeometry moved(0.05, 2.0, 1.0, 200, 200);  // a rolling window 2 m right, 1 m up
  const MoveReport report = core.moveTo(moved, true);

  EXPECT_TRUE(core.geometry().sameAs(moved));
  EXPECT_EQ(worldCells(moved, core.sharedCells("kept")), before);
  EXPECT_EQ(report.shared_cells_dropped, lost.size());
  EXPECT_EQ(report.obstacles_out_of_grid, 1u);
  EXPECT_EQ(core.sharedObstacles().count("lost"), 1u) << "still held, for its updates and its expiry";
  EXPECT_TRUE(core.sharedCells("lost").empty());

  const std::uint32_t tombstone = indexAt(moved, 6.0 + 0.025, 5.0 + 0.025);
  ObstacleUpdate late = sharedUpdate("kept", { tombstone }, Subsection(5.8, 4.8, 6.6, 5.6), 1, "robot_2");
  late.geometry = moved;
  ASSERT_TRUE(core.applyShared(late, 2.0).ok);
  EXPECT_EQ(worldCells(moved, core.sharedCells("kept")), before) << "the cleared cell came back";

  std::vector<std::uint8_t> master(moved.cellCount(), FREE_SPACE);
  core.drawShared(master.data(), master.size());
  std::vector<std::uint32_t> drawn;
  for (std::uint32_t i = 0; i < master.size(); ++i)
  {
    if (master[i] == LETHAL_OBSTACLE)
    {
      drawn.push_back(i);
    }
  }
  EXPECT_EQ(worldCells(moved, drawn), before);
}

TEST(MoveTo, TheOwnObservationsFollowTheWorldOnAnOriginMoveAndStartEmptyOnAResize)
{
  SimWorld world = walledWorld();
  world.box(6.0, 5.0, 6.4, 5.4);
  SharingCore rolling = makeCore();
  SharingCore resized = makeCore();
  const Observation scan = world.scan(4.5, 5.2, 0.0);
  rolling.processScan(scan, 0.0);
  resized.processScan(scan, 0.0);
  const GridGeometry old = rolling.geometry();
  std::vector<std::uint32_t> lethal;
  for (std::uint32_t i = 0; i < old.cellCount(); ++i)
  {
    if (rolling.obstacleGrid().at(i) == LETHAL_OBSTACLE)
    {
      lethal.push_back(i);
    }
  }
  ASSERT_FALSE(lethal.empty());

  const GridGeometry moved(0.05, 1.0, 2.0, 200, 200);
  const MoveReport kept = rolling.moveTo(moved, true);
  std::vector<std::uint32_t> lethal_after;
  for (std::uint32_t i = 0; i < moved.cellCount(); ++i)
  {
    if (rolling.obstacleGrid().at(i) == LETHAL_OBSTACLE)
    {
      lethal_after.push_back(i);
    }
  }
  EXPECT_EQ(worldCells(moved, lethal_after), worldCells(old, lethal));
  EXPECT_EQ(kept.obstacle_cells_kept, lethal.size());
  EXPECT_EQ(worldCells(moved, rolling.shareableCells()).size(), rolling.shareableCells().size());
  EXPECT_FALSE(rolling.shareableCells().empty()) << "the block's face is still this robot's candidate";

  const GridGeometry larger(0.05, -1.0, -1.0, 260, 260);
  const MoveReport reset = resized.moveTo(larger, false);
  EXPECT_EQ(reset.obstacle_cells_kept, 0u);
  for (std::uint32_t i = 0; i < larger.cellCount(); ++i)
  {
    ASSERT_EQ(resized.obstacleGrid().at(i), FREE_SPACE) << "Costmap2D::resizeMap leaves the layer empty";
  }
  EXPECT_TRUE(resized.shareableCells().empty());
}

TEST(MoveTo, MonitoringGoesOnAfterAMove)
{
  // A shared block that stays is never cleared; once it is really removed its cells are cleared, with the
  // evidence rule, in the new grid's indexes.
  SimWorld standing = walledWorld();
  standing.box(6.0, 5.0, 6.4, 5.4);
  const SimWorld removed = walledWorld();
  SharingCore core = makeCore();
  const GridGeometry old = core.geometry();
  const std::vector<std::uint32_t> face = outline(old, 6.0, 5.0, 0.4);
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", face, Subsection(5.8, 4.8, 6.6, 5.6)), 0.0).ok);
  const GridGeometry moved(0.05, 3.0, 2.0, 150, 150);
  core.moveTo(moved, true);
  const std::size_t present = core.sharedCells("block").size();
  ASSERT_EQ(present, face.size());

  double t = 1.0;
  for (int i = 0; i < 20; ++i, t += 0.2)
  {
    const ScanOutcome outcome = core.processScan(standing.scan(4.6, 5.2, 0.0), t);
    for (const ObstacleUpdate& u : outcome.updates)
    {
      EXPECT_TRUE(u.cleared.empty()) << "a standing block lost cells after the move";
      EXPECT_TRUE(u.geometry.sameAs(moved));
    }
  }
  std::size_t cleared = 0;
  for (int i = 0; i < 20; ++i, t += 0.2)
  {
    for (const ObstacleUpdate& u : core.processScan(removed.scan(4.6, 5.2, 0.0), t).updates)
    {
      cleared += u.cleared.size();
    }
  }
  EXPECT_GT(cleared, 0u);
  EXPECT_LT(core.sharedCells("block").size(), present / 2) << "the removed block was not cleared";
}

TEST(MoveTo, FleetRobotsStayExcludedWhereTheyStand)
{
  SharingCore core = makeCore();
  FleetRobot robot;
  robot.name = "robot_1";
  robot.stamp = 0.0;
  robot.footprint = { { 6.8, 6.8 }, { 7.2, 6.8 }, { 7.2, 7.2 }, { 6.8, 7.2 } };
  core.fleetRobots().update(robot);
  const GridGeometry moved(0.05, 2.5, 2.5, 200, 200);
  core.moveTo(moved, true);
  EXPECT_TRUE(core.fleetRobots().excludes(indexAt(moved, 7.0, 7.0)));
  EXPECT_FALSE(core.fleetRobots().excludes(indexAt(moved, 5.0, 5.0)));
}

TEST(VersionedCellSetRemap, CellsLandingOnOneKeepTheNewestStampAndAClearWinsATie)
{
  VersionedCellSet cells;
  cells.apply({ 0, 2 }, {}, 1, "robot_a");
  cells.apply({}, { 1 }, 2, "robot_a");  // a newer clear next to cell 0
  // Exact ties (same version and source), the mark first in one pair and the clear first in the other, so
  // that whatever order remap() meets them in, one pair has the mark first.
  cells.apply({ 3 }, {}, 5, "robot_b");
  cells.apply({}, { 4 }, 5, "robot_b");
  cells.apply({}, { 5 }, 6, "robot_b");
  cells.apply({ 6 }, {}, 6, "robot_b");
  // 0 and 1 land on 0, 3 and 4 on 1, 5 and 6 on 2; 2 is dropped.
  const std::size_t dropped = cells.remap([](std::uint32_t index, std::uint32_t& moved) {
    if (index == 2)
    {
      return false;
    }
    moved = index < 2 ? 0 : (index < 5 ? 1 : 2);
    return true;
  });
  EXPECT_EQ(dropped, 1u);
  EXPECT_FALSE(cells.isPresent(0)) << "the newer clear of cell 1 lost to the older mark of cell 0";
  EXPECT_FALSE(cells.isPresent(1)) << "on an exact tie a clear wins, as in apply()";
  EXPECT_FALSE(cells.isPresent(2)) << "on an exact tie a clear wins, as in apply()";
  EXPECT_EQ(cells.presentCount(), 0u);
  EXPECT_EQ(cells.trackedCount(), 3u);
}

// A shared obstacle sent on another robot's grid reaches a layer whose grid differs (a rolling window, a map of
// another size or origin) at the same place in the world.
TEST(Reproject, AnUpdateFromAnotherGridKeepsItsCellsInTheWorldAndDropsWhatFallsOff)
{
  const GridGeometry sender(0.05, 0.0, 0.0, 200, 200);
  const GridGeometry window(0.05, 2.0, 2.0, 60, 60);  // 3 m x 3 m from (2, 2)
  ObstacleUpdate u;
  u.uuid = "u1";
  u.source = "robot_1";
  u.geometry = sender;
  u.version = 3;
  u.deadline = 60;
  u.rectangle = Subsection(1.8, 2.9, 3.4, 3.3);
  u.marked = outline(sender, 1.8, 2.9, 0.4);      // straddles the window's lower-left edge
  u.cleared = outline(sender, 3.0, 3.0, 0.2);
  std::size_t dropped = 0;
  const ObstacleUpdate moved = reprojectUpdate(u, window, &dropped);
  EXPECT_TRUE(moved.geometry.sameAs(window));
  EXPECT_EQ(u.uuid, moved.uuid);
  EXPECT_EQ(u.version, moved.version);
  std::set<WorldCell> expected_marked;
  for (const WorldCell& c : worldCells(sender, u.marked, 1000.0))
  {
    expected_marked.insert(c);
  }
  std::set<WorldCell> kept = worldCells(window, moved.marked, 1000.0);
  std::size_t off = 0;
  for (const WorldCell& c : expected_marked)
  {
    if (c.first < 2000 || c.second < 2000)
    {
      ++off;
      EXPECT_EQ(0u, kept.count(c));
    }
    else
    {
      EXPECT_EQ(1u, kept.count(c)) << c.first << ", " << c.second;
    }
  }
  EXPECT_GT(off, 0u);
  EXPECT_EQ(off, dropped);
  EXPECT_EQ(worldCells(sender, u.cleared, 1000.0), worldCells(window, moved.cleared, 1000.0));
  // A coarser grid: cells merge; a cell both marked and cleared there stays marked.
  ObstacleUpdate both = u;
  both.cleared = u.marked;
  const ObstacleUpdate coarse = reprojectUpdate(both, GridGeometry(0.1, 0.0, 0.0, 100, 100));
  EXPECT_FALSE(coarse.marked.empty());
  EXPECT_TRUE(coarse.cleared.empty());
  // An index outside the sender's own grid is refused, naming the obstacle.
  ObstacleUpdate bad = u;
  bad.marked.push_back(sender.cellCount());
  EXPECT_THROW(reprojectUpdate(bad, window), std::invalid_argument);
}

namespace
{
/// What Costmap2D::updateOrigin does to a layer's grid: the cells of the overlap keep their world position, the rest
/// goes back to the default value.
std::vector<std::uint8_t> shifted(const std::vector<std::uint8_t>& grid, const GridGeometry& from, const GridGeometry& to,
                                  std::uint8_t default_value)
{
  std::vector<std::uint8_t> out(to.cellCount(), default_value);
  for (unsigned int y = 0; y < from.size_y; ++y)
  {
    for (unsigned int x = 0; x < from.size_x; ++x)
    {
      double wx = 0.0, wy = 0.0;
      from.mapToWorld(x, y, wx, wy);
      unsigned int nx = 0, ny = 0;
      if (to.worldToMap(wx, wy, nx, ny))
      {
        out[to.getIndex(nx, ny)] = grid[from.getIndex(x, y)];
      }
    }
  }
  return out;
}
}  // namespace

TEST(OneGrid, TheCoreWritesIntoTheCallersGridAndFollowsItWhenItMoves)
{
  // The plugin hands the core its layer's own costmap_ (here with track_unknown_space's NO_INFORMATION default):
  // scans must leave it exactly as plain raytrace + mark leaves a grid of its own, through a rolling-window move the
  // caller makes itself (Costmap2D::updateOrigin) and a resize into a new buffer.
  SimWorld world = walledWorld();
  world.box(6.0, 5.0, 6.4, 5.4);
  SharingCore core = makeCore();
  const GridGeometry old = core.geometry();
  std::vector<std::uint8_t> layer(old.cellCount(), NO_INFORMATION);
  core.useObstacleGrid(layer.data(), NO_INFORMATION);
  EXPECT_EQ(core.obstacleGrid().data(), layer.data());
  CostGrid reference(old, NO_INFORMATION);
  const std::vector<std::uint32_t> face = outline(old, 6.0, 5.0, 0.4);
  ASSERT_TRUE(core.applyShared(sharedUpdate("block", face, Subsection(5.8, 4.8, 6.6, 5.6)), 0.0).ok);

  const Observation first = world.scan(4.5, 5.2, 0.0);
  core.processScan(first, 1.0);
  applyScan(reference, first, core.params().limits);
  ASSERT_EQ(std::vector<std::uint8_t>(reference.data(), reference.data() + old.cellCount()), layer);
  const std::size_t lethal = static_cast<std::size_t>(std::count(layer.begin(), layer.end(), LETHAL_OBSTACLE));
  ASSERT_GT(lethal, 0u);
  const std::set<WorldCell> shared_before = worldCells(old, core.sharedCells("block"));

  // The rolling window moves 1 m right: the caller shifts its own grid in place, then tells the core.
  const GridGeometry moved(0.05, 1.0, 0.0, old.size_x, old.size_y);
  const std::vector<std::uint8_t> moved_layer = shifted(layer, old, moved, NO_INFORMATION);
  std::copy(moved_layer.begin(), moved_layer.end(), layer.begin());
  const std::vector<std::uint8_t> moved_reference =
      shifted(std::vector<std::uint8_t>(reference.data(), reference.data() + old.cellCount()), old, moved,
              NO_INFORMATION);
  reference = CostGrid(moved, NO_INFORMATION);
  reference.assign(moved_reference);
  const MoveReport report = core.moveTo(moved, true, layer.data(), NO_INFORMATION);
  EXPECT_EQ(report.obstacle_cells_kept, static_cast<std::size_t>(std::count(layer.begin(), layer.end(), LETHAL_OBSTACLE)));
  EXPECT_EQ(worldCells(moved, core.sharedCells("block")), shared_before);
  EXPECT_EQ(core.obstacleGrid().data(), layer.data());
  const Observation second = world.scan(5.0, 5.0, 0.2);
  core.processScan(second, 2.0);
  applyScan(reference, second, core.params().limits);
  EXPECT_EQ(std::vector<std::uint8_t>(reference.data(), reference.data() + moved.cellCount()), layer)
      << "the caller's grid after a move differs from plain raytrace + mark";

  // A resize into a new buffer (Costmap2D::resizeMap): the new buffer, as the caller left it, is the grid.
  const GridGeometry larger(0.05, -1.0, -1.0, 260, 260);
  std::vector<std::uint8_t> resized(larger.cellCount(), NO_INFORMATION);
  const std::set<WorldCell> shared_moved = worldCells(moved, core.sharedCells("block"));
  core.moveTo(larger, false, resized.data(), NO_INFORMATION);
  EXPECT_EQ(core.obstacleGrid().data(), resized.data());
  EXPECT_EQ(worldCells(larger, core.sharedCells("block")), shared_moved);
  core.processScan(second, 3.0);
  CostGrid larger_reference(larger, NO_INFORMATION);
  applyScan(larger_reference, second, core.params().limits);
  EXPECT_EQ(std::vector<std::uint8_t>(larger_reference.data(), larger_reference.data() + larger.cellCount()), resized);
  core.resetObstacleLayer();
  EXPECT_EQ(std::count(resized.begin(), resized.end(), NO_INFORMATION), static_cast<long>(resized.size()))
      << "a reset restores the caller's default value";
  EXPECT_THROW(core.useObstacleGrid(nullptr, FREE_SPACE), std::invalid_argument);
  EXPECT_THROW(core.moveTo(larger, false, nullptr, FREE_SPACE), std::invalid_argument);
}

TEST(OneGrid, ACopiedGridOfItsOwnIsIndependentAndAViewIsNot)
{
  const GridGeometry g(0.1, 0.0, 0.0, 4, 3);
  CostGrid own(g, FREE_SPACE);
  CostGrid copy = own;
  copy.set(5, LETHAL_OBSTACLE);
  EXPECT_EQ(own.at(5), FREE_SPACE);
  std::vector<std::uint8_t> buffer(g.cellCount(), FREE_SPACE);
  CostGrid view = CostGrid::view(g, buffer.data(), FREE_SPACE);
  EXPECT_FALSE(view.ownsCells());
  CostGrid view_copy = view;
  view_copy.set(7, LETHAL_OBSTACLE);
  EXPECT_EQ(buffer[7], LETHAL_OBSTACLE);
  CostGrid moved_own = std::move(copy);
  EXPECT_TRUE(moved_own.ownsCells());
  EXPECT_EQ(moved_own.at(5), LETHAL_OBSTACLE);
}

TEST(Monitoring, AnExpiredObstacleLeavesTheRectangleOfAnOverlappingOneMonitored)
{
  // Cells inside a shared obstacle's rectangle are monitoring's, never this robot's own candidates. Two obstacles
  // cover the block; when one expires, the other's rectangle must still hold the block's cells.
  SimWorld world = walledWorld();
  world.box(6.0, 5.0, 6.4, 5.4);
  SharingCore core = makeCore();
  const GridGeometry g = core.geometry();
  const Subsection around(5.8, 4.8, 6.6, 5.6);
  ASSERT_TRUE(core.applyShared(sharedUpdate("a", { indexAt(g, 6.55, 5.55) }, around), 0.0).ok);
  ASSERT_TRUE(core.applyShared(sharedUpdate("b", { indexAt(g, 5.85, 4.85) }, Subsection(5.8, 4.8, 6.7, 5.7)), 0.0).ok);
  ASSERT_TRUE(core.expire("a"));
  const Observation scan = world.scan(4.5, 5.2, 0.0);
  core.processScan(scan, 1.0);
  const std::vector<std::uint32_t> face = core.shareableCells();
  EXPECT_TRUE(std::none_of(face.begin(), face.end(), [&](std::uint32_t index) {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    return wx >= around.min_x && wx <= around.max_x && wy >= around.min_y && wy <= around.max_y;
  })) << "cells of obstacle b's rectangle became shareable when a expired";
  ASSERT_TRUE(core.expire("b"));
  core.processScan(scan, 1.1);
  EXPECT_FALSE(core.shareableCells().empty()) << "with no obstacle left the block's face is this robot's candidate";
}

TEST(OneGrid, SharingAddsAtMostOneBytePerCellOnTheReferenceWarehouse)
{
  // Issues 13 and 29: ObstacleLayer keeps one byte per cell; what sharing keeps beside it must stay within one more,
  // with every per-cell fact in use: the static map's walls and its unknown outside the hall (and the static filter
  // grown from both), ten fleet robots, the 100 crates shared as obstacles (their monitored rectangles and present
  // cells), and the flags of scans that marked, cleared, remembered and watched. The old layout (a flags byte per
  // cell and a bit per cell per fact) held 1.625 bytes per cell here.
  const bench::Scene scene = bench::makeScene();
  const GridGeometry& g = scene.geometry;
  const std::size_t cells = g.cellCount();
  LayerParams params;
  params.limits.obstacle_range = 2.5;
  params.limits.raytrace_range = 30.0;
  params.limits.max_obstacle_height = 2.0;
  params.robot_name = "robot_0";
  SharingCore core(g, params);
  std::vector<std::uint8_t> walls(cells, FREE_SPACE), unknown(cells, 0);
  for (unsigned int y = 0; y < g.size_y; ++y)
  {
    for (unsigned int x = 0; x < g.size_x; ++x)
    {
      const std::uint32_t i = g.getIndex(x, y);
      double wx = 0.0, wy = 0.0;
      g.mapToWorld(x, y, wx, wy);
      walls[i] = scene.map[i] ? LETHAL_OBSTACLE : FREE_SPACE;
      unknown[i] = !scene.map[i] && (wx < 20.0 || wx > 80.0 || wy < 30.0 || wy > 70.0);
    }
  }
  core.setStaticMap(walls.data(), cells);
  core.setUnknownMap(unknown.data(), cells);
  for (int k = 0; k < 10; ++k)
  {
    const double cx = 30.0 + 4.0 * k, cy = 45.0;
    FleetRobot robot;
    robot.name = "robot_" + std::to_string(k + 1);
    robot.footprint = { { cx - 0.3, cy - 0.3 }, { cx + 0.3, cy - 0.3 }, { cx + 0.3, cy + 0.3 },
                        { cx - 0.3, cy + 0.3 } };
    core.fleetRobots().update(robot);
  }
  for (int i = 0; i < bench::kCrates; ++i)
  {
    ASSERT_TRUE(core.applyShared(bench::crateUpdate(scene, i), 0.0).ok);
  }
  for (int r = 0; r < 3; ++r)
  {
    core.processScan(scene.scan, 0.1 * r);
  }
  ASSERT_TRUE(core.fleetRobots().excludes(g.getIndex(600, 900)));
  EXPECT_LE(core.perCellBytes(), cells) << core.perCellBytes() / static_cast<double>(cells) << " bytes per cell";
  EXPECT_GE(core.perCellBytes(), cells / 32) << "the flags' directory alone is 1/32 byte per cell";
  RecordProperty("bytes_per_cell_x1000", static_cast<int>(1000 * core.perCellBytes() / cells));
}

TEST(OneGrid, TiledBitsAndFlagsReadAsOneValuePerCellAndHoldMemoryOnlyWhereMixed)
{
  // BitGrid and CellFlags keep only tiles with something in them (BitGrid: neither all false nor all true). Random
  // sets and resets against a plain array, then everything undone: what they read must agree at every step, and the
  // tiles must be given back.
  const std::size_t cells = 5 * BitGrid::kTileCells + 77;
  std::mt19937 rng(7);
  BitGrid bits;
  bits.assign(cells);
  CellFlags flags;
  flags.assign(cells);
  std::vector<std::uint8_t> plain_bits(cells, 0), plain_flags(cells, 0);
  const std::size_t empty_bits = bits.bytes(), empty_flags = flags.bytes();
  for (int step = 0; step < 20000; ++step)
  {
    // Runs of one value over a stretch of cells, so that whole tiles become all true too.
    const std::size_t from = rng() % cells, length = 1 + rng() % (2 * BitGrid::kTileCells);
    const bool value = rng() % 2 == 0;
    const std::uint8_t bit = static_cast<std::uint8_t>(1u << (rng() % 8));
    for (std::size_t i = from; i < std::min(cells, from + length); ++i)
    {
      bits.set(i, value);
      plain_bits[i] = value;
      if (rng() % 8 == 0)
      {
        value ? flags.set(static_cast<std::uint32_t>(i), bit) : flags.clear(static_cast<std::uint32_t>(i), bit);
        plain_flags[i] = value ? (plain_flags[i] | bit) : (plain_flags[i] & ~bit);
      }
    }
    if (step % 1000 == 0)
    {
      for (std::size_t i = 0; i < cells; ++i)
      {
        ASSERT_EQ(plain_bits[i] != 0, bits.test(i)) << "step " << step << ", cell " << i;
        ASSERT_EQ(plain_flags[i], flags.get(static_cast<std::uint32_t>(i))) << "step " << step << ", cell " << i;
      }
    }
  }
  for (bool value : { true, false })  // all true: every tile is the shared constant again; then all false
  {
    for (std::size_t i = 0; i < cells; ++i)
    {
      bits.set(i, value);
      flags.clear(static_cast<std::uint32_t>(i), 0xFF);
    }
    // (all true, the last tile, of 77 cells, is mixed: the bits beyond the grid stay false)
    EXPECT_EQ(value ? 1u : 0u, bits.mixedTiles()) << "all " << value;
    EXPECT_EQ(0u, flags.tilesInUse());
  }
  EXPECT_FALSE(bits.test(cells - 1));
  EXPECT_EQ(0, flags.get(static_cast<std::uint32_t>(cells - 1)));
  EXPECT_GE(bits.bytes(), empty_bits);
  EXPECT_GE(flags.bytes(), empty_flags);
}
