#ifndef SHARING_LAYER_COST_VALUES_H
#define SHARING_LAYER_COST_VALUES_H

#include <cstdint>

namespace sharing_layer
{
/// Cost values with costmap_2d's meaning, so grids can be copied in and out unchanged.
constexpr std::uint8_t NO_INFORMATION = 255;
constexpr std::uint8_t LETHAL_OBSTACLE = 254;
constexpr std::uint8_t INSCRIBED_INFLATED_OBSTACLE = 253;
constexpr std::uint8_t FREE_SPACE = 0;
}  // namespace sharing_layer

#endif  // SHARING_LAYER_COST_VALUES_H
