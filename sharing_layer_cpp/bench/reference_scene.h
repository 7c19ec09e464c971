// The reference scene of the benchmarks (DESIGN.md §10): a synthetic warehouse on a 2000 x 2000 grid of 0.05 m
// (outer walls, racks, pillars), 100 crates that are not on the map, and one 1081-beam, 270 degree, 30 m scan
// raycast from (50.02, 50.03). Shared by bench_core (the core against plain raytrace + mark) and, where
// costmap_2d is installed, bench_plugin_cycle (the plugin against costmap_2d's ObstacleLayer).
#ifndef SHARING_LAYER_BENCH_REFERENCE_SCENE_H
#define SHARING_LAYER_BENCH_REFERENCE_SCENE_H

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "sharing_layer/raycast.h"
#include "sharing_layer/shared_obstacle.h"
#include "sharing_layer/sharing_core.h"

namespace sharing_layer
{
namespace bench
{
constexpr double kPi = 3.14159265358979323846;

struct Scene
{
  GridGeometry geometry{ 0.05, 0.0, 0.0, 2000, 2000 };
  std::vector<std::uint8_t> walls;                ///< what the scan is raycast against: the map and the crates
  std::vector<std::uint8_t> map;                  ///< the a-priori map: walls, racks, pillars (no crates)
  std::vector<std::pair<double, double>> crates;  ///< lower-left corners of 0.4 m crates, not on the map
  Observation scan;
};
constexpr double kCrate = 0.4;
constexpr int kCrates = 100;

inline void fillRect(Scene& s, double x0, double y0, double x1, double y1)
{
  const GridGeometry& g = s.geometry;
  for (unsigned int y = static_cast<unsigned int>(y0 / g.resolution); y < y1 / g.resolution && y < g.size_y; ++y)
  {
    for (unsigned int x = static_cast<unsigned int>(x0 / g.resolution); x < x1 / g.resolution && x < g.size_x; ++x)
    {
      s.walls[g.getIndex(x, y)] = 1;
    }
  }
}

inline Scene makeScene()
{
  Scene s;
  s.walls.assign(s.geometry.cellCount(), 0);
  // A 60 m x 40 m hall around the robot at (50, 50), rack rows, and a few pillars near the robot.
  fillRect(s, 20.0, 30.0, 80.0, 30.2);
  fillRect(s, 20.0, 69.8, 80.0, 70.0);
  fillRect(s, 20.0, 30.0, 20.2, 70.0);
  fillRect(s, 79.8, 30.0, 80.0, 70.0);
  for (double y = 34.0; y < 68.0; y += 6.0)
  {
    fillRect(s, 56.0, y, 74.0, y + 1.0);
    fillRect(s, 26.0, y, 44.0, y + 1.0);
  }
  fillRect(s, 51.5, 51.0, 51.9, 51.4);
  fillRect(s, 48.0, 48.6, 48.4, 49.0);
  s.map = s.walls;
  // Crates strewn over the hall: the obstacles the fleet shares. They stand in every configuration,
  // so all of them scan the same world; they differ only in how many crates are shared obstacles.
  std::mt19937 placement(42);
  std::uniform_real_distribution<double> px(21.0, 78.0), py(31.0, 68.0);
  while (static_cast<int>(s.crates.size()) < kCrates)
  {
    const double x = px(placement), y = py(placement);
    if (std::hypot(x - 50.0, y - 50.0) < 1.5)
    {
      continue;  // not on top of the robot
    }
    s.crates.emplace_back(x, y);
    fillRect(s, x, y, x + kCrate, y + kCrate);
  }

  const std::size_t beams = 1081;
  std::vector<double> angles(beams);
  const double yaw = 0.3;
  for (std::size_t i = 0; i < beams; ++i)
  {
    angles[i] = yaw - 0.75 * kPi + i * (1.5 * kPi / (beams - 1));
  }
  std::vector<float> ranges(beams);
  const double ox = 50.02, oy = 50.03;
  raycastRanges(s.geometry, s.walls.data(), s.walls.size(), ox, oy, angles.data(), beams, 0.05, 30.0, ranges.data());
  s.scan.origin = Point3{ ox, oy, 0.3 };
  for (std::size_t i = 0; i < beams; ++i)
  {
    if (ranges[i] < 30.0f)  // laser_geometry drops max-range readings
    {
      s.scan.points.push_back(Point3{ ox + ranges[i] * std::cos(angles[i]), oy + ranges[i] * std::sin(angles[i]), 0.3 });
    }
  }
  return s;
}

/// Crate i shared as an obstacle: a 1 m x 1 m rectangle around it, holding the crate's outline cells, as a robot
/// that saw it from all sides would share it.
inline ObstacleUpdate crateUpdate(const Scene& scene, int i)
{
  const GridGeometry& g = scene.geometry;
  const double x = scene.crates[i].first, y = scene.crates[i].second;
  ObstacleUpdate u;
  u.uuid = "bench-" + std::to_string(i);
  u.rectangle = Subsection(x - 0.3, y - 0.3, x + kCrate + 0.3, y + kCrate + 0.3);
  unsigned int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  g.worldToMap(x + 0.001, y + 0.001, x0, y0);
  g.worldToMap(x + kCrate - 0.001, y + kCrate - 0.001, x1, y1);
  for (unsigned int my = y0; my <= y1; ++my)
  {
    for (unsigned int mx = x0; mx <= x1; ++mx)
    {
      if (mx == x0 || mx == x1 || my == y0 || my == y1)
      {
        u.marked.push_back(g.getIndex(mx, my));
      }
    }
  }
  u.deadline = 600;
  u.source = "robot_1";
  u.geometry = g;
  u.version = 1;
  return u;
}
}  // namespace bench
}  // namespace sharing_layer

#endif  // SHARING_LAYER_BENCH_REFERENCE_SCENE_H
