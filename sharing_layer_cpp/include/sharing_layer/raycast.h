#ifndef SHARING_LAYER_RAYCAST_H
#define SHARING_LAYER_RAYCAST_H

#include <cstdint>
#include <vector>

#include "sharing_layer/grid_geometry.h"

namespace sharing_layer
{
/**
 * @brief Simulated range finder: for each beam angle, the distance from the sensor
 * to the first cell whose value is non-zero.
 *
 * The ray is walked cell by cell with an exact grid traversal (Amanatides & Woo), so
 * the range is the distance to where the ray enters the blocking cell. A ray that leaves
 * the grid or finds nothing within max_range returns max_range; a hit closer than
 * min_range returns min_range (as Stage clamps), so a sensor inside a blocking cell
 * reads min_range. A sensor outside the grid is traced from where each ray enters it.
 *
 * @param occupancy  size_x * size_y values, row-major (index = y * size_x + x)
 * @param angles     absolute beam angles in the grid frame, radians
 * @param ranges     output, one per angle
 * @throws std::invalid_argument on a size mismatch, non-finite sensor pose, or
 *         min_range/max_range not satisfying 0 <= min_range < max_range (finite)
 */
void raycastRanges(const GridGeometry& geometry, const std::uint8_t* occupancy, std::size_t occupancy_size,
                   double sensor_x, double sensor_y, const double* angles, std::size_t beam_count,
                   double min_range, double max_range, float* ranges);

}  // namespace sharing_layer

#endif  // SHARING_LAYER_RAYCAST_H
