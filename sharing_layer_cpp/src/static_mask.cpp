#include "sharing_layer/static_mask.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace sharing_layer
{
void StaticMask::setWalls(const GridGeometry& geometry, const std::uint8_t* costs, std::size_t cost_count,
                          int tolerance, std::uint8_t occupied_cost)
{
  // Validate (size) before keeping anything.
  StaticMapFilter check(geometry, costs, cost_count, tolerance, occupied_cost);
  (void)check;
  setSource(kWalls, geometry.cellCount(), [&](std::size_t i) { return costs[i] >= occupied_cost; });
  rebuild(geometry, tolerance);
}

void StaticMask::setUnknown(const GridGeometry& geometry, const std::uint8_t* unknown, std::size_t cell_count,
                            int tolerance)
{
  if (unknown == nullptr || cell_count == 0)
  {
    if (given_ & kUnknown)
    {
      unknown_.release();
      given_ &= ~kUnknown;
    }
  }
  else
  {
    if (cell_count != geometry.cellCount())
    {
      throw std::invalid_argument("setUnknownMap: unknown mask has " + std::to_string(cell_count) +
                                  " cells, the layer grid " + geometry.describe());
    }
    setSource(kUnknown, cell_count, [&](std::size_t i) { return unknown[i] != 0; });
  }
  rebuild(geometry, tolerance);
}

void StaticMask::setTolerance(const GridGeometry& geometry, int tolerance)
{
  if (tolerance < 0)
  {
    throw std::invalid_argument("static_tolerance must be >= 0 cells, got " + std::to_string(tolerance));
  }
  rebuild(geometry, tolerance);
}

void StaticMask::clear()
{
  walls_.release();
  unknown_.release();
  given_ = 0;
  filter_ = StaticMapFilter();
}

template <class IsSet>
void StaticMask::setSource(std::uint8_t source, std::size_t cell_count, IsSet is_set)
{
  BitGrid& bits = source == kWalls ? walls_ : unknown_;
  bits.assign(cell_count);
  for (std::size_t i = 0; i < cell_count; ++i)
  {
    if (is_set(i))
    {
      bits.set(i);
    }
  }
  given_ |= source;
}

void StaticMask::rebuild(const GridGeometry& geometry, int tolerance)
{
  if (given_ == 0)
  {
    filter_ = StaticMapFilter();
    return;
  }
  // Occupied or unknown (a byte per cell only while the filter is built).
  std::vector<std::uint8_t> blocked(geometry.cellCount(), 0);
  for (std::size_t i = 0; i < blocked.size(); ++i)
  {
    blocked[i] = (!walls_.empty() && walls_.test(i)) || (!unknown_.empty() && unknown_.test(i));
  }
  filter_ = StaticMapFilter(geometry, blocked.data(), blocked.size(), tolerance, 1);
}

}  // namespace sharing_layer
