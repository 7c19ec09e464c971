#include "sharing_layer/static_filter.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace sharing_layer
{
StaticMapFilter::StaticMapFilter(const GridGeometry& geometry, const std::uint8_t* costs, std::size_t cost_count,
                                 int tolerance, std::uint8_t occupied_threshold, const std::uint8_t* unknown)
  : tolerance_(tolerance)
{
  if (cost_count != geometry.cellCount())
  {
    throw std::invalid_argument("StaticMapFilter: static map has " + std::to_string(cost_count) +
                                " cells, the layer grid " + geometry.describe());
  }
  if (tolerance < 0)
  {
    throw std::invalid_argument("StaticMapFilter: static_tolerance must be >= 0, got " + std::to_string(tolerance));
  }
  const int sx = static_cast<int>(geometry.size_x);
  const int sy = static_cast<int>(geometry.size_y);
  std::vector<std::uint8_t> blocked(geometry.cellCount(), 0);  // occupied or unknown
  for (std::size_t i = 0; i < blocked.size(); ++i)
  {
    blocked[i] = (costs != nullptr && costs[i] >= occupied_threshold) || (unknown != nullptr && unknown[i] != 0);
  }
  // Separable square dilation: first along rows, then along columns, each with a sliding count.
  std::vector<std::uint8_t> rows(geometry.cellCount(), 0);
  for (int y = 0; y < sy; ++y)
  {
    const std::uint8_t* in = blocked.data() + static_cast<std::size_t>(y) * sx;
    std::uint8_t* out = rows.data() + static_cast<std::size_t>(y) * sx;
    int count = 0;
    for (int x = 0; x < std::min(tolerance, sx); ++x)
    {
      count += in[x];
    }
    for (int x = 0; x < sx; ++x)
    {
      if (x + tolerance < sx)
      {
        count += in[x + tolerance];
      }
      if (x - tolerance - 1 >= 0)
      {
        count -= in[x - tolerance - 1];
      }
      out[x] = count > 0;
    }
  }
  near_static_.assign(geometry.cellCount());
  std::vector<int> counts(sx, 0);
  for (int y = 0; y < std::min(tolerance, sy); ++y)
  {
    for (int x = 0; x < sx; ++x)
    {
      counts[x] += rows[static_cast<std::size_t>(y) * sx + x];
    }
  }
  for (int y = 0; y < sy; ++y)
  {
    if (y + tolerance < sy)
    {
      const std::uint8_t* add = rows.data() + static_cast<std::size_t>(y + tolerance) * sx;
      for (int x = 0; x < sx; ++x)
      {
        counts[x] += add[x];
      }
    }
    if (y - tolerance - 1 >= 0)
    {
      const std::uint8_t* sub = rows.data() + static_cast<std::size_t>(y - tolerance - 1) * sx;
      for (int x = 0; x < sx; ++x)
      {
        counts[x] -= sub[x];
      }
    }
    const std::size_t row = static_cast<std::size_t>(y) * sx;
    for (int x = 0; x < sx; ++x)
    {
      if (counts[x] > 0)
      {
        near_static_.set(row + static_cast<std::size_t>(x));
      }
    }
  }
}

}  // namespace sharing_layer
