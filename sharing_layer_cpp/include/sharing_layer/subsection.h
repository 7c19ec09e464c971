#ifndef SHARING_LAYER_SUBSECTION_H
#define SHARING_LAYER_SUBSECTION_H

#include <string>

#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/observation.h"

namespace sharing_layer
{
/// @brief The monitored rectangle of a shared obstacle, [min_x, min_y, max_x, max_y] in metres.
struct Subsection
{
  double min_x = 0.0;
  double min_y = 0.0;
  double max_x = 0.0;
  double max_y = 0.0;

  Subsection() = default;
  /// @throws std::invalid_argument when a bound is not finite or min > max (e.g. "Subsection: min_x > max_x")
  Subsection(double min_x, double min_y, double max_x, double max_y);

  /// @return whether the two rectangles share any area or edge
  bool overlaps(const Subsection& other) const;
  /// @return whether any point of the rectangle lies within radius of (x, y)
  bool withinRadius(double x, double y, double radius) const;
  /// @brief The cells whose centres lie inside the rectangle, clipped to the grid (may be empty).
  CellRect cells(const GridGeometry& geometry) const;
  /// @return "[min_x, min_y, max_x, max_y]", for messages
  std::string describe() const;
};

}  // namespace sharing_layer

#endif  // SHARING_LAYER_SUBSECTION_H
