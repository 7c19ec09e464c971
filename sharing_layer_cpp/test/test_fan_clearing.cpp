// clearFan against raytracing beam by beam: the same cells, in every octant, for sparse and dense fans, cut lines,
// lines in every direction of slope ties, and the reference scan of the benchmarks.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "../bench/reference_scene.h"
#include "sharing_layer/fan_clearing.h"
#include "sharing_layer/raytrace.h"

using sharing_layer::clearFan;
using sharing_layer::FanStats;
using sharing_layer::kNearSteps;
using sharing_layer::LineSteps;

namespace
{
constexpr std::uint8_t kUntouched = 7;
constexpr std::uint8_t kCleared = 0;

/// Lines from one start cell, kept both as raytraceLine's arguments (the reference) and as clearFan's input.
struct Fan
{
  unsigned int size_x = 0, size_y = 0, x0 = 0, y0 = 0;
  struct End
  {
    unsigned int x1, y1, max_length;
  };
  std::vector<End> ends;
  std::vector<LineSteps> lines;

  /// A line from (x0, y0) to (x1, y1), cut to max_length cells.
  void to(unsigned int x1, unsigned int y1, unsigned int max_length = UINT_MAX)
  {
    ends.push_back(End{ x1, y1, max_length });
    lines.emplace_back(x0, y0, x1, y1, max_length);
  }
};

/// The reference: raytraceLine, costmap_2d's semantics (test_raytrace), beam by beam.
std::vector<std::uint8_t> beamByBeam(const Fan& fan)
{
  std::vector<std::uint8_t> grid(static_cast<std::size_t>(fan.size_x) * fan.size_y, kUntouched);
  const sharing_layer::SetCellAction clear{ grid.data(), kCleared };
  for (const Fan::End& end : fan.ends)
  {
    sharing_layer::raytraceLine(clear, fan.x0, fan.y0, end.x1, end.y1, fan.size_x, end.max_length);
  }
  return grid;
}

std::vector<std::uint8_t> together(const Fan& fan, FanStats* stats = nullptr)
{
  std::vector<std::uint8_t> grid(static_cast<std::size_t>(fan.size_x) * fan.size_y, kUntouched);
  const FanStats s = clearFan(grid.data(), fan.size_x, fan.x0, fan.y0, fan.lines, kCleared);
  if (stats != nullptr)
  {
    *stats = s;
  }
  return grid;
}

/// The first cell where the two grids differ, as "(x, y): beam by beam v, together w"; empty when equal.
std::string firstDifference(const Fan& fan, const std::vector<std::uint8_t>& expected,
                            const std::vector<std::uint8_t>& actual)
{
  for (std::size_t i = 0; i < expected.size(); ++i)
  {
    if (expected[i] != actual[i])
    {
      return "(" + std::to_string(i % fan.size_x) + ", " + std::to_string(i / fan.size_x) + "): beam by beam " +
             std::to_string(expected[i]) + ", together " + std::to_string(actual[i]);
    }
  }
  return "";
}

/// A laser-like fan: `beams` beams over `span` radians from `first`, each to a random range (some cut by
/// max_length, all clipped to the grid as costmap_2d clips endpoints).
Fan randomFan(std::mt19937& rng, unsigned int beams, double span, double first, double max_range,
              unsigned int max_length)
{
  Fan fan;
  fan.size_x = 60 + rng() % 400;
  fan.size_y = 60 + rng() % 400;
  fan.x0 = rng() % fan.size_x;
  fan.y0 = rng() % fan.size_y;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (unsigned int i = 0; i < beams; ++i)
  {
    const double angle = first + span * i / std::max(1u, beams - 1);
    const double range = unit(rng) < 0.2 ? unit(rng) * 30.0 : unit(rng) * max_range;
    const int ex = std::max(0, std::min(static_cast<int>(fan.size_x) - 1,
                                        static_cast<int>(std::lround(fan.x0 + range * std::cos(angle)))));
    const int ey = std::max(0, std::min(static_cast<int>(fan.size_y) - 1,
                                        static_cast<int>(std::lround(fan.y0 + range * std::sin(angle)))));
    fan.to(static_cast<unsigned int>(ex), static_cast<unsigned int>(ey), max_length);
  }
  return fan;
}

/// The benchmarks' reference scan as a fan from its origin, every beam cut at range_m.
void referenceFan(double range_m, Fan* fan)
{
  const sharing_layer::bench::Scene scene = sharing_layer::bench::makeScene();
  const sharing_layer::GridGeometry& g = scene.geometry;
  fan->size_x = g.size_x;
  fan->size_y = g.size_y;
  ASSERT_TRUE(g.worldToMap(scene.scan.origin.x, scene.scan.origin.y, fan->x0, fan->y0));
  for (const sharing_layer::Point3& p : scene.scan.points)
  {
    unsigned int x1 = 0, y1 = 0;
    ASSERT_TRUE(g.worldToMap(p.x, p.y, x1, y1));
    fan->to(x1, y1, g.cellDistance(range_m));
  }
}
}  // namespace

TEST(FanClearing, RandomFansClearTheCellsOfEveryBeam)
{
  std::mt19937 rng(29);
  FanStats total;
  for (int trial = 0; trial < 400; ++trial)
  {
    const unsigned int beams = 5 + rng() % 2000;
    const double span = (trial % 3 == 0) ? 2.0 * M_PI : 0.2 + 4.5 * (rng() % 1000) / 1000.0;
    const double first = 2.0 * M_PI * (rng() % 1000) / 1000.0;
    const unsigned int max_length = (trial % 4 == 0) ? UINT_MAX : 20 + rng() % 400;
    const Fan fan = randomFan(rng, beams, span, first, 500.0, max_length);
    FanStats stats;
    const std::string difference = firstDifference(fan, beamByBeam(fan), together(fan, &stats));
    ASSERT_EQ("", difference) << "trial " << trial << ": " << beams << " beams from (" << fan.x0 << ", " << fan.y0
                              << ") on " << fan.size_x << " x " << fan.size_y;
    total.groups += stats.groups;
    total.grouped_beams += stats.grouped_beams;
  }
  // The fill ran: the equality above is not raytracing beam by beam again.
  EXPECT_GT(total.groups, 400u);
  EXPECT_GT(total.grouped_beams, 20000u);
}

TEST(FanClearing, TheReferenceScanIsFilledNearTheSensorAndEqualToRaytracing)
{
  Fan fan;
  ASSERT_NO_FATAL_FAILURE(referenceFan(30.0, &fan));
  FanStats stats;
  EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan, &stats)));
  // Most beams share the near field, which then takes a fraction of their steps.
  EXPECT_GT(stats.grouped_beams, fan.lines.size() * 8 / 10);
  EXPECT_LT(stats.near_cells, stats.grouped_beams * (kNearSteps + 1) / 3);
}

TEST(FanClearing, TheReferenceScanCutAtThreeMetresIsFilledThoughNoBeamReachesTheNearSteps)
{
  // raytrace_range 3 m: every beam is cut at 60 cells, before kNearSteps; the runs fill as far as their shortest beam.
  Fan fan;
  ASSERT_NO_FATAL_FAILURE(referenceFan(3.0, &fan));
  for (const LineSteps& line : fan.lines)
    ASSERT_LT(line.end, kNearSteps);
  FanStats stats;
  EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan, &stats)));
  EXPECT_GT(stats.grouped_beams, fan.lines.size() * 8 / 10);
  EXPECT_LT(stats.near_cells, stats.grouped_beams * 60 / 6);
}

TEST(FanClearing, ABeamEndingCloseIsRaytracedAloneAndShrinkingBeamsStartRunsOfTheirOwn)
{
  // 60 beams close together along +x, 240 cells long but for: beam 10, which ends at step 20 (on something close),
  // and beams 25 on, cut shorter and shorter, from 100 down to 32 cells (as raytrace_range cuts beams along an
  // octant). The fill must not reach past any beam's end, nor miss a cell of the long ones.
  Fan fan;
  fan.size_x = fan.size_y = 400;
  fan.x0 = fan.y0 = 100;
  for (unsigned int i = 0; i < 60; ++i)
  {
    if (i == 10)
    {
      fan.to(120, 101);  // about the same direction, 20 steps
      continue;
    }
    fan.to(340, 100 + i, i < 25 ? UINT_MAX : 100 - 2 * (i - 25));
  }
  FanStats stats;
  EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan, &stats)));
  // The long beams in one run across beam 10, the shrinking ones below kNearSteps in one of their own.
  EXPECT_EQ(2u, stats.groups);
}

TEST(FanClearing, EveryOctantAndTheAxesBetweenThem)
{
  // 64 beams close together around each of the 16 directions k * 22.5 degrees (axes, diagonals and between),
  // long enough to be grouped, on a grid where the far ends are clipped.
  for (int k = 0; k < 16; ++k)
  {
    Fan fan;
    fan.size_x = fan.size_y = 301;
    fan.x0 = fan.y0 = 150;
    for (int i = -32; i < 32; ++i)
    {
      const double angle = k * M_PI / 8.0 + i * 0.002;
      const int ex = std::max(0, std::min(300, static_cast<int>(std::lround(150 + 200 * std::cos(angle)))));
      const int ey = std::max(0, std::min(300, static_cast<int>(std::lround(150 + 200 * std::sin(angle)))));
      fan.to(static_cast<unsigned int>(ex), static_cast<unsigned int>(ey));
    }
    FanStats stats;
    EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan, &stats))) << "direction " << k;
    EXPECT_GT(stats.grouped_beams, 0u) << "direction " << k;
  }
}

TEST(FanClearing, EqualSlopesWithOddAndEvenLengthsStartDifferently)
{
  // (3, 1), (6, 2), (9, 3), ... : one slope, but bresenham2D starts an odd-length line's error at (A - 1) / 2, so
  // their cells differ where the exact line crosses a cell's middle. Mixed with their neighbours in direction,
  // and not in order of slope.
  Fan fan;
  fan.size_x = fan.size_y = 400;
  fan.x0 = fan.y0 = 10;
  for (unsigned int n = 22; n < 120; ++n)
  {
    fan.to(10 + 3 * n, 10 + n);
    fan.to(10 + 3 * n + 1, 10 + n);
  }
  FanStats stats;
  EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan, &stats)));
  EXPECT_GT(stats.grouped_beams, 0u);
}

TEST(FanClearing, ShortAndZeroLengthLinesAreRaytracedAlone)
{
  Fan fan;
  fan.size_x = fan.size_y = 50;
  fan.x0 = 20;
  fan.y0 = 30;
  fan.to(20, 30);  // the start cell only
  fan.to(25, 31);
  fan.to(0, 0);
  fan.to(49, 49, 10);  // cut to 10 cells
  FanStats stats;
  EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan, &stats)));
  EXPECT_EQ(0u, stats.groups);
}

TEST(FanClearing, AnEmptyFanWritesNothing)
{
  Fan fan;
  fan.size_x = fan.size_y = 10;
  const std::vector<std::uint8_t> grid = together(fan);
  EXPECT_EQ(std::vector<std::uint8_t>(100, kUntouched), grid);
}

TEST(FanClearing, LongLinesAndWideGridsAroundTheReciprocalLimits)
{
  // Lines up to 16384 cells along a are stepped by a reciprocal, longer ones (and any on grids wider than 32767)
  // by bresenham2D: both sides of each limit, in a few rows so that the grids stay small.
  for (const unsigned int size_x : { 20000u, 40000u })
  {
    Fan fan;
    fan.size_x = size_x;
    fan.size_y = 7;
    fan.x0 = 1;
    fan.y0 = 3;
    for (const unsigned int length : { 16383u, 16384u, 16385u, 19998u })
    {
      for (const unsigned int y1 : { 0u, 1u, 3u, 5u, 6u })
      {
        fan.to(1 + length, y1);
      }
    }
    fan.to(1 + 16384, 6, 9000);  // cut
    EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan))) << size_x << " cells wide";
  }
  // And along y: a tall, narrow grid.
  Fan fan;
  fan.size_x = 5;
  fan.size_y = 20000;
  fan.x0 = 2;
  fan.y0 = 19990;
  for (const unsigned int length : { 16383u, 16384u, 16385u, 19990u })
  {
    for (const unsigned int x1 : { 0u, 1u, 3u, 4u })
    {
      fan.to(x1, 19990 - length);
    }
  }
  EXPECT_EQ("", firstDifference(fan, beamByBeam(fan), together(fan)));
}
