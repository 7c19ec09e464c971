// Marking and clearing with costmap_2d ObstacleLayer's rules.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

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
