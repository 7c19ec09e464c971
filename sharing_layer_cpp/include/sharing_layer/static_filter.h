#ifndef SHARING_LAYER_STATIC_FILTER_H
#define SHARING_LAYER_STATIC_FILTER_H

#include <cstdint>
#include <vector>

#include "sharing_layer/bit_grid.h"
#include "sharing_layer/grid_geometry.h"

namespace sharing_layer
{
/**
 * @brief Tells whether a cell belongs to the a-priori static map, with a tolerance.
 *
 * Localisation error shifts walls by a cell or two, so a marked cell within
 * tolerance cells (in x and in y) of an occupied static cell counts as static and is
 * never shared. Cells where the a-priori map is unknown count like occupied ones: a robot
 * sees walls there that the map does not hold, and they are not obstacles to share.
 */
class StaticMapFilter
{
public:
  StaticMapFilter() = default;
  /**
   * @param costs costmap values of the static layer; a cell is occupied when its cost >= occupied_threshold
   *        (nullptr: none)
   * @param unknown optional, cost_count values, non-zero where the a-priori map is unknown
   * @throws std::invalid_argument on a size mismatch or a negative tolerance
   */
  StaticMapFilter(const GridGeometry& geometry, const std::uint8_t* costs, std::size_t cost_count, int tolerance,
                  std::uint8_t occupied_threshold, const std::uint8_t* unknown = nullptr);

  /// @return whether the cell is static within the tolerance (false when no map was given)
  bool isStatic(std::uint32_t index) const { return !near_static_.empty() && near_static_.test(index); }
  int tolerance() const { return tolerance_; }
  bool hasMap() const { return !near_static_.empty(); }
  /// @return bytes it keeps per grid (a bit per cell once a map was given)
  std::size_t gridBytes() const { return near_static_.bytes(); }

private:
  BitGrid near_static_;  ///< a bit per cell: it is kept for the map's lifetime
  int tolerance_ = 0;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_STATIC_FILTER_H
