// Inflation and planner of fleet_nav's core, on small grids drawn as ASCII maps.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "fleet_nav/grid_planner.h"
#include "fleet_nav/inflation.h"

using namespace fleet_nav;

namespace
{
// '#' lethal, '?' unknown, '.' free; row 0 of the picture is the top (largest y).
std::vector<std::uint8_t> parse(const std::vector<std::string>& rows, unsigned int& sx, unsigned int& sy)
{
  sy = static_cast<unsigned int>(rows.size());
  sx = static_cast<unsigned int>(rows[0].size());
  std::vector<std::uint8_t> grid(sx * sy, 0);
  for (unsigned int r = 0; r < sy; ++r)
  {
    const unsigned int y = sy - 1 - r;
    for (unsigned int x = 0; x < sx; ++x)
    {
      const char c = rows[r][x];
      grid[y * sx + x] = c == '#' ? 254 : c == '?' ? 255 : 0;
    }
  }
  return grid;
}

InflationParams params(double inscribed, double radius, double scaling)
{
  InflationParams p;
  p.resolution = 0.1;
  p.inscribed_radius = inscribed;
  p.inflation_radius = radius;
  p.cost_scaling_factor = scaling;
  return p;
}
}  // namespace

TEST(Inflation, CostsFollowCostmap2dFormula)
{
  Inflator inflator(params(0.2, 0.5, 10.0));
  EXPECT_EQ(5u, inflator.cellRadius());
  EXPECT_EQ(254, inflator.costAtDistance(0.0));
  EXPECT_EQ(253, inflator.costAtDistance(1.0));
  EXPECT_EQ(253, inflator.costAtDistance(2.0));
  EXPECT_EQ(static_cast<int>(252 * std::exp(-10.0 * (0.3 - 0.2))), inflator.costAtDistance(3.0));
  EXPECT_EQ(static_cast<int>(252 * std::exp(-10.0 * (0.5 - 0.2))), inflator.costAtDistance(5.0));
  EXPECT_EQ(0, inflator.costAtDistance(5.1));
}

TEST(Inflation, SingleObstacleGivesRadialCosts)
{
  unsigned int sx = 0, sy = 0;
  const std::vector<std::uint8_t> master = parse({ "...........",
                                                   "...........",
                                                   "...........",
                                                   "...........",
                                                   "...........",
                                                   ".....#.....",
                                                   "...........",
                                                   "...........",
                                                   "...........",
                                                   "...........",
                                                   "..........." },
                                                 sx, sy);
  Inflator inflator(params(0.2, 0.5, 10.0));
  std::vector<std::uint8_t> out(master.size(), 7);
  inflator.inflateAll(master.data(), sx, sy, out.data());
  for (unsigned int y = 0; y < sy; ++y)
  {
    for (unsigned int x = 0; x < sx; ++x)
    {
      const double d = std::hypot(double(x) - 5.0, double(y) - 5.0);
      EXPECT_EQ(inflator.costAtDistance(d), out[y * sx + x]) << "cell " << x << "," << y;
    }
  }
}

TEST(Inflation, WindowMatchesFullInflationAndLeavesOutsideAlone)
{
  unsigned int sx = 0, sy = 0;
  const std::vector<std::uint8_t> master = parse({ "#...........?...",
                                                   "......#.........",
                                                   "................",
                                                   "..##............",
                                                   "...........#....",
                                                   "................",
                                                   "?..........#...#" },
                                                 sx, sy);
  Inflator inflator(params(0.1, 0.4, 3.0));
  std::vector<std::uint8_t> full(master.size(), 0);
  inflator.inflateAll(master.data(), sx, sy, full.data());
  std::vector<std::uint8_t> part(master.size(), 77);
  inflator.inflate(master.data(), sx, sy, part.data(), 4, 2, 9, 5);
  for (unsigned int y = 0; y < sy; ++y)
  {
    for (unsigned int x = 0; x < sx; ++x)
    {
      const bool in = x >= 4 && x < 9 && y >= 2 && y < 5;
      EXPECT_EQ(in ? full[y * sx + x] : 77, part[y * sx + x]) << "cell " << x << "," << y;
    }
  }
  // Unknown stays unknown unless it becomes inscribed or lethal; a lethal cell never drops.
  EXPECT_EQ(255, full[6 * sx + 12]);
  EXPECT_EQ(254, full[6 * sx + 0]);
}

TEST(Inflation, BadParametersNameTheValue)
{
  try
  {
    Inflator inflator(params(0.1, -1.0, 3.0));
    FAIL() << "negative inflation radius accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string::npos, std::string(e.what()).find("inflation_radius"));
    EXPECT_NE(std::string::npos, std::string(e.what()).find("-1"));
  }
}

TEST(Planner, GoesAroundAWallThroughTheGap)
{
  unsigned int sx = 0, sy = 0;
  const std::vector<std::uint8_t> costs = parse({ "..........",
                                                  "....#.....",
                                                  "....#.....",
                                                  "....#.....",
                                                  "S...#....G",
                                                  "....#.....",
                                                  "....#....." },
                                                sx, sy);
  GridPlanner planner;
  std::vector<std::uint32_t> path;
  const std::uint32_t start = 2 * sx + 0, goal = 2 * sx + 9;
  ASSERT_EQ(PlanStatus::Ok, planner.makePlan(costs.data(), sx, sy, start, goal, path));
  EXPECT_EQ(start, path.front());
  EXPECT_EQ(goal, path.back());
  bool through_gap = false;
  for (std::size_t i = 0; i < path.size(); ++i)
  {
    EXPECT_LT(costs[path[i]], 253) << "path enters an obstacle at " << path[i];
    if (path[i] == 6 * sx + 4)
    {
      through_gap = true;
    }
    if (i > 0)
    {
      const int dx = int(path[i] % sx) - int(path[i - 1] % sx);
      const int dy = int(path[i] / sx) - int(path[i - 1] / sx);
      EXPECT_LE(std::abs(dx), 1);
      EXPECT_LE(std::abs(dy), 1);
    }
  }
  EXPECT_TRUE(through_gap);
  // Optimal without corner cutting: (0,2) to (3,6) is 3 diagonal + 1 straight, (3,6) to (5,6) 2 straight
  // through the gap, (5,6) to (9,2) 4 diagonal.
  EXPECT_NEAR(50.0 * (7 * std::sqrt(2.0) + 3.0), planner.lastCost(), 1e-3);
}

TEST(Planner, NoCornerCutting)
{
  unsigned int sx = 0, sy = 0;
  const std::vector<std::uint8_t> costs = parse({ "#.",
                                                  ".#" },
                                                sx, sy);
  GridPlanner planner;
  std::vector<std::uint32_t> path;
  EXPECT_EQ(PlanStatus::NoPath, planner.makePlan(costs.data(), sx, sy, 0, 3, path));
  EXPECT_TRUE(path.empty());
}

TEST(Planner, ReportsBlockedGoalAndClosedCorridor)
{
  unsigned int sx = 0, sy = 0;
  const std::vector<std::uint8_t> costs = parse({ "....#....",
                                                  "....#....",
                                                  "....#...#" },
                                                sx, sy);
  GridPlanner planner;
  std::vector<std::uint32_t> path;
  EXPECT_EQ(PlanStatus::NoPath, planner.makePlan(costs.data(), sx, sy, 0, 7, path));
  EXPECT_EQ(PlanStatus::GoalBlocked, planner.makePlan(costs.data(), sx, sy, 0, 4, path));
  EXPECT_EQ(PlanStatus::GoalOffGrid, planner.makePlan(costs.data(), sx, sy, 0, 999, path));
}

TEST(Planner, PrefersCheapCellsAndEscapesInscribedStart)
{
  // Start in an inscribed cell (253) next to a wall: the plan may leave through inscribed cells.
  const unsigned int sx = 5, sy = 3;
  std::vector<std::uint8_t> costs = { 254, 253, 253, 0, 0,   //
                                      254, 253, 253, 0, 0,   //
                                      254, 253, 253, 0, 0 };
  GridPlanner planner;
  std::vector<std::uint32_t> path;
  ASSERT_EQ(PlanStatus::Ok, planner.makePlan(costs.data(), sx, sy, 1 * sx + 1, 1 * sx + 4, path));
  EXPECT_EQ(4u, path.size());
  // Never into a lethal cell, even when escaping.
  EXPECT_EQ(PlanStatus::GoalBlocked, planner.makePlan(costs.data(), sx, sy, 1 * sx + 1, 1 * sx + 0, path));
  costs[1 * sx + 3] = 254;
  costs[0 * sx + 3] = 254;
  costs[2 * sx + 3] = 254;
  EXPECT_EQ(PlanStatus::NoPath, planner.makePlan(costs.data(), sx, sy, 1 * sx + 1, 1 * sx + 4, path));
}

TEST(Planner, EscapeStaysNearTheStart)
{
  // A long inscribed ridge from the start: escaping may use its first cells only.
  const unsigned int sx = 12, sy = 3;
  std::vector<std::uint8_t> costs(sx * sy, 254);
  for (unsigned int x = 0; x < sx; ++x)
  {
    costs[1 * sx + x] = 253;
  }
  costs[1 * sx + 11] = 0;
  PlannerParams params;
  params.escape_cells = 3;
  GridPlanner planner(params);
  std::vector<std::uint32_t> path;
  EXPECT_EQ(PlanStatus::NoPath, planner.makePlan(costs.data(), sx, sy, 1 * sx + 0, 1 * sx + 11, path));
  params.escape_cells = 20;
  GridPlanner wide(params);
  EXPECT_EQ(PlanStatus::Ok, wide.makePlan(costs.data(), sx, sy, 1 * sx + 0, 1 * sx + 11, path));
}

TEST(Planner, WindowLimitsTheSearch)
{
  unsigned int sx = 0, sy = 0;
  const std::vector<std::uint8_t> costs = parse({ ".........",
                                                  "....#....",
                                                  "....#....",
                                                  "....#...." },
                                                sx, sy);
  GridPlanner planner;
  std::vector<std::uint32_t> path;
  ASSERT_EQ(PlanStatus::Ok, planner.makePlan(costs.data(), sx, sy, 0, 8, path));
  CellWindow window{ 0, 0, 9, 3 };  // the top row, the only way round, is outside
  EXPECT_EQ(PlanStatus::NoPath, planner.makePlan(costs.data(), sx, sy, 0, 8, path, &window));
}

TEST(Planner, FirstBlockedFindsTheFirstObstacleAhead)
{
  const std::vector<std::uint8_t> costs = { 0, 10, 253, 0, 254, 255 };
  const std::vector<std::uint32_t> path = { 0, 1, 2, 3, 4, 5 };
  EXPECT_EQ(2, firstBlocked(costs.data(), costs.size(), path, 0, 6, 253));
  EXPECT_EQ(4, firstBlocked(costs.data(), costs.size(), path, 3, 6, 253));
  EXPECT_EQ(-1, firstBlocked(costs.data(), costs.size(), path, 0, 2, 253));
  EXPECT_EQ(-1, firstBlocked(costs.data(), costs.size(), path, 5, 1, 253));  // unknown is not blocked
}
