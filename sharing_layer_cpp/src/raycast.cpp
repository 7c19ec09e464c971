#include "sharing_layer/raycast.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace sharing_layer
{
namespace
{
/// Clips the ray s + t*d, t in [t_min, t_max], to the slab [lo, hi); false when it misses.
bool clipSlab(double s, double d, double lo, double hi, double& t_min, double& t_max)
{
  if (d == 0.0)
  {
    return s >= lo && s < hi;
  }
  double t_a = (lo - s) / d;
  double t_b = (hi - s) / d;
  if (t_a > t_b)
  {
    std::swap(t_a, t_b);
  }
  t_min = std::max(t_min, t_a);
  t_max = std::min(t_max, t_b);
  return t_min <= t_max;
}

float traceBeam(const GridGeometry& g, const std::uint8_t* occupancy, double sx, double sy, double angle,
                double min_range, double max_range)
{
  const double dx = std::cos(angle);
  const double dy = std::sin(angle);
  double t_enter = 0.0;
  double t_leave = max_range;
  if (!clipSlab(sx, dx, g.origin_x, g.endX(), t_enter, t_leave) ||
      !clipSlab(sy, dy, g.origin_y, g.endY(), t_enter, t_leave))
  {
    return static_cast<float>(max_range);
  }

  // Start in the cell where the ray enters the grid (the sensor's own cell when inside).
  const double px = sx + t_enter * dx;
  const double py = sy + t_enter * dy;
  int cx = static_cast<int>(std::floor((px - g.origin_x) / g.resolution));
  int cy = static_cast<int>(std::floor((py - g.origin_y) / g.resolution));
  cx = std::min(std::max(cx, 0), static_cast<int>(g.size_x) - 1);
  cy = std::min(std::max(cy, 0), static_cast<int>(g.size_y) - 1);

  const int step_x = dx > 0.0 ? 1 : -1;
  const int step_y = dy > 0.0 ? 1 : -1;
  const double inf = std::numeric_limits<double>::infinity();
  const double t_delta_x = dx != 0.0 ? g.resolution / std::fabs(dx) : inf;
  const double t_delta_y = dy != 0.0 ? g.resolution / std::fabs(dy) : inf;
  const double next_x = g.origin_x + (cx + (step_x > 0 ? 1 : 0)) * g.resolution;
  const double next_y = g.origin_y + (cy + (step_y > 0 ? 1 : 0)) * g.resolution;
  double t_max_x = dx != 0.0 ? (next_x - sx) / dx : inf;
  double t_max_y = dy != 0.0 ? (next_y - sy) / dy : inf;

  double t_cell = t_enter;  // distance at which the ray entered the current cell
  const int size_x = static_cast<int>(g.size_x);
  const int size_y = static_cast<int>(g.size_y);
  while (t_cell <= max_range)
  {
    if (occupancy[static_cast<std::size_t>(cy) * g.size_x + cx] != 0)
    {
      return static_cast<float>(std::max(min_range, t_cell));
    }
    if (t_max_x < t_max_y)
    {
      t_cell = t_max_x;
      t_max_x += t_delta_x;
      cx += step_x;
      if (cx < 0 || cx >= size_x)
      {
        break;
      }
    }
    else
    {
      t_cell = t_max_y;
      t_max_y += t_delta_y;
      cy += step_y;
      if (cy < 0 || cy >= size_y)
      {
        break;
      }
    }
  }
  return static_cast<float>(max_range);
}
}  // namespace

void raycastRanges(const GridGeometry& geometry, const std::uint8_t* occupancy, std::size_t occupancy_size,
                   double sensor_x, double sensor_y, const double* angles, std::size_t beam_count,
                   double min_range, double max_range, float* ranges)
{
  if (occupancy_size != geometry.cellCount())
  {
    throw std::invalid_argument("raycastRanges: occupancy has " + std::to_string(occupancy_size) +
                                " cells, geometry " + geometry.describe());
  }
  if (!std::isfinite(sensor_x) || !std::isfinite(sensor_y))
  {
    throw std::invalid_argument("raycastRanges: sensor position is not finite");
  }
  if (!std::isfinite(min_range) || !std::isfinite(max_range) || min_range < 0.0 || !(min_range < max_range))
  {
    throw std::invalid_argument("raycastRanges: need 0 <= min_range < max_range, finite; got min_range " +
                                std::to_string(min_range) + ", max_range " + std::to_string(max_range));
  }
  for (std::size_t i = 0; i < beam_count; ++i)
  {
    ranges[i] = std::isfinite(angles[i]) ?
                    traceBeam(geometry, occupancy, sensor_x, sensor_y, angles[i], min_range, max_range) :
                    static_cast<float>(max_range);
  }
}

}  // namespace sharing_layer
