// Marking and clearing with costmap_2d ObstacleLayer's rules.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <limits>
#include <random>
#include <set>

#include "ascii_grid.h"
#include "sharing_layer/cost_values.h"
#include "sharing_layer/scan_update.h"

using namespace sharing_layer;
using sharing_layer::test::drawCells;
using sharing_layer::test::picture;

namespace
{
/// 12 x 5 cells of 0.1 m, origin (0, 0); the sensor sits in cell (0, 2).
CostGrid smallGrid(std::uint8_t fill = FREE_SPACE)
{
  return CostGrid(GridGeometry(0.1, 0.0, 0.0, 12, 5), fill);
}

Observation scanFrom(double ox, double oy, std::vector<Point3> points)
{
  Observation obs;
  obs.origin = Point3{ ox, oy, 0.0 };
  obs.points = std::move(points);
  return obs;
}

std::vector<std::uint32_t> cellsWithCost(const CostGrid& grid, std::uint8_t cost)
{
  std::vector<std::uint32_t> cells;
  for (std::uint32_t i = 0; i < grid.geometry().cellCount(); ++i)
  {
    if (grid.at(i) == cost)
    {
      cells.push_back(i);
    }
  }
  return cells;
}

ScanLimits limits(double obstacle_range, double raytrace_range)
{
  ScanLimits l;
  l.obstacle_range = obstacle_range;
  l.raytrace_range = raytrace_range;
  return l;
}
}  // namespace

TEST(ScanUpdate, ClearsTheBeamThenMarksTheEndpoint)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 0.85, 0.25, 0.0 } }), limits(2.5, 3.0));
  EXPECT_TRUE(touch.origin_in_map);
  // Row y = 2 is cleared from the sensor up to the endpoint, which is marked again.
  EXPECT_EQ(picture({ "############",
                      "############",
                      "........####",
                      "############",
                      "############" }),
            drawCells(cellsWithCost(grid, LETHAL_OBSTACLE), 12, 5));
  EXPECT_EQ((std::vector<std::uint32_t>{ 2 * 12 + 8 }), touch.marked);
}

TEST(ScanUpdate, ObstacleRangeLimitsMarkingButNotClearing)
{
  CostGrid grid = smallGrid();
  // Endpoint 1.0 m away, obstacle_range 0.5 m: cleared along the way, not marked.
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 1.05, 0.25, 0.0 } }), limits(0.5, 3.0));
  EXPECT_TRUE(touch.marked.empty());
  EXPECT_TRUE(cellsWithCost(grid, LETHAL_OBSTACLE).empty());
}

TEST(ScanUpdate, RaytraceRangeLimitsClearing)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  // raytrace_range 0.3 m = 3 cells: cells 0..3 of the row are cleared, the rest stays.
  applyScan(grid, scanFrom(0.05, 0.25, { { 1.15, 0.25, 0.0 } }), limits(0.2, 0.3));
  EXPECT_EQ(picture({ "############",
                      "############",
                      "....########",
                      "############",
                      "############" }),
            drawCells(cellsWithCost(grid, LETHAL_OBSTACLE), 12, 5));
}

TEST(ScanUpdate, HeightLimitsIgnorePointsForBothMarkingAndClearing)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  ScanLimits l = limits(2.5, 3.0);
  l.min_obstacle_height = 0.1;
  l.max_obstacle_height = 0.5;
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 0.85, 0.25, 0.05 }, { 0.85, 0.15, 0.9 } }), l);
  EXPECT_EQ(2u, touch.height_filtered);
  EXPECT_TRUE(touch.marked.empty());
  EXPECT_EQ(60u, cellsWithCost(grid, LETHAL_OBSTACLE).size());  // nothing cleared
}

TEST(ScanUpdate, OriginOffTheMapSkipsClearingButStillMarks)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  grid.set(2 * 12 + 5, FREE_SPACE);
  const ScanTouch touch = applyScan(grid, scanFrom(-0.5, 0.25, { { 0.55, 0.25, 0.0 } }), limits(2.5, 3.0));
  EXPECT_FALSE(touch.origin_in_map);
  EXPECT_EQ((std::vector<std::uint32_t>{ 2 * 12 + 5 }), touch.marked);
  EXPECT_EQ(60u, cellsWithCost(grid, LETHAL_OBSTACLE).size());
}

TEST(ScanUpdate, EndpointsOffTheMapAreClippedToTheEdge)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  // A beam to x = 3 m leaves the 1.2 m grid: it clears up to the edge and marks nothing.
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 3.05, 0.25, 0.0 } }), limits(5.0, 5.0));
  EXPECT_TRUE(touch.marked.empty());
  EXPECT_EQ(picture({ "############",
                      "############",
                      "............",
                      "############",
                      "############" }),
            drawCells(cellsWithCost(grid, LETHAL_OBSTACLE), 12, 5));
  // Leaving through the bottom edge: clipped on y, the cells down to row 0 are cleared.
  CostGrid below = smallGrid(LETHAL_OBSTACLE);
  applyScan(below, scanFrom(0.05, 0.25, { { 0.05, -2.0, 0.0 } }), limits(5.0, 5.0));
  EXPECT_EQ(picture({ "############",
                      "############",
                      ".###########",
                      ".###########",
                      ".###########" }),
            drawCells(cellsWithCost(below, LETHAL_OBSTACLE), 12, 5));
}

TEST(ScanUpdate, WatchedRectanglesReportClearedCellsOnlyInside)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  CellRect watched;
  watched.min_x = 4;
  watched.max_x = 6;
  watched.min_y = 1;
  watched.max_y = 3;
  const ScanTouch touch =
      applyScan(grid, scanFrom(0.05, 0.25, { { 0.85, 0.25, 0.0 }, { 0.05, 0.45, 0.0 } }), limits(2.5, 3.0), ScanWatch::fromRects(grid.geometry(), { watched }));
  EXPECT_EQ((std::vector<std::uint32_t>{ 2 * 12 + 4, 2 * 12 + 5, 2 * 12 + 6 }), touch.watched_cleared);
}

TEST(ScanUpdate, CellClearedByOneBeamAndMarkedByAnotherStaysMarked)
{
  CostGrid grid = smallGrid();
  CellRect watched;
  watched.min_x = 0;
  watched.max_x = 11;
  watched.min_y = 0;
  watched.max_y = 4;
  // The second beam passes through (5, 2), which the first beam hits.
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 0.55, 0.25, 0.0 }, { 1.05, 0.25, 0.0 } }),
                                    limits(2.5, 3.0), ScanWatch::fromRects(grid.geometry(), { watched }));
  EXPECT_EQ(LETHAL_OBSTACLE, grid.at(2 * 12 + 5));
  for (std::uint32_t index : touch.watched_cleared)
  {
    EXPECT_NE(2u * 12 + 5, index);
  }
}

// Watched cells are flagged in the grid during the scan: afterwards every cell must hold exactly what a scan
// without a watch leaves, whatever the cells held before (free, lethal, unknown) and with duplicates.
TEST(ScanUpdate, WatchingLeavesTheGridAsAnUnwatchedScanDoes)
{
  CostGrid watched_grid = smallGrid();
  for (std::uint32_t i = 0; i < watched_grid.geometry().cellCount(); ++i)
  {
    watched_grid.data()[i] = i % 3 == 0 ? LETHAL_OBSTACLE : (i % 3 == 1 ? NO_INFORMATION : FREE_SPACE);
  }
  CostGrid plain_grid = watched_grid;
  const CostGrid before = watched_grid;
  ScanWatch watch = ScanWatch::fromRects(watched_grid.geometry(), { CellRect{ 0, 0, 11, 4 } });
  watch.cells.insert(watch.cells.end(), { 2 * 12 + 5, 2 * 12 + 5, 1 * 12 + 9 });  // duplicates
  const Observation scan = scanFrom(0.05, 0.25, { { 0.55, 0.25, 0.0 }, { 1.15, 0.05, 0.0 }, { 0.75, 0.45, 0.0 } });

  // The evidence options (margin, shadow filter, regions) must not change what the grid ends with either.
  CostGrid evidence_grid = watched_grid;
  ScanWatch evidence_watch = watch;
  evidence_watch.free_margin = 0.1;
  evidence_watch.free_neighbours = 1;
  evidence_watch.regions = { CellRect{ 0, 0, 11, 4 } };
  const ScanTouch evidence = applyScan(evidence_grid, scan, limits(2.5, 3.0), evidence_watch);
  const ScanTouch watched = applyScan(watched_grid, scan, limits(2.5, 3.0), watch);
  applyScan(plain_grid, scan, limits(2.5, 3.0));

  for (std::uint32_t i = 0; i < plain_grid.geometry().cellCount(); ++i)
  {
    ASSERT_EQ(plain_grid.at(i), watched_grid.at(i)) << "cell " << i;
    ASSERT_EQ(plain_grid.at(i), evidence_grid.at(i)) << "cell " << i;
  }
  EXPECT_EQ(watched.watched_cleared, evidence.watched_cleared);
  // Every cell the scan turned free must be reported; a reported cell must end free.
  std::vector<std::uint32_t> expected;
  for (std::uint32_t i = 0; i < plain_grid.geometry().cellCount(); ++i)
  {
    if (plain_grid.at(i) == FREE_SPACE && before.at(i) != FREE_SPACE)
    {
      expected.push_back(i);
    }
  }
  ASSERT_FALSE(expected.empty());
  for (std::uint32_t i : watched.watched_cleared)
  {
    EXPECT_EQ(FREE_SPACE, plain_grid.at(i)) << "cell " << i;
  }
  for (std::uint32_t i : expected)
  {
    EXPECT_TRUE(std::binary_search(watched.watched_cleared.begin(), watched.watched_cleared.end(), i)) << "cell " << i;
  }
  EXPECT_TRUE(std::is_sorted(watched.watched_cleared.begin(), watched.watched_cleared.end()));
  EXPECT_EQ(std::adjacent_find(watched.watched_cleared.begin(), watched.watched_cleared.end()),
            watched.watched_cleared.end());
}

TEST(ScanUpdate, WatchedCellOutsideTheGridIsRefusedAndTheGridUntouched)
{
  CostGrid grid = smallGrid(NO_INFORMATION);
  ScanWatch watch;
  watch.cells = { 3, 60 };  // the grid has 60 cells
  EXPECT_THROW(applyScan(grid, scanFrom(0.05, 0.25, { { 0.55, 0.25, 0.0 } }), limits(2.5, 3.0), watch),
               std::invalid_argument);
  for (std::uint32_t i = 0; i < 60; ++i)
  {
    ASSERT_EQ(NO_INFORMATION, grid.at(i));
  }
}

// The update box is costmap_2d ObstacleLayer's: origin, each clipped endpoint pulled in to raytrace_range, every
// marked point; nothing else (issue 13: a fixed box of the range around the sensor made every later layer work
// over 3.4 times the area at 30 m).
TEST(ScanUpdate, TouchedBoxIsWhatTheBeamsReachedAndWhatWasMarked)
{
  CostGrid grid = smallGrid();
  // Sensor at (0.05, 0.25). One beam to (1.05, 0.25), 1.0 m: cleared up to raytrace_range 0.6 m, beyond
  // obstacle_range 0.4 m, so not marked. One to (0.25, 0.45): marked, and inside raytrace_range.
  const ScanTouch touch =
      applyScan(grid, scanFrom(0.05, 0.25, { { 1.05, 0.25, 0.0 }, { 0.25, 0.45, 0.0 } }), limits(0.4, 0.6));
  ASSERT_FALSE(touch.touchedNothing());
  EXPECT_DOUBLE_EQ(touch.min_x, 0.05);
  EXPECT_DOUBLE_EQ(touch.max_x, 0.65);  // the long beam, pulled in to raytrace_range
  EXPECT_DOUBLE_EQ(touch.min_y, 0.25);
  EXPECT_DOUBLE_EQ(touch.max_y, 0.45);  // the marked point
}

TEST(ScanUpdate, TouchedBoxFollowsBeamsClippedAtTheMapEdge)
{
  CostGrid grid = smallGrid();  // 1.2 m x 0.5 m
  // Leaves the map at the top: clipped to y = 0.5 - 0.001 as costmap_2d clips, well within raytrace_range.
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 0.55, 1.25, 0.0 } }), limits(2.5, 3.0));
  EXPECT_NEAR(touch.max_y, 0.499, 1e-9);
  EXPECT_NEAR(touch.max_x, 0.05 + 0.5 * (0.5 - 0.25) / 1.0, 1e-9);  // x where the beam crosses the edge
  EXPECT_DOUBLE_EQ(touch.min_x, 0.05);
  EXPECT_DOUBLE_EQ(touch.min_y, 0.25);
}

TEST(ScanUpdate, TouchedBoxWithTheOriginOffTheMapHoldsOnlyMarkedPoints)
{
  CostGrid grid = smallGrid();
  const ScanTouch touch = applyScan(grid, scanFrom(-0.5, 0.25, { { 0.15, 0.25, 0.0 }, { 0.35, 0.15, 0.0 } }),
                                    limits(2.5, 3.0));
  EXPECT_FALSE(touch.origin_in_map);
  EXPECT_DOUBLE_EQ(touch.min_x, 0.15);
  EXPECT_DOUBLE_EQ(touch.max_x, 0.35);
  EXPECT_DOUBLE_EQ(touch.min_y, 0.15);
  EXPECT_DOUBLE_EQ(touch.max_y, 0.25);
  EXPECT_TRUE(applyScan(grid, scanFrom(-0.5, 0.25, {}), limits(2.5, 3.0)).touchedNothing());
}

// costmap_2d's per-source marking / clearing flags (issue 13).
TEST(ScanUpdate, AMarkingOnlySourceMarksWithoutClearing)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  ScanLimits marking_only = limits(2.5, 3.0);
  marking_only.clearing = false;
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 0.85, 0.25, 0.0 } }), marking_only);
  EXPECT_EQ(cellsWithCost(grid, LETHAL_OBSTACLE).size(), 60u);  // nothing cleared
  EXPECT_EQ(touch.marked, std::vector<std::uint32_t>{ 2 * 12 + 8 });
  EXPECT_DOUBLE_EQ(touch.min_x, 0.85);  // the box holds the marked point only: no beam was raytraced
  EXPECT_DOUBLE_EQ(touch.max_x, 0.85);
}

TEST(ScanUpdate, AClearingOnlySourceClearsWithoutMarkingButItsEndpointsStillCount)
{
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  ScanLimits clearing_only = limits(2.5, 3.0);
  clearing_only.marking = false;
  ScanWatch watch;
  watch.cells = { 2 * 12 + 8 };  // the endpoint's cell, watched (a shared cell)
  const ScanTouch touch = applyScan(grid, scanFrom(0.05, 0.25, { { 0.85, 0.25, 0.0 } }), clearing_only, watch);
  EXPECT_TRUE(touch.marked.empty());
  // costmap_2d's raytrace clears the endpoint's cell too; a marking source marks it again, this one does not.
  for (unsigned int x = 0; x <= 8; ++x)
  {
    EXPECT_EQ(FREE_SPACE, grid.at(2 * 12 + x)) << "cell " << x << " of the beam";
  }
  EXPECT_EQ(touch.watched_hit, std::vector<std::uint32_t>{ 2 * 12 + 8 });  // evidence the cell is occupied
  EXPECT_TRUE(touch.watched_free.empty());
}

TEST(ApplyScan, PointsAboveTheMarkingHeightClearButAreNotMarked)
{
  // costmap_2d ObstacleLayer's layer-level max_obstacle_height: it bounds marking only.
  CostGrid grid = smallGrid(LETHAL_OBSTACLE);
  Observation obs;
  obs.origin = Point3{ 0.05, 0.25, 0.5 };
  obs.points = { Point3{ 0.55, 0.25, 0.5 }, Point3{ 0.35, 0.15, 0.2 } };
  ScanLimits limits;
  limits.max_marking_height = 0.4;
  const ScanTouch touch = applyScan(grid, obs, limits);
  EXPECT_EQ(FREE_SPACE, grid.getCost(5, 2)) << "the high point's cell is cleared, not marked";
  EXPECT_EQ(FREE_SPACE, grid.getCost(3, 2));
  EXPECT_EQ(LETHAL_OBSTACLE, grid.getCost(3, 1)) << "the low point is marked";
  EXPECT_EQ(std::vector<std::uint32_t>{ 1 * 12 + 3 }, touch.marked);
  limits.max_marking_height = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(applyScan(grid, obs, limits), std::invalid_argument);
}

// A long scan marks its cells in scan order, with repeats; touch.marked lists them sorted and once each, whatever the
// grid's size.
TEST(ApplyScan, ManyMarkedCellsComeOutSortedAndUniqueOnGridsOfEverySize)
{
  for (const unsigned int side : { 40u, 700u, 3000u })  // 1,600, 490,000 and 9 M cells
  {
    const GridGeometry geometry(0.05, 0.0, 0.0, side, side);
    CostGrid grid(geometry, FREE_SPACE);
    std::mt19937 random(side);
    std::uniform_real_distribution<double> coordinate(0.0, side * 0.05);
    Observation obs;
    obs.origin = Point3{ 0.5 * side * 0.05, 0.5 * side * 0.05, 0.0 };
    std::set<std::uint32_t> expected;
    for (int i = 0; i < 3000; ++i)
    {
      // Every third point falls in the cell of an earlier one.
      const Point3 p = i % 3 == 2 ? obs.points[random() % obs.points.size()]
                                  : Point3{ coordinate(random), coordinate(random), 0.0 };
      obs.points.push_back(p);
      unsigned int mx = 0, my = 0;
      ASSERT_TRUE(geometry.worldToMap(p.x, p.y, mx, my));
      expected.insert(geometry.getIndex(mx, my));
    }
    ScanLimits l;
    l.obstacle_range = 1e9;
    l.raytrace_range = 1.0;
    const ScanTouch touch = applyScan(grid, obs, l);
    EXPECT_EQ(std::vector<std::uint32_t>(expected.begin(), expected.end()), touch.marked) << side << " x " << side;
    EXPECT_GT(obs.points.size(), expected.size()) << "the scan repeats cells";
  }
}
