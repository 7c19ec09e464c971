#include "sharing_layer/obstacle_index.h"

#include <algorithm>
#include <limits>

namespace sharing_layer
{
void ObstacleIndex::add(SharedObstacle& obstacle)
{
  obstacle.index_slot = entries_.size();
  entries_.push_back(Entry{});
  entries_.back().obstacle = &obstacle;
  obstacle.flagged.clear();
  obstacle.watch_pending = false;
  changed(obstacle);
}

void ObstacleIndex::changed(SharedObstacle& obstacle)
{
  update(entries_[obstacle.index_slot]);
  if (!obstacle.watch_pending)
  {
    obstacle.watch_pending = true;
    pending_.push_back(&obstacle);
  }
}

void ObstacleIndex::update(Entry& entry)
{
  const SharedObstacle& obstacle = *entry.obstacle;
  entry.rectangle = obstacle.rectangle;
  entry.rectangle_cells = obstacle.rectangle_cells;
  const std::vector<std::uint32_t>& present = obstacle.cells.present();
  entry.first = present.empty() ? 1 : present.front();
  entry.last = present.empty() ? 0 : present.back();
}

void ObstacleIndex::remove(SharedObstacle& obstacle)
{
  released_.insert(released_.end(), obstacle.flagged.begin(), obstacle.flagged.end());
  obstacle.flagged.clear();
  if (obstacle.watch_pending)
  {
    pending_.erase(std::find(pending_.begin(), pending_.end(), &obstacle));
    obstacle.watch_pending = false;
  }
  // The last entry takes the removed one's slot.
  const std::size_t slot = obstacle.index_slot;
  entries_[slot] = entries_.back();
  entries_[slot].obstacle->index_slot = slot;
  entries_.pop_back();
}

void ObstacleIndex::rebuild(std::vector<SharedObstacle*> obstacles)
{
  entries_.clear();
  pending_.clear();
  released_.clear();
  extra_holders_.clear();
  for (SharedObstacle* obstacle : obstacles)
  {
    add(*obstacle);
  }
}

void ObstacleIndex::acquire(std::uint32_t cell, CellFlags& flags)
{
  if (flags.has(cell, CellFlags::kFlaggedWatched))
  {
    ++extra_holders_[cell];
  }
  else
  {
    flags.set(cell, CellFlags::kFlaggedWatched);
  }
}

void ObstacleIndex::release(std::uint32_t cell, CellFlags& flags)
{
  const auto extra = extra_holders_.find(cell);
  if (extra == extra_holders_.end())
  {
    flags.clear(cell, CellFlags::kFlaggedWatched);
  }
  else if (--extra->second == 0)
  {
    extra_holders_.erase(extra);
  }
}

void ObstacleIndex::refreshWatchFlags(const GridGeometry& g, CellFlags& flags)
{
  for (std::uint32_t cell : released_)
  {
    release(cell, flags);
  }
  released_.clear();
  for (SharedObstacle* obstacle : pending_)
  {
    obstacle->watch_pending = false;
    const std::vector<std::uint32_t>& present = obstacle->cells.present();
    std::vector<std::uint32_t>& was = obstacle->flagged;  // both sorted: what left, what came
    auto w = was.begin();
    auto p = present.begin();
    while (w != was.end() || p != present.end())
    {
      if (p == present.end() || (w != was.end() && *w < *p))
      {
        release(*w++, flags);
      }
      else if (w == was.end() || *p < *w)
      {
        acquire(*p++, flags);
      }
      else
      {
        ++w;
        ++p;
      }
    }
    was = present;
    obstacle->present_box = CellRect{ 0, 0, -1, -1 };
    if (!present.empty())
    {
      // Sorted: the first and last cells give the rows.
      CellRect box{ std::numeric_limits<int>::max(), static_cast<int>(present.front() / g.size_x),
                    std::numeric_limits<int>::min(), static_cast<int>(present.back() / g.size_x) };
      for (std::uint32_t index : present)
      {
        const int x = static_cast<int>(index % g.size_x);
        box.min_x = std::min(box.min_x, x);
        box.max_x = std::max(box.max_x, x);
      }
      obstacle->present_box = box;
    }
  }
  pending_.clear();
}

std::size_t ObstacleIndex::overlaps() const
{
  std::size_t n = 0;
  for (const auto& extra : extra_holders_)
  {
    n += extra.second;
  }
  return n;
}

}  // namespace sharing_layer
