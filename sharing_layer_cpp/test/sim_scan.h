// Test helper: a small world of boxes and 1081-beam 270 degree scans raycast in it, so tests see the
// beams a real laser gives (grazing rays, faces at any range) rather than hand-placed endpoints.
#ifndef SHARING_LAYER_TEST_SIM_SCAN_H
#define SHARING_LAYER_TEST_SIM_SCAN_H

#include <cmath>
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/observation.h"
#include "sharing_layer/raycast.h"
#include "sharing_layer/sharing_core.h"

namespace sharing_layer
{
namespace test
{
/// A world of axis-aligned boxes on a 1 cm grid, so beam endpoints do not sit on 5 cm costmap cell borders.
class SimWorld
{
public:
  SimWorld(double size_x_m, double size_y_m)
    : geometry_(0.01, 0.0, 0.0, static_cast<unsigned int>(size_x_m / 0.01), static_cast<unsigned int>(size_y_m / 0.01))
    , occupancy_(geometry_.cellCount(), 0)
  {
  }

  /// Fills [x0, x1) x [y0, y1) with value (1 = solid, 0 = free).
  void box(double x0, double y0, double x1, double y1, std::uint8_t value = 1)
  {
    for (unsigned int y = 0; y < geometry_.size_y; ++y)
    {
      const double cy = (y + 0.5) * geometry_.resolution;
      if (cy < y0 || cy >= y1)
      {
        continue;
      }
      for (unsigned int x = 0; x < geometry_.size_x; ++x)
      {
        const double cx = (x + 0.5) * geometry_.resolution;
        if (cx >= x0 && cx < x1)
        {
          occupancy_[geometry_.getIndex(x, y)] = value;
        }
      }
    }
  }

  /**
   * @brief A 270 degree, 1081-beam scan from the true pose (x, y, yaw), its endpoints placed with the
   * believed pose (x + ex, y + ey, yaw + eyaw), as a robot with localisation error places them.
   * Max-range readings give no point (laser_geometry drops them).
   */
  Observation scan(double x, double y, double yaw, double ex = 0.0, double ey = 0.0, double eyaw = 0.0,
                   double max_range = 30.0) const
  {
    const std::size_t beams = 1081;
    const double pi = 3.14159265358979323846;
    std::vector<double> angles(beams);
    for (std::size_t i = 0; i < beams; ++i)
    {
      angles[i] = yaw - 0.75 * pi + i * (1.5 * pi / (beams - 1));
    }
    std::vector<float> ranges(beams);
    raycastRanges(geometry_, occupancy_.data(), occupancy_.size(), x, y, angles.data(), beams, 0.05, max_range,
                  ranges.data());
    Observation obs;
    const double bx = x + ex, by = y + ey;
    obs.origin = Point3{ bx, by, 0.3 };
    for (std::size_t i = 0; i < beams; ++i)
    {
      if (ranges[i] < max_range)
      {
        const double a = angles[i] + eyaw;
        obs.points.push_back(Point3{ bx + ranges[i] * std::cos(a), by + ranges[i] * std::sin(a), 0.3 });
      }
    }
    return obs;
  }

private:
  GridGeometry geometry_;
  std::vector<std::uint8_t> occupancy_;
};
/// The clearing and trigger tests' world: 10 m x 10 m with 0.2 m outer walls, under a 0.05 m
/// costmap whose static map knows the walls (4 cells thick).
constexpr double kWorld = 10.0;

inline GridGeometry grid()
{
  return GridGeometry(0.05, 0.0, 0.0, 200, 200);
}

inline void outerWalls(SimWorld& world)
{
  world.box(0.0, 0.0, kWorld, 0.2);
  world.box(0.0, kWorld - 0.2, kWorld, kWorld);
  world.box(0.0, 0.0, 0.2, kWorld);
  world.box(kWorld - 0.2, 0.0, kWorld, kWorld);
}

inline SimWorld walledWorld()
{
  SimWorld world(kWorld, kWorld);
  outerWalls(world);
  return world;
}

inline std::vector<std::uint8_t> staticMap()
{
  const GridGeometry g = grid();
  std::vector<std::uint8_t> costs(g.cellCount(), FREE_SPACE);
  for (unsigned int y = 0; y < g.size_y; ++y)
  {
    for (unsigned int x = 0; x < g.size_x; ++x)
    {
      if (x < 4 || y < 4 || x >= g.size_x - 4 || y >= g.size_y - 4)
      {
        costs[g.getIndex(x, y)] = LETHAL_OBSTACLE;
      }
    }
  }
  return costs;
}

/// The layer's defaults (obstacle_range 2.5, raytrace_range 3.0: the tutorials' and costmap_2d's).
inline LayerParams defaults()
{
  LayerParams p;
  p.robot_name = "robot_0";
  return p;
}

/// A core on grid() that knows the outer walls from its static map.
inline SharingCore makeCore(const LayerParams& p = defaults())
{
  SharingCore core(grid(), p);
  const std::vector<std::uint8_t> costs = staticMap();
  core.setStaticMap(costs.data(), costs.size());
  return core;
}

/// An obstacle on grid() as a handler hands it to the layer (a first share is version 1).
inline ObstacleUpdate sharedUpdate(const std::string& uuid, const std::vector<std::uint32_t>& marked,
                                   const Subsection& rectangle, std::uint64_t version = 1,
                                   const std::string& source = "robot_1", std::uint32_t deadline = 60)
{
  ObstacleUpdate u;
  u.uuid = uuid;
  u.marked = marked;
  u.rectangle = rectangle;
  u.deadline = deadline;
  u.source = source;
  u.geometry = grid();
  u.version = version;
  return u;
}

/// Cells of a proposal list, all together, sorted.
inline std::vector<std::uint32_t> allCells(const std::vector<Proposal>& proposals)
{
  std::vector<std::uint32_t> cells;
  for (const Proposal& p : proposals)
  {
    cells.insert(cells.end(), p.cells.begin(), p.cells.end());
  }
  std::sort(cells.begin(), cells.end());
  return cells;
}
}  // namespace test
}  // namespace sharing_layer

#endif  // SHARING_LAYER_TEST_SIM_SCAN_H
