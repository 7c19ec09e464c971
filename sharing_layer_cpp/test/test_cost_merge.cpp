// The layer's merge into the master grid (sharing_layer/cost_merge.h) against costmap_2d's rules written out cell
// by cell, as CostmapLayer::updateWithMax and updateWithOverwrite state them, over random grids and windows.
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

#include "sharing_layer/cost_merge.h"
#include "sharing_layer/cost_values.h"

namespace sharing_layer
{
namespace
{
using Grid = std::vector<std::uint8_t>;

void referenceMax(const Grid& layer, Grid& master, const MergeWindow& w)
{
  for (int j = w.min_j; j < w.max_j; ++j)
  {
    for (int i = w.min_i; i < w.max_i; ++i)
    {
      const std::size_t it = static_cast<std::size_t>(j) * w.row_size + static_cast<std::size_t>(i);
      if (layer[it] == NO_INFORMATION)
      {
        continue;
      }
      if (master[it] == NO_INFORMATION || master[it] < layer[it])
      {
        master[it] = layer[it];
      }
    }
  }
}

void referenceOverwrite(const Grid& layer, Grid& master, const MergeWindow& w)
{
  for (int j = w.min_j; j < w.max_j; ++j)
  {
    for (int i = w.min_i; i < w.max_i; ++i)
    {
      const std::size_t it = static_cast<std::size_t>(j) * w.row_size + static_cast<std::size_t>(i);
      if (layer[it] != NO_INFORMATION)
      {
        master[it] = layer[it];
      }
    }
  }
}

/// Costs drawn mostly from the values the rules treat specially, the rest uniformly.
Grid randomGrid(std::mt19937& rng, std::size_t cells)
{
  static const std::uint8_t kSpecial[] = { 0, 1, 127, 252, 253, 254, 255 };
  std::uniform_int_distribution<int> any(0, 255), pick(0, 6), coin(0, 1);
  Grid grid(cells);
  for (std::uint8_t& c : grid)
  {
    c = coin(rng) ? kSpecial[pick(rng)] : static_cast<std::uint8_t>(any(rng));
  }
  return grid;
}

TEST(CostMerge, MaxAndOverwriteAreCostmap2dsRulesOnEveryCellOfRandomWindows)
{
  std::mt19937 rng(7);
  for (int round = 0; round < 300; ++round)
  {
    const int size_x = std::uniform_int_distribution<int>(1, 97)(rng);
    const int size_y = std::uniform_int_distribution<int>(1, 41)(rng);
    const std::size_t cells = static_cast<std::size_t>(size_x) * static_cast<std::size_t>(size_y);
    std::uniform_int_distribution<int> ix(0, size_x), iy(0, size_y);
    int a = ix(rng), b = ix(rng), c = iy(rng), d = iy(rng);
    if (round % 10 != 0)  // every tenth window is inverted or empty: it must merge nothing
    {
      if (a > b) std::swap(a, b);
      if (c > d) std::swap(c, d);
    }
    const MergeWindow window{ static_cast<std::size_t>(size_x), a, c, b, d };
    const Grid layer = randomGrid(rng, cells), master = randomGrid(rng, cells);

    Grid expected = master, got = master;
    referenceMax(layer, expected, window);
    mergeMax(layer.data(), got.data(), window);
    ASSERT_EQ(got, expected) << "max, round " << round << ", window [" << a << ", " << b << ") x [" << c << ", " << d
                             << ") of " << size_x << " x " << size_y;

    expected = master, got = master;
    referenceOverwrite(layer, expected, window);
    mergeOverwrite(layer.data(), got.data(), window);
    ASSERT_EQ(got, expected) << "overwrite, round " << round;
  }
}

// Every pair of costs, 256 x 256 in one window (row m: the master's cost m beside each of the layer's 256), so that
// the pairs go through the vector lanes that merge 16 cells at a time as well as the scalar rule.
TEST(CostMerge, EveryPairOfCostsFollowsBothRulesInTheVectorLanes)
{
  Grid master(256 * 256), layer(256 * 256);
  for (std::size_t m = 0; m < 256; ++m)
  {
    for (std::size_t l = 0; l < 256; ++l)
    {
      master[m * 256 + l] = static_cast<std::uint8_t>(m);
      layer[m * 256 + l] = static_cast<std::uint8_t>(l);
    }
  }
  const MergeWindow window{ 256, 0, 0, 256, 256 };
  for (const bool overwrite : { false, true })
  {
    Grid expected = master, got = master;
    if (overwrite)
    {
      referenceOverwrite(layer, expected, window);
      mergeOverwrite(layer.data(), got.data(), window);
    }
    else
    {
      referenceMax(layer, expected, window);
      mergeMax(layer.data(), got.data(), window);
    }
    for (std::size_t i = 0; i < got.size(); ++i)
    {
      ASSERT_EQ(expected[i], got[i]) << (overwrite ? "overwrite" : "max") << ": master " << i / 256 << ", layer "
                                     << i % 256;
    }
  }
}

TEST(CostMerge, EveryPairOfCostsFollowsTheMaxRule)
{
  for (int m = 0; m < 256; ++m)
  {
    for (int l = 0; l < 256; ++l)
    {
      Grid master{ static_cast<std::uint8_t>(m) }, expected = master;
      const Grid layer{ static_cast<std::uint8_t>(l) };
      const MergeWindow window{ 1, 0, 0, 1, 1 };
      referenceMax(layer, expected, window);
      mergeMax(layer.data(), master.data(), window);
      ASSERT_EQ(master, expected) << "master " << m << ", layer " << l;
    }
  }
}
}  // namespace
}  // namespace sharing_layer
