// Per-scan cost of the sharing layer's core against plain raytrace + mark (the costmap_2d ObstacleLayer work).
//
// Reference scan (DESIGN.md §10): 1081 beams over 270 degrees, 30 m max range, on a 0.05 m grid of
// 2000 x 2000 cells, in a synthetic warehouse (outer walls, racks, pillars) raycast with the core.
// Configurations are interleaved round by round so that machine noise hits all of them alike; the
// figures are medians, and the ratios are taken within this run.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/raycast.h"
#include "sharing_layer/scan_update.h"
#include "sharing_layer/sharing_core.h"

using namespace sharing_layer;

namespace
{
constexpr double kPi = 3.14159265358979323846;

struct Scene
{
  GridGeometry geometry{ 0.05, 0.0, 0.0, 2000, 2000 };
  std::vector<std::uint8_t> walls;
  Observation scan;
};

void fillRect(Scene& s, double x0, double y0, double x1, double y1)
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

Scene makeScene()
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

/// Adds n shared obstacles of 1 m x 1 m with 40 cells each, at seeded random places over the hall.
void addObstacles(SharingCore& core, int n, std::mt19937& rng)
{
  std::uniform_real_distribution<double> px(21.0, 78.0), py(31.0, 68.0);
  const GridGeometry& g = core.geometry();
  for (int i = 0; i < n; ++i)
  {
    const double x = px(rng), y = py(rng);
    ObstacleUpdate u;
    u.uuid = "bench-" + std::to_string(i);
    u.rectangle = Subsection(x, y, x + 1.0, y + 1.0);
    for (int k = 0; k < 40; ++k)
    {
      unsigned int mx = 0, my = 0;
      g.worldToMap(x + 0.025 + (k % 20) * 0.05, y + 0.025 + (k / 20) * 0.5, mx, my);
      u.marked.push_back(g.getIndex(mx, my));
    }
    u.deadline = 600;
    u.source = "robot_1";
    u.geometry = g;
    u.version = 1;
    core.applyShared(u, 0.0);
  }
}

double median(std::vector<double> v)
{
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

double seconds(const std::function<void()>& f)
{
  const auto start = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

int inView(const SharingCore& core, const Observation& scan, double radius)
{
  int n = 0;
  for (const auto& entry : core.sharedObstacles())
  {
    n += entry.second.rectangle.withinRadius(scan.origin.x, scan.origin.y, radius);
  }
  return n;
}
}  // namespace

int main(int argc, char** argv)
{
  const int rounds = argc > 1 ? std::max(5, std::atoi(argv[1])) : 60;
  const Scene scene = makeScene();
  std::printf("reference scan: %zu of 1081 beams return within 30 m; grid %s\n", scene.scan.points.size(),
              scene.geometry.describe().c_str());

  bool all_ok = true;
  for (double raytrace_range : { 3.0, 30.0 })
  {
    LayerParams params;
    params.limits.obstacle_range = 2.5;
    params.limits.raytrace_range = raytrace_range;
    params.limits.max_obstacle_height = 2.0;
    params.robot_name = "robot_0";

    CostGrid baseline_grid(scene.geometry, FREE_SPACE);
    std::vector<std::unique_ptr<SharingCore>> cores;
    const int counts[] = { 0, 10, 100 };
    std::mt19937 rng(7);
    for (int n : counts)
    {
      cores.emplace_back(new SharingCore(scene.geometry, params));
      std::mt19937 placement(42);  // the 10 are the first 10 of the 100
      addObstacles(*cores.back(), n, placement);
    }
    std::vector<double> t_base, t_core[3];
    for (int r = 0; r < rounds; ++r)
    {
      t_base.push_back(seconds([&] { applyScan(baseline_grid, scene.scan, params.limits); }));
      for (int c = 0; c < 3; ++c)
      {
        t_core[c].push_back(seconds([&] { cores[c]->processScan(scene.scan, 1.0 + r); }));
      }
    }
    const double base = median(t_base);
    std::printf("raytrace_range %.0f m: raytrace + mark only          median %8.3f ms/scan\n", raytrace_range,
                base * 1e3);
    for (int c = 0; c < 3; ++c)
    {
      std::printf("raytrace_range %.0f m: with %3d monitored obstacles  median %8.3f ms/scan  (%d in view)  ratio %.3f\n",
                  raytrace_range, counts[c], median(t_core[c]) * 1e3,
                  inView(*cores[c], scene.scan, std::max(2.5, raytrace_range)), median(t_core[c]) / base);
    }
    const double overhead = median(t_core[2]) / base;
    const bool ok = overhead <= 1.10;
    all_ok = all_ok && ok;
    std::printf("raytrace_range %.0f m: monitoring overhead at 100 obstacles %.3fx (target <= 1.10x) %s\n",
                raytrace_range, overhead, ok ? "MET" : "NOT MET");
  }
  return all_ok ? 0 : 1;
}
