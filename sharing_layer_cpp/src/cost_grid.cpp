#include "sharing_layer/cost_grid.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace sharing_layer
{
CostGrid::CostGrid(const GridGeometry& geometry, std::uint8_t default_value)
  : geometry_(geometry), default_value_(default_value), own_(geometry.cellCount(), default_value), data_(own_.data())
{
}

CostGrid CostGrid::view(const GridGeometry& geometry, std::uint8_t* costs, std::uint8_t default_value)
{
  if (costs == nullptr && geometry.cellCount() > 0)
  {
    throw std::invalid_argument("CostGrid::view: no buffer for a grid of " + geometry.describe());
  }
  CostGrid grid;
  grid.geometry_ = geometry;
  grid.default_value_ = default_value;
  grid.data_ = costs;
  return grid;
}

CostGrid::CostGrid(const CostGrid& other)
  : geometry_(other.geometry_), default_value_(other.default_value_), own_(other.own_)
  , data_(other.ownsCells() ? own_.data() : other.data_)
{
}

CostGrid& CostGrid::operator=(const CostGrid& other)
{
  if (this != &other)
  {
    CostGrid copy(other);
    *this = std::move(copy);
  }
  return *this;
}

CostGrid::CostGrid(CostGrid&& other) noexcept
  : geometry_(other.geometry_), default_value_(other.default_value_)
{
  const bool owns = other.ownsCells();
  own_ = std::move(other.own_);  // a moved vector keeps its buffer
  data_ = owns ? own_.data() : other.data_;
  other.data_ = nullptr;
  other.own_.clear();
}

CostGrid& CostGrid::operator=(CostGrid&& other) noexcept
{
  if (this != &other)
  {
    const bool owns = other.ownsCells();
    geometry_ = other.geometry_;
    default_value_ = other.default_value_;
    own_ = std::move(other.own_);
    data_ = owns ? own_.data() : other.data_;
    other.data_ = nullptr;
    other.own_.clear();
  }
  return *this;
}

void CostGrid::reset()
{
  std::fill(data_, data_ + geometry_.cellCount(), default_value_);
}

void CostGrid::assign(const std::vector<std::uint8_t>& costs)
{
  if (costs.size() != geometry_.cellCount())
  {
    throw std::invalid_argument("CostGrid::assign: got " + std::to_string(costs.size()) + " costs for a grid of " +
                                std::to_string(geometry_.cellCount()) + " cells");
  }
  std::copy(costs.begin(), costs.end(), data_);
}

}  // namespace sharing_layer
