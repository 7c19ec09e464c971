#include "sharing_layer/grid_geometry.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace sharing_layer
{
GridGeometry::GridGeometry(double resolution, double origin_x, double origin_y, unsigned int size_x,
                           unsigned int size_y)
  : resolution(resolution), origin_x(origin_x), origin_y(origin_y), size_x(size_x), size_y(size_y)
{
  if (!std::isfinite(resolution) || resolution <= 0.0)
  {
    throw std::invalid_argument("GridGeometry: resolution must be finite and > 0, got " + std::to_string(resolution));
  }
  if (!std::isfinite(origin_x) || !std::isfinite(origin_y))
  {
    throw std::invalid_argument("GridGeometry: origin must be finite");
  }
  if (size_x == 0 || size_y == 0)
  {
    throw std::invalid_argument("GridGeometry: size must be > 0, got " + std::to_string(size_x) + " x " +
                                std::to_string(size_y));
  }
  if (static_cast<std::uint64_t>(size_x) * size_y > 0xFFFFFFFFull)
  {
    throw std::invalid_argument("GridGeometry: " + std::to_string(size_x) + " x " + std::to_string(size_y) +
                                " cells do not fit 32-bit indexes");
  }
}

bool GridGeometry::worldToMap(double wx, double wy, unsigned int& mx, unsigned int& my) const
{
  if (!(wx >= origin_x) || !(wy >= origin_y))  // also rejects NaN
  {
    return false;
  }
  const double fx = (wx - origin_x) / resolution;
  const double fy = (wy - origin_y) / resolution;
  if (!(fx < size_x) || !(fy < size_y))
  {
    return false;
  }
  mx = static_cast<unsigned int>(fx);
  my = static_cast<unsigned int>(fy);
  return mx < size_x && my < size_y;
}

void GridGeometry::worldToMapEnforceBounds(double wx, double wy, int& mx, int& my) const
{
  const double fx = (wx - origin_x) / resolution;
  const double fy = (wy - origin_y) / resolution;
  mx = fx < 0.0 ? 0 : (fx >= size_x ? static_cast<int>(size_x) - 1 : static_cast<int>(fx));
  my = fy < 0.0 ? 0 : (fy >= size_y ? static_cast<int>(size_y) - 1 : static_cast<int>(fy));
}

void GridGeometry::mapToWorld(unsigned int mx, unsigned int my, double& wx, double& wy) const
{
  wx = origin_x + (mx + 0.5) * resolution;
  wy = origin_y + (my + 0.5) * resolution;
}

unsigned int GridGeometry::cellDistance(double world_dist) const
{
  const double cells_dist = std::max(0.0, std::ceil(world_dist / resolution));
  return cells_dist >= 4294967295.0 ? 0xFFFFFFFFu : static_cast<unsigned int>(cells_dist);
}

bool GridGeometry::sameAs(const GridGeometry& other) const
{
  const auto close = [](double a, double b, double scale) { return std::fabs(a - b) <= 1e-6 * scale; };
  const double scale = std::max(1.0, std::fabs(resolution) * std::max(size_x, size_y));
  return size_x == other.size_x && size_y == other.size_y &&
         close(resolution, other.resolution, std::max(1e-9, std::fabs(resolution))) &&
         close(origin_x, other.origin_x, scale) && close(origin_y, other.origin_y, scale);
}

std::string GridGeometry::describe() const
{
  std::ostringstream out;
  out << size_x << "x" << size_y << " cells at " << resolution << " m, origin (" << origin_x << ", " << origin_y
      << ")";
  return out.str();
}

}  // namespace sharing_layer
