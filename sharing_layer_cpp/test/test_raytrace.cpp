// Golden raytrace cases, drawn as ASCII maps (top row = highest y) and checked cell by cell
// against costmap_2d's raytraceLine/bresenham2D semantics.
#include <gtest/gtest.h>

#include <vector>

#include "ascii_grid.h"
#include "sharing_layer/raytrace.h"

using sharing_layer::CollectAction;
using sharing_layer::raytraceLine;
using sharing_layer::test::drawCells;
using sharing_layer::test::picture;

namespace
{
std::vector<std::uint32_t> trace(unsigned int x0, unsigned int y0, unsigned int x1, unsigned int y1,
                                 unsigned int size_x, unsigned int max_length = UINT_MAX)
{
  std::vector<std::uint32_t> cells;
  CollectAction<std::vector<std::uint32_t>> collect{ &cells };
  raytraceLine(collect, x0, y0, x1, y1, size_x, max_length);
  return cells;
}
}  // namespace

TEST(Raytrace, HorizontalLineIncludesBothEnds)
{
  EXPECT_EQ(picture({ ".......",
                      ".......",
                      "######." }),
            drawCells(trace(0, 0, 5, 0, 7), 7, 3));
}

TEST(Raytrace, ShallowSlopeStepsLikeBresenham)
{
  // (0,0) -> (6,2): x dominant, error starts at abs_dx / 2 = 3.
  EXPECT_EQ(picture({ ".....##",
                      "..###..",
                      "##....." }),
            drawCells(trace(0, 0, 6, 2, 7), 7, 3));
  EXPECT_EQ((std::vector<std::uint32_t>{ 0, 1, 9, 10, 11, 19, 20 }), trace(0, 0, 6, 2, 7));
}

TEST(Raytrace, SteepSlopeIsYDominant)
{
  EXPECT_EQ(picture({ "..#",
                      "..#",
                      ".#.",
                      ".#.",
                      "#..",
                      "#.." }),
            drawCells(trace(0, 0, 2, 5, 3), 3, 6));
}

TEST(Raytrace, DiagonalAndReverseDirectionVisitFromTheStart)
{
  EXPECT_EQ(picture({ "...#",
                      "..#.",
                      ".#..",
                      "#..." }),
            drawCells(trace(3, 3, 0, 0, 4), 4, 4));
  const auto cells = trace(3, 3, 0, 0, 4);
  ASSERT_EQ(4u, cells.size());
  EXPECT_EQ(15u, cells.front());  // the origin first
  EXPECT_EQ(0u, cells.back());    // the endpoint last
}

TEST(Raytrace, MaxLengthCutsTheLineAndKeepsTheCellReached)
{
  // 6 cells long, max_length 3: three steps plus the cell reached, the endpoint is not touched.
  EXPECT_EQ(picture({ "####..." }), drawCells(trace(0, 0, 6, 0, 7, 3), 7, 1));
  // max_length is Euclidean: along the diagonal 4 cells * sqrt(2) = 5.66, cut at 3 -> scale 0.53 -> 2 steps.
  EXPECT_EQ(picture({ "....",
                      "..#.",
                      ".#..",
                      "#..." }),
            drawCells(trace(0, 0, 3, 3, 4, 3), 4, 4));
}

TEST(Raytrace, ZeroLengthLineVisitsOneCell)
{
  EXPECT_EQ((std::vector<std::uint32_t>{ 12 }), trace(2, 2, 2, 2, 5));
  EXPECT_EQ((std::vector<std::uint32_t>{ 12 }), trace(2, 2, 2, 2, 5, 0));
}

TEST(Raytrace, VerticalLineDownwards)
{
  EXPECT_EQ(picture({ ".#",
                      ".#",
                      ".#",
                      ".." }),
            drawCells(trace(1, 3, 1, 1, 2), 2, 4));
}
