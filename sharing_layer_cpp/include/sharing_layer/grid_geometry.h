#ifndef SHARING_LAYER_GRID_GEOMETRY_H
#define SHARING_LAYER_GRID_GEOMETRY_H

#include <cstdint>
#include <string>

namespace sharing_layer
{
/**
 * @brief Placement and size of a 2D grid, with costmap_2d's conventions:
 * cell (mx, my) covers [origin + m * resolution, origin + (m + 1) * resolution),
 * and its index is my * size_x + mx.
 */
struct GridGeometry
{
  double resolution = 0.05;   ///< metres per cell
  double origin_x = 0.0;      ///< world x of the grid's lower-left corner
  double origin_y = 0.0;      ///< world y of the grid's lower-left corner
  unsigned int size_x = 0;    ///< cells along x
  unsigned int size_y = 0;    ///< cells along y

  GridGeometry() = default;
  /// @throws std::invalid_argument on a non-positive or non-finite resolution, a non-finite origin or a zero size.
  GridGeometry(double resolution, double origin_x, double origin_y, unsigned int size_x, unsigned int size_y);

  /// @return number of cells
  std::size_t cellCount() const { return static_cast<std::size_t>(size_x) * size_y; }

  /// @brief World to cell; false (outputs untouched) when the point is outside the grid or not finite.
  bool worldToMap(double wx, double wy, unsigned int& mx, unsigned int& my) const;
  /// @brief World to cell, clamped to the grid edge (costmap_2d's worldToMapEnforceBounds).
  void worldToMapEnforceBounds(double wx, double wy, int& mx, int& my) const;
  /// @brief World coordinates of a cell's centre.
  void mapToWorld(unsigned int mx, unsigned int my, double& wx, double& wy) const;
  /// @brief Cell to flat index (no bounds check, like costmap_2d's getIndex).
  std::uint32_t getIndex(unsigned int mx, unsigned int my) const { return my * size_x + mx; }
  /// @brief Flat index to cell (no bounds check).
  void indexToCells(std::uint32_t index, unsigned int& mx, unsigned int& my) const
  {
    my = index / size_x;
    mx = index - my * size_x;
  }
  /// @return whether a flat index lies inside the grid
  bool containsIndex(std::uint64_t index) const { return index < cellCount(); }
  /// @brief Distance in world units as a whole number of cells (costmap_2d's cellDistance).
  unsigned int cellDistance(double world_dist) const;
  /// @return world x of the far edge of the grid
  double endX() const { return origin_x + size_x * resolution; }
  /// @return world y of the far edge of the grid
  double endY() const { return origin_y + size_y * resolution; }

  /// @brief Same grid within floating-point tolerance (relative 1e-6 on resolution and origin, sizes exact).
  bool sameAs(const GridGeometry& other) const;
  /// @return a short human-readable description, for error messages
  std::string describe() const;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_GRID_GEOMETRY_H
