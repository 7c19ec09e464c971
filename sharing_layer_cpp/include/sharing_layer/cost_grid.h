#ifndef SHARING_LAYER_COST_GRID_H
#define SHARING_LAYER_COST_GRID_H

#include <cstdint>
#include <vector>

#include "sharing_layer/grid_geometry.h"

namespace sharing_layer
{
/**
 * @brief A grid of costmap_2d cost values over a GridGeometry: its own cells, or a view of a caller's buffer (the
 * costmap_2d plugin hands the core its layer's own grid, so that there is one obstacle grid, not two).
 */
class CostGrid
{
public:
  CostGrid() = default;
  /// @brief A grid of its own with every cell set to default_value.
  CostGrid(const GridGeometry& geometry, std::uint8_t default_value);
  /// @brief A grid over the caller's buffer of geometry.cellCount() costs, whose contents it takes as they are.
  /// The caller keeps the buffer alive while the grid (or a copy of it) uses it.
  static CostGrid view(const GridGeometry& geometry, std::uint8_t* costs, std::uint8_t default_value);

  CostGrid(const CostGrid& other);
  CostGrid& operator=(const CostGrid& other);
  CostGrid(CostGrid&& other) noexcept;
  CostGrid& operator=(CostGrid&& other) noexcept;

  const GridGeometry& geometry() const { return geometry_; }
  std::uint8_t* data() { return data_; }
  const std::uint8_t* data() const { return data_; }
  /// @return whether the cells are the grid's own (false: a view of a caller's buffer)
  bool ownsCells() const { return data_ == nullptr || data_ == own_.data(); }
  std::uint8_t defaultValue() const { return default_value_; }
  std::uint8_t getCost(unsigned int mx, unsigned int my) const { return data_[geometry_.getIndex(mx, my)]; }
  void setCost(unsigned int mx, unsigned int my, std::uint8_t cost) { data_[geometry_.getIndex(mx, my)] = cost; }
  std::uint8_t at(std::uint32_t index) const { return data_[index]; }
  void set(std::uint32_t index, std::uint8_t cost) { data_[index] = cost; }
  /// @brief Every cell back to the default value.
  void reset();
  /// @brief Replaces all costs; @throws std::invalid_argument when the size does not match.
  void assign(const std::vector<std::uint8_t>& costs);

private:
  GridGeometry geometry_;
  std::uint8_t default_value_ = 0;
  std::vector<std::uint8_t> own_;
  std::uint8_t* data_ = nullptr;  ///< own_.data(), or the caller's buffer
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_COST_GRID_H
