#include "sharing_layer/shared_obstacle.h"

#include <algorithm>

namespace sharing_layer
{
std::uint32_t VersionedCellSet::sourceId(const std::string& source)
{
  for (std::uint32_t i = 0; i < sources_.size(); ++i)
  {
    if (sources_[i] == source)
    {
      return i;
    }
  }
  sources_.push_back(source);
  return static_cast<std::uint32_t>(sources_.size() - 1);
}

std::size_t VersionedCellSet::remap(const std::function<bool(std::uint32_t, std::uint32_t&)>& to_new)
{
  std::unordered_map<std::uint32_t, CellState> moved;
  std::size_t dropped = 0;
  for (const auto& entry : cells_)
  {
    std::uint32_t index = 0;
    if (!to_new(entry.first, index))
    {
      dropped += entry.second.present;
      continue;
    }
    const CellState& cell = entry.second;
    const auto found = moved.find(index);
    if (found == moved.end())
    {
      moved.emplace(index, cell);
    }
    else if (newer(found->second, cell.version, cell.source, !cell.present))
    {
      found->second = cell;
    }
  }
  cells_.swap(moved);
  present_count_ = 0;
  for (const auto& entry : cells_)
  {
    present_count_ += entry.second.present;
  }
  present_cache_valid_ = false;
  return dropped;
}

bool VersionedCellSet::newer(const CellState& cell, std::uint64_t version, std::uint32_t source,
                             bool or_equal) const
{
  if (version != cell.version)
  {
    return version > cell.version;
  }
  const int order = sources_[source].compare(sources_[cell.source]);
  return order > 0 || (or_equal && order == 0);
}

std::size_t VersionedCellSet::apply(const std::vector<std::uint32_t>& marked,
                                    const std::vector<std::uint32_t>& cleared, std::uint64_t version,
                                    const std::string& source)
{
  const std::uint32_t source_id = sourceId(source);
  std::size_t changed = 0;
  for (std::uint32_t index : marked)
  {
    auto found = cells_.find(index);
    if (found == cells_.end())
    {
      cells_.emplace(index, CellState{ version, source_id, true });
      ++present_count_;
      ++changed;
    }
    else if (newer(found->second, version, source_id, false))
    {
      if (!found->second.present)
      {
        ++present_count_;
        ++changed;
      }
      found->second = CellState{ version, source_id, true };
    }
  }
  for (std::uint32_t index : cleared)
  {
    auto found = cells_.find(index);
    if (found == cells_.end())
    {
      // A tombstone, so an older mark that arrives later cannot bring the cell back.
      cells_.emplace(index, CellState{ version, source_id, false });
    }
    else if (newer(found->second, version, source_id, true))
    {
      if (found->second.present)
      {
        --present_count_;
        ++changed;
      }
      found->second = CellState{ version, source_id, false };
    }
  }
  present_cache_valid_ = present_cache_valid_ && changed == 0;
  return changed;
}

bool VersionedCellSet::isPresent(std::uint32_t index) const
{
  const auto found = cells_.find(index);
  return found != cells_.end() && found->second.present;
}

const std::vector<std::uint32_t>& VersionedCellSet::present() const
{
  if (!present_cache_valid_)
  {
    present_cache_.clear();
    present_cache_.reserve(present_count_);
    for (const auto& entry : cells_)
    {
      if (entry.second.present)
      {
        present_cache_.push_back(entry.first);
      }
    }
    std::sort(present_cache_.begin(), present_cache_.end());
    present_cache_valid_ = true;
  }
  return present_cache_;
}

}  // namespace sharing_layer
