// Updates applied in any order, any number of times, give the same cells everywhere.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "sharing_layer/sharing_core.h"

using namespace sharing_layer;

namespace
{
GridGeometry grid()
{
  return GridGeometry(0.1, 0.0, 0.0, 30, 30);
}

/// A random history of one obstacle: robots take turns to mark and clear cells of a 10 x 10 patch,
/// each update one version above the highest its maker has seen (Lamport), sometimes concurrently.
std::vector<ObstacleUpdate> randomHistory(std::mt19937& rng, int updates)
{
  const std::vector<std::string> robots = { "robot_0", "robot_1", "robot_2" };
  std::vector<std::uint64_t> seen(robots.size(), 1);
  std::vector<ObstacleUpdate> history;
  std::uniform_int_distribution<int> coord(10, 19);
  std::uniform_int_distribution<int> count(0, 12);
  std::uniform_int_distribution<std::size_t> who(0, robots.size() - 1);

  ObstacleUpdate first;
  first.uuid = "7d3c1a8e-5b6f-4c2d-9e8f-0a1b2c3d4e5f";
  for (int i = 0; i < 20; ++i)
  {
    first.marked.push_back(static_cast<std::uint32_t>(coord(rng) * 30 + coord(rng)));
  }
  first.deadline = 60;
  first.rectangle = Subsection(1.0, 1.0, 2.0, 2.0);
  first.source = "robot_0";
  first.geometry = grid();
  first.version = 1;
  history.push_back(first);

  for (int u = 0; u < updates; ++u)
  {
    const std::size_t r = who(rng);
    // A robot has seen a random prefix of the history: versions may collide across robots.
    seen[r] = std::max(seen[r], history[std::uniform_int_distribution<std::size_t>(0, history.size() - 1)(rng)].version);
    ObstacleUpdate update = first;
    update.marked.clear();
    for (int i = count(rng); i > 0; --i)
    {
      update.marked.push_back(static_cast<std::uint32_t>(coord(rng) * 30 + coord(rng)));
    }
    for (int i = count(rng); i > 0; --i)
    {
      update.cleared.push_back(static_cast<std::uint32_t>(coord(rng) * 30 + coord(rng)));
    }
    update.source = robots[r];
    update.version = ++seen[r];
    history.push_back(update);
  }
  return history;
}
}  // namespace

TEST(Convergence, AnyOrderAndDuplicationGiveTheSameCells)
{
  std::mt19937 rng(20190501);
  for (int trial = 0; trial < 200; ++trial)
  {
    const std::vector<ObstacleUpdate> history = randomHistory(rng, 15);
    std::vector<std::uint32_t> reference;
    for (int receiver = 0; receiver < 4; ++receiver)
    {
      std::vector<ObstacleUpdate> delivery = history;
      // Duplicates: some updates arrive twice.
      for (int d = 0; d < 5; ++d)
      {
        delivery.push_back(history[std::uniform_int_distribution<std::size_t>(0, history.size() - 1)(rng)]);
      }
      std::shuffle(delivery.begin(), delivery.end(), rng);
      SharingCore core(grid(), LayerParams());
      for (const auto& update : delivery)
      {
        ASSERT_TRUE(core.applyShared(update, 0.0).ok);
      }
      const auto cells = core.sharedCells(history[0].uuid);
      if (receiver == 0)
      {
        reference = cells;
      }
      ASSERT_EQ(reference, cells) << "trial " << trial << ", receiver " << receiver;
    }
  }
}

TEST(Convergence, InOrderDeliveryMeansAddMarkedThenRemoveCleared)
{
  // With causal (in-order) delivery the result is the thesis's plain rule, applied update by update.
  VersionedCellSet cells;
  cells.apply({ 1, 2, 3 }, {}, 1, "robot_0");
  cells.apply({ 4 }, { 2 }, 2, "robot_1");
  cells.apply({ 2 }, { 2, 3 }, 3, "robot_0");  // marked then cleared in the same update: cleared wins
  EXPECT_EQ((std::vector<std::uint32_t>{ 1, 4 }), cells.present());
  // An old mark arriving late does not bring a cleared cell back.
  cells.apply({ 3 }, {}, 2, "robot_2");
  EXPECT_EQ((std::vector<std::uint32_t>{ 1, 4 }), cells.present());
  EXPECT_EQ(2u, cells.presentCount());
}

TEST(Convergence, TiesBetweenRobotsBreakBySourceName)
{
  VersionedCellSet a, b;
  a.apply({ 5 }, {}, 2, "robot_0");
  a.apply({}, { 5 }, 2, "robot_1");
  b.apply({}, { 5 }, 2, "robot_1");
  b.apply({ 5 }, {}, 2, "robot_0");
  EXPECT_EQ(a.present(), b.present());
  EXPECT_TRUE(a.present().empty());  // "robot_1" > "robot_0": its clear wins either way
}
