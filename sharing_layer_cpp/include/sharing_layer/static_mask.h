#ifndef SHARING_LAYER_STATIC_MASK_H
#define SHARING_LAYER_STATIC_MASK_H

#include <cstddef>
#include <cstdint>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/static_filter.h"

namespace sharing_layer
{
/**
 * @brief The cells never shared because the a-priori map explains them: its walls and its unknown areas, grown by
 * static_tolerance (StaticMapFilter). Owns the two sources, a bit per cell each (kept to rebuild the filter when one
 * of them changes), and the filter. A new grid (a resize, a rolling window's move) starts with none: the map is
 * given again.
 */
class StaticMask
{
public:
  /// @brief The walls: cells whose cost is at least occupied_cost.
  /// @throws std::invalid_argument on a size mismatch, before anything changes
  void setWalls(const GridGeometry& geometry, const std::uint8_t* costs, std::size_t cost_count, int tolerance,
                std::uint8_t occupied_cost);
  /// @brief Where the map is unknown (non-zero); nullptr / 0 cells forgets them.
  /// @throws std::invalid_argument on a size mismatch, before anything changes
  void setUnknown(const GridGeometry& geometry, const std::uint8_t* unknown, std::size_t cell_count, int tolerance);
  /// @brief Rebuilds the filter from the sources given so far with another static_tolerance (nothing to do
  /// without any). @throws std::invalid_argument when negative, before anything changes
  void setTolerance(const GridGeometry& geometry, int tolerance);
  /// @brief Forgets both sources (a new grid).
  void clear();

  bool isStatic(std::uint32_t index) const { return filter_.isStatic(index); }
  std::size_t bytes() const { return walls_.bytes() + unknown_.bytes() + filter_.gridBytes(); }

private:
  static constexpr std::uint8_t kWalls = 1;
  static constexpr std::uint8_t kUnknown = 2;
  template <class IsSet>
  void setSource(std::uint8_t source, std::size_t cell_count, IsSet is_set);
  void rebuild(const GridGeometry& geometry, int tolerance);

  BitGrid walls_;
  BitGrid unknown_;
  std::uint8_t given_ = 0;  ///< the sources given so far (kWalls, kUnknown)
  StaticMapFilter filter_;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_STATIC_MASK_H
