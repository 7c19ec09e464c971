#ifndef SHARING_LAYER_COST_GRID_H
#define SHARING_LAYER_COST_GRID_H

#include <cstdint>
#include <vector>

#include "sharing_layer/grid_geometry.h"

namespace sharing_layer
{
/// @brief A grid of costmap_2d cost values over a GridGeometry.
class CostGrid
{
public:
  CostGrid() = default;
  /// @brief A grid with every cell set to default_value.
  CostGrid(const GridGeometry& geometry, std::uint8_t default_value);

  const GridGeometry& geometry() const { return geometry_; }
  std::uint8_t* data() { return costs_.data(); }
  const std::uint8_t* data() const { return costs_.data(); }
  std::uint8_t defaultValue() const { return default_value_; }

  std::uint8_t getCost(unsigned int mx, unsigned int my) const { return costs_[geometry_.getIndex(mx, my)]; }
  void setCost(unsigned int mx, unsigned int my, std::uint8_t cost) { costs_[geometry_.getIndex(mx, my)] = cost; }
  std::uint8_t at(std::uint32_t index) const { return costs_[index]; }
  void set(std::uint32_t index, std::uint8_t cost) { costs_[index] = cost; }

  /// @brief Every cell back to the default value.
  void reset();
  /// @brief Replaces all costs; @throws std::invalid_argument when the size does not match.
  void assign(const std::vector<std::uint8_t>& costs);

private:
  GridGeometry geometry_;
  std::uint8_t default_value_ = 0;
  std::vector<std::uint8_t> costs_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_COST_GRID_H
