// The obstacles' index (obstacle_index.h): the watch flags it keeps obstacle by obstacle are those of every present
// cell of every obstacle held, whatever came, changed and went in between (overlaps included); drawing reads the
// entries' cell ranges and still draws every present cell in the window; and only a change of what is drawn
// dirties the master (issue 48).
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "sharing_layer/cell_flags.h"
#include "sharing_layer/cost_values.h"
#include "sharing_layer/obstacle_index.h"
#include "sharing_layer/sharing_core.h"

using namespace sharing_layer;

namespace
{
constexpr unsigned int kSize = 60;

GridGeometry grid()
{
  return GridGeometry(0.1, 0.0, 0.0, kSize, kSize);
}

/// What the flags must say: the union of every held obstacle's present cells.
std::set<std::uint32_t> presentUnion(const std::map<std::string, SharedObstacle>& held)
{
  std::set<std::uint32_t> cells;
  for (const auto& entry : held)
  {
    const std::vector<std::uint32_t>& present = entry.second.cells.present();
    cells.insert(present.begin(), present.end());
  }
  return cells;
}

std::set<std::uint32_t> flagged(const CellFlags& flags)
{
  std::set<std::uint32_t> cells;
  for (std::uint32_t i = 0; i < kSize * kSize; ++i)
  {
    if (flags.has(i, CellFlags::kFlaggedWatched))
    {
      cells.insert(i);
    }
  }
  return cells;
}

ObstacleUpdate share(const std::string& uuid, std::vector<std::uint32_t> marked, std::uint64_t version,
                     std::vector<std::uint32_t> cleared = {})
{
  ObstacleUpdate u;
  u.uuid = uuid;
  u.marked = std::move(marked);
  u.cleared = std::move(cleared);
  u.deadline = 60;
  u.rectangle = Subsection(0.0, 0.0, 1.0, 1.0);
  u.source = "robot_1";
  u.geometry = grid();
  u.version = version;
  return u;
}
}  // namespace

TEST(ObstacleIndex, WatchFlagsAreEveryPresentCellAfterAnyAddChangeAndRemove)
{
  // Obstacles in a small area so that they overlap often: a cell two obstacles hold keeps its flag until both let it
  // go. Checked against the union of present cells after every refresh, and the entries against the obstacles.
  std::mt19937 rng(48);
  std::map<std::string, SharedObstacle> held;
  ObstacleIndex index;
  CellFlags flags;
  flags.assign(kSize * kSize);
  std::uint64_t version = 1;
  std::size_t overlaps_seen = 0;
  for (int step = 0; step < 3000; ++step)
  {
    const std::string uuid = "o" + std::to_string(rng() % 12);
    const auto found = held.find(uuid);
    const int action = static_cast<int>(rng() % 10);
    if (found != held.end() && action == 0)
    {
      index.remove(found->second);
      held.erase(found);
    }
    else
    {
      std::vector<std::uint32_t> marked, cleared;
      for (int k = 0; k < 3; ++k)
      {
        marked.push_back(static_cast<std::uint32_t>(rng() % 40));  // the first 40 cells: overlaps
        cleared.push_back(static_cast<std::uint32_t>(rng() % 40));
      }
      std::sort(marked.begin(), marked.end());
      marked.erase(std::unique(marked.begin(), marked.end()), marked.end());
      std::sort(cleared.begin(), cleared.end());
      cleared.erase(std::unique(cleared.begin(), cleared.end()), cleared.end());
      SharedObstacle* obstacle = nullptr;
      if (found == held.end())
      {
        obstacle = &held[uuid];
        obstacle->uuid = uuid;
        index.add(*obstacle);
      }
      else
      {
        obstacle = &found->second;
      }
      if (obstacle->cells.apply(marked, cleared, ++version, "robot_1") != 0 || found == held.end())
      {
        index.changed(*obstacle);
      }
    }
    if (rng() % 3 == 0)
    {
      index.refreshWatchFlags(grid(), flags);
      ASSERT_FALSE(index.stale());
      ASSERT_EQ(presentUnion(held), flagged(flags)) << "step " << step;
      overlaps_seen += index.overlaps();
    }
    ASSERT_EQ(held.size(), index.entries().size()) << "step " << step;
    for (const ObstacleIndex::Entry& entry : index.entries())
    {
      const std::vector<std::uint32_t>& present = entry.obstacle->cells.present();
      ASSERT_EQ(present.empty() ? 1u : present.front(), entry.first) << entry.obstacle->uuid << ", step " << step;
      ASSERT_EQ(present.empty() ? 0u : present.back(), entry.last) << entry.obstacle->uuid << ", step " << step;
      ASSERT_EQ(entry.obstacle, index.entries()[entry.obstacle->index_slot].obstacle);
    }
  }
  EXPECT_GT(overlaps_seen, 100u);  // the shared cells' counting ran
}

TEST(ObstacleIndex, AnObstacleWhoseCellsMoveToOtherRowsIsDrawnThereAndTheOthersStay)
{
  // The draw reads each entry's cell range before it looks at the obstacle: a change must move the range.
  SharingCore core(grid(), LayerParams{});
  for (int k = 0; k < 5; ++k)
  {
    ASSERT_TRUE(core.applyShared(share("a" + std::to_string(k), { static_cast<std::uint32_t>(k * kSize + 2) }, 1),
                                 0.0)
                    .ok);
  }
  ASSERT_TRUE(core.applyShared(share("a2", { 50 * kSize + 7 }, 2, { 2 * kSize + 2 }), 0.0).ok);
  ASSERT_TRUE(core.expire("a0"));  // the last entry takes its slot
  std::vector<std::uint8_t> master(kSize * kSize, FREE_SPACE);
  core.drawShared(master.data(), master.size(), 0, 40, static_cast<int>(kSize), static_cast<int>(kSize));
  EXPECT_EQ(LETHAL_OBSTACLE, master[50 * kSize + 7]) << "a2's new cell, 48 rows below its old range";
  std::fill(master.begin(), master.end(), FREE_SPACE);
  core.drawShared(master.data(), master.size());
  std::vector<std::uint32_t> lethal;
  for (std::uint32_t i = 0; i < master.size(); ++i)
  {
    if (master[i] == LETHAL_OBSTACLE)
    {
      lethal.push_back(i);
    }
  }
  const std::vector<std::uint32_t> expected = { 1 * kSize + 2, 3 * kSize + 2, 4 * kSize + 2, 50 * kSize + 7 };
  EXPECT_EQ(expected, lethal);
}

TEST(ObstacleIndex, OnlyAChangeOfWhatIsDrawnDirtiesTheMaster)
{
  SharingCore core(grid(), LayerParams{});
  ASSERT_TRUE(core.applyShared(share("a", { 5, 6 }, 1), 0.0).ok);
  EXPECT_FALSE(core.takeDirtyBounds().empty()) << "a new obstacle is drawn";
  // A renewal: cells present already, nothing to redraw (with many obstacles held far apart, such updates made
  // every cycle's window most of the map).
  ASSERT_TRUE(core.applyShared(share("a", { 5, 6 }, 2), 0.0).ok);
  EXPECT_TRUE(core.takeDirtyBounds().empty());
  // A cell cleared, then one marked: each redraws.
  ASSERT_TRUE(core.applyShared(share("a", {}, 3, { 6 }), 0.0).ok);
  const WorldBounds cleared = core.takeDirtyBounds();
  EXPECT_FALSE(cleared.empty());
  EXPECT_DOUBLE_EQ(0.6, cleared.min_x);
  ASSERT_TRUE(core.applyShared(share("a", { 6 }, 4), 0.0).ok);
  EXPECT_FALSE(core.takeDirtyBounds().empty());
  // An older version than the cell's (5 was marked again at 2) changes nothing.
  ASSERT_TRUE(core.applyShared(share("a", {}, 1, { 5 }), 0.0).ok);
  EXPECT_TRUE(core.takeDirtyBounds().empty());
  std::vector<std::uint8_t> master(kSize * kSize, FREE_SPACE);
  core.drawShared(master.data(), master.size());
  EXPECT_EQ(LETHAL_OBSTACLE, master[5]);
  EXPECT_EQ(LETHAL_OBSTACLE, master[6]);
}
