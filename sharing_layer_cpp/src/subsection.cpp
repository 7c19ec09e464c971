#include "sharing_layer/subsection.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace sharing_layer
{
Subsection::Subsection(double min_x, double min_y, double max_x, double max_y)
  : min_x(min_x), min_y(min_y), max_x(max_x), max_y(max_y)
{
  if (!std::isfinite(min_x) || !std::isfinite(min_y) || !std::isfinite(max_x) || !std::isfinite(max_y))
  {
    throw std::invalid_argument("Subsection: bounds must be finite, got " + describe());
  }
  if (min_x > max_x)
  {
    throw std::invalid_argument("Subsection: min_x > max_x in " + describe());
  }
  if (min_y > max_y)
  {
    throw std::invalid_argument("Subsection: min_y > max_y in " + describe());
  }
}

bool Subsection::overlaps(const Subsection& other) const
{
  return min_x <= other.max_x && other.min_x <= max_x && min_y <= other.max_y && other.min_y <= max_y;
}

bool Subsection::withinRadius(double x, double y, double radius) const
{
  const double dx = std::max({ min_x - x, 0.0, x - max_x });
  const double dy = std::max({ min_y - y, 0.0, y - max_y });
  return dx * dx + dy * dy <= radius * radius;
}

CellRect Subsection::cells(const GridGeometry& g) const
{
  CellRect r;
  // Cells whose centre origin + (m + 0.5) * res lies in [min, max].
  const double lo_x = std::ceil((min_x - g.origin_x) / g.resolution - 0.5 - 1e-9);
  const double hi_x = std::floor((max_x - g.origin_x) / g.resolution - 0.5 + 1e-9);
  const double lo_y = std::ceil((min_y - g.origin_y) / g.resolution - 0.5 - 1e-9);
  const double hi_y = std::floor((max_y - g.origin_y) / g.resolution - 0.5 + 1e-9);
  r.min_x = static_cast<int>(std::max(0.0, lo_x));
  r.min_y = static_cast<int>(std::max(0.0, lo_y));
  r.max_x = static_cast<int>(std::min(static_cast<double>(g.size_x) - 1.0, hi_x));
  r.max_y = static_cast<int>(std::min(static_cast<double>(g.size_y) - 1.0, hi_y));
  return r;
}

std::string Subsection::describe() const
{
  std::ostringstream out;
  out << "[" << min_x << ", " << min_y << ", " << max_x << ", " << max_y << "]";
  return out.str();
}

}  // namespace sharing_layer
