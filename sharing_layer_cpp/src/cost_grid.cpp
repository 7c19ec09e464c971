#include "sharing_layer/cost_grid.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace sharing_layer
{
CostGrid::CostGrid(const GridGeometry& geometry, std::uint8_t default_value)
  : geometry_(geometry), default_value_(default_value), costs_(geometry.cellCount(), default_value)
{
}

void CostGrid::reset()
{
  std::fill(costs_.begin(), costs_.end(), default_value_);
}

void CostGrid::assign(const std::vector<std::uint8_t>& costs)
{
  if (costs.size() != costs_.size())
  {
    throw std::invalid_argument("CostGrid::assign: got " + std::to_string(costs.size()) + " costs for a grid of " +
                                std::to_string(costs_.size()) + " cells");
  }
  costs_ = costs;
}

}  // namespace sharing_layer
