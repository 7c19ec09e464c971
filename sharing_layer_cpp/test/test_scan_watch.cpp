// applyScan's watch against an oracle that walks every beam cell by cell (raytraceLine with CollectAction) and
// applies the documented rules directly: random grids, scans, watched cells, regions and loose cells. The
// watch walks only the beams pointing at a region and only the steps inside it; this checks that it finds
// exactly the cells and step positions the full walk finds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "sharing_layer/cost_values.h"
#include "sharing_layer/raytrace.h"
#include "sharing_layer/scan_update.h"

using namespace sharing_layer;

namespace
{
/// @return every cell's byte of the flags
std::vector<std::uint8_t> bytesOf(const CellFlags& flags)
{
  std::vector<std::uint8_t> bytes(flags.size());
  for (std::size_t i = 0; i < bytes.size(); ++i)
  {
    bytes[i] = flags.get(static_cast<std::uint32_t>(i));
  }
  return bytes;
}

struct Expected
{
  std::vector<std::uint32_t> cleared, free, hit;
};

/// The rules of ScanTouch::watched_* for a scan whose points all lie inside the grid and inside the height
/// limits, with the origin inside the grid (no clipping).
Expected oracle(const GridGeometry& g, const Observation& obs, const ScanLimits& limits, const ScanWatch& watch)
{
  std::set<std::uint32_t> watched(watch.cells.begin(), watch.cells.end());
  watched.insert(watch.loose_cells.begin(), watch.loose_cells.end());
  const double ox = obs.origin.x, oy = obs.origin.y;
  unsigned int x0 = 0, y0 = 0;
  g.worldToMap(ox, oy, x0, y0);
  std::set<std::uint32_t> visited, deep, marked, hit;
  for (std::size_t pi = 0; pi < obs.points.size(); ++pi)
  {
    const Point3& p = obs.points[pi];
    unsigned int x1 = 0, y1 = 0;
    g.worldToMap(p.x, p.y, x1, y1);
    std::vector<std::uint32_t> cells;
    CollectAction<std::vector<std::uint32_t>> collect{ &cells };
    raytraceLine(collect, x0, y0, x1, y1, g.size_x, g.cellDistance(limits.raytrace_range));
    // Shadow filter: the shortest planar range among the point and free_neighbours neighbours on each side.
    double shortest = std::hypot(p.x - ox, p.y - oy);
    for (std::size_t j = pi >= watch.free_neighbours ? pi - watch.free_neighbours : 0;
         j <= std::min(obs.points.size() - 1, pi + watch.free_neighbours); ++j)
    {
      shortest = std::min(shortest, std::hypot(obs.points[j].x - ox, obs.points[j].y - oy));
    }
    const LineSteps line(x0, y0, x1, y1);
    const unsigned int deep_steps =
        stepsWithin((shortest - watch.free_margin) / g.resolution, line.abs_da, line.dist());
    for (std::size_t step = 0; step < cells.size(); ++step)  // one cell per step along the dominant axis
    {
      visited.insert(cells[step]);
      if (step < deep_steps)
      {
        deep.insert(cells[step]);
      }
    }
    const std::uint32_t end = g.getIndex(x1, y1);
    hit.insert(end);
    const double dz = p.z - obs.origin.z;
    if ((p.x - ox) * (p.x - ox) + (p.y - oy) * (p.y - oy) + dz * dz < limits.obstacle_range * limits.obstacle_range)
    {
      marked.insert(end);
    }
  }
  Expected e;
  for (std::uint32_t c : watched)
  {
    if (visited.count(c) && !marked.count(c))
    {
      e.cleared.push_back(c);
      if (deep.count(c) && !hit.count(c))
      {
        e.free.push_back(c);
      }
    }
    if (hit.count(c))
    {
      e.hit.push_back(c);
    }
  }
  return e;
}
}  // namespace

TEST(ScanWatch, FindsExactlyTheCellsAFullWalkFinds)
{
  std::mt19937 rng(2026);
  std::size_t results = 0;
  std::size_t flagged_trials = 0;
  for (int trial = 0; trial < 1500; ++trial)
  {
    const unsigned int w = 30 + rng() % 90, h = 30 + rng() % 90;
    const GridGeometry g(0.05, -1.0, 2.0, w, h);
    CostGrid grid(g, NO_INFORMATION);
    std::uniform_real_distribution<double> ux(g.origin_x + 0.001, g.endX() - 0.001);
    std::uniform_real_distribution<double> uy(g.origin_y + 0.001, g.endY() - 0.001);
    Observation obs;
    obs.origin = Point3{ ux(rng), uy(rng), 0.3 };
    const int n = 1 + static_cast<int>(rng() % 150);
    if (trial % 2 == 0)
    {
      for (int i = 0; i < n; ++i)
      {
        obs.points.push_back(Point3{ ux(rng), uy(rng), 0.3 });
      }
    }
    else  // a scan: points in angle order, ranges that jump now and then (occlusion edges)
    {
      double range = 1.0;
      for (int i = 0; i < n; ++i)
      {
        if (rng() % 5 == 0)
        {
          range = 0.1 + (rng() % 80) * 0.05;
        }
        const double a = 6.283 * i / n;
        const double x = std::min(std::max(obs.origin.x + range * std::cos(a), ux.a()), ux.b());
        const double y = std::min(std::max(obs.origin.y + range * std::sin(a), uy.a()), uy.b());
        obs.points.push_back(Point3{ x, y, 0.3 });
      }
    }
    ScanLimits limits;
    limits.obstacle_range = 0.3 + (rng() % 40) * 0.1;
    limits.raytrace_range = 0.3 + (rng() % 60) * 0.1;
    ScanWatch watch;
    watch.free_margin = (rng() % 5) * 0.05;
    watch.free_neighbours = rng() % 4;
    const bool with_regions = rng() % 2 == 0;
    for (int i = 0, k = static_cast<int>(rng() % 12); i < k; ++i)  // blobs, each covered by a region
    {
      const int cx = static_cast<int>(rng() % w), cy = static_cast<int>(rng() % h);
      const int rx = static_cast<int>(rng() % 6), ry = static_cast<int>(rng() % 6);
      CellRect r{ std::max(0, cx - rx), std::max(0, cy - ry), std::min<int>(w - 1, cx + rx),
                  std::min<int>(h - 1, cy + ry) };
      for (int y = r.min_y; y <= r.max_y; ++y)
      {
        for (int x = r.min_x; x <= r.max_x; ++x)
        {
          if (rng() % 3 == 0)
          {
            watch.cells.push_back(g.getIndex(x, y));
          }
        }
      }
      watch.regions.push_back(r);
    }
    if (!with_regions)
    {
      watch.regions.clear();  // every cell walked on its own
    }
    for (int i = 0, k = static_cast<int>(rng() % 30); i < k; ++i)
    {
      watch.loose_cells.push_back(static_cast<std::uint32_t>(rng() % g.cellCount()));
    }
    for (int i = 0, k = static_cast<int>(rng() % 10); i < k; ++i)  // endpoint cells: hit, and often marked
    {
      const Point3& p = obs.points[rng() % obs.points.size()];
      unsigned int mx = 0, my = 0;
      g.worldToMap(p.x, p.y, mx, my);
      watch.loose_cells.push_back(g.getIndex(mx, my));
    }
    CellFlags scratch;
    if (rng() % 2 == 0)
    {
      scratch.assign(g.cellCount());
      watch.scratch = &scratch;
    }

    const Expected expected = oracle(g, obs, limits, watch);
    // An owner that keeps its watched cells flagged in the scratch instead of listing them gets the same result;
    // flagged cells outside every region are not watched.
    std::vector<std::uint8_t> flagged_before;
    if (scratch.size() != 0 && with_regions && rng() % 2 == 0)
    {
      for (std::uint32_t c : watch.cells)
      {
        scratch.set(c, ScanWatch::kFlaggedWatched);
      }
      watch.cells.clear();
      for (int i = 0, k = static_cast<int>(rng() % 20); i < k; ++i)
      {
        const std::uint32_t c = static_cast<std::uint32_t>(rng() % g.cellCount());
        unsigned int cx = 0, cy = 0;
        g.indexToCells(c, cx, cy);
        if (std::none_of(watch.regions.begin(), watch.regions.end(),
                         [&](const CellRect& r) { return r.contains(static_cast<int>(cx), static_cast<int>(cy)); }))
        {
          scratch.set(c, ScanWatch::kFlaggedWatched);
        }
      }
      for (int i = 0, k = static_cast<int>(rng() % 40); i < k; ++i)  // the owner's bits: neither read nor changed
      {
        const std::uint32_t c = static_cast<std::uint32_t>(rng() % g.cellCount());
        scratch.set(c, static_cast<std::uint8_t>((rng() % 8) << 5));
      }
      flagged_before = bytesOf(scratch);
    }
    const ScanTouch touch = applyScan(grid, obs, limits, watch);
    ASSERT_EQ(expected.cleared, touch.watched_cleared) << "trial " << trial;
    ASSERT_EQ(expected.free, touch.watched_free) << "trial " << trial;
    ASSERT_EQ(expected.hit, touch.watched_hit) << "trial " << trial;
    if (flagged_before.empty())
    {
      const std::vector<std::uint8_t> after = bytesOf(scratch);
      ASSERT_TRUE(std::all_of(after.begin(), after.end(), [](std::uint8_t f) { return f == 0; }))
          << "trial " << trial << ": the scratch must come back zeroed";
      ASSERT_EQ(0u, scratch.tilesInUse()) << "trial " << trial << ": a tile with no bit left is given back";
    }
    else
    {
      ASSERT_EQ(flagged_before, bytesOf(scratch))
          << "trial " << trial << ": the flagged cells must come back as they were";
      ++flagged_trials;
    }
    results += expected.cleared.size() + expected.free.size() + expected.hit.size();
  }
  EXPECT_GT(results, 10000u);  // the trials exercise the rules, not only empty watches
  EXPECT_GT(flagged_trials, 100u);
}

TEST(ScanWatch, ScratchOfTheWrongSizeIsRefused)
{
  const GridGeometry g(0.1, 0.0, 0.0, 10, 10);
  CostGrid grid(g, FREE_SPACE);
  Observation obs;
  obs.origin = Point3{ 0.05, 0.05, 0.0 };
  obs.points = { Point3{ 0.85, 0.05, 0.0 } };
  CellFlags scratch;
  scratch.assign(50);
  ScanWatch watch;
  watch.cells = { 3 };
  watch.scratch = &scratch;
  EXPECT_THROW(applyScan(grid, obs, ScanLimits(), watch), std::invalid_argument);
  watch.cells.clear();
  watch.loose_cells = { 100 };  // outside the grid
  watch.scratch = nullptr;
  EXPECT_THROW(applyScan(grid, obs, ScanLimits(), watch), std::invalid_argument);
}

TEST(ScanWatch, AClippedEndpointIsNoHit)
{
  // A beam to a point beyond the grid edge is raytraced to the edge cell (as costmap_2d clips it): that cell is
  // passed and seen free, but holds no endpoint.
  const GridGeometry g(0.1, 0.0, 0.0, 10, 10);
  Observation obs;
  obs.origin = Point3{ 0.05, 0.55, 0.0 };
  obs.points = { Point3{ 1.5, 0.55, 0.0 }, Point3{ 0.55, 0.95, 0.0 } };
  ScanLimits limits;
  limits.raytrace_range = 3.0;
  const std::uint32_t edge = g.getIndex(9, 5);
  const std::uint32_t end_in_grid = g.getIndex(5, 9);
  for (const bool flagged : { false, true })
  {
    CostGrid grid(g, FREE_SPACE);
    CellFlags scratch;
    scratch.assign(g.cellCount());
    ScanWatch watch;
    watch.scratch = &scratch;
    watch.regions = { CellRect{ 9, 5, 9, 5 }, CellRect{ 5, 9, 5, 9 } };
    if (flagged)
    {
      scratch.set(edge, ScanWatch::kFlaggedWatched);
      scratch.set(end_in_grid, ScanWatch::kFlaggedWatched);
    }
    else
    {
      watch.cells = { edge, end_in_grid };
    }
    const ScanTouch touch = applyScan(grid, obs, limits, watch);
    EXPECT_EQ(std::vector<std::uint32_t>{ end_in_grid }, touch.watched_hit) << "flagged " << flagged;
    EXPECT_EQ(std::vector<std::uint32_t>{ edge }, touch.watched_free) << "flagged " << flagged;
  }
}

TEST(ScanWatch, PointCellsGivenByTheCallerChangeNothing)
{
  // ScanPass looks each point's cell up once and hands them to applyScan (ScanWatch::point_cells): grids, marks,
  // bounds and evidence must be exactly those of a scan that looks them up itself, with points off the grid (clipped
  // beams), not finite and outside the height limits among them. A list of another length is refused.
  std::mt19937 rng(29);
  const GridGeometry g(0.05, -1.0, 2.0, 80, 60);
  std::uniform_real_distribution<double> ux(g.origin_x - 1.0, g.endX() + 1.0), uy(g.origin_y - 1.0, g.endY() + 1.0);
  for (int trial = 0; trial < 300; ++trial)
  {
    Observation obs;
    obs.origin = Point3{ g.origin_x + 2.0, g.origin_y + 1.5, 0.3 };
    for (int i = 0; i < 200; ++i)
    {
      const double z = rng() % 10 == 0 ? 5.0 : 0.3;
      obs.points.push_back(rng() % 50 == 0 ? Point3{ NAN, 1.0, 0.3 } : Point3{ ux(rng), uy(rng), z });
    }
    ScanLimits limits;
    limits.obstacle_range = 0.5 + (rng() % 30) * 0.1;
    limits.raytrace_range = 0.5 + (rng() % 40) * 0.1;
    limits.max_obstacle_height = 2.0;
    ScanWatch watch;
    watch.regions = { CellRect{ 10, 10, 30, 25 } };
    watch.cells = ScanWatch::fromRects(g, watch.regions).cells;
    CostGrid plain(g, NO_INFORMATION), given(g, NO_INFORMATION);
    const ScanTouch expected = applyScan(plain, obs, limits, watch);
    for (const Point3& p : obs.points)
    {
      ScanWatch::Cell cell{ ScanWatch::kNoCell, 0 };
      if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && p.z <= limits.max_obstacle_height &&
          !g.worldToMap(p.x, p.y, cell.x, cell.y))
      {
        cell.x = ScanWatch::kNoCell;
      }
      watch.point_cells.push_back(cell);
    }
    const ScanTouch touch = applyScan(given, obs, limits, watch);
    ASSERT_TRUE(std::equal(plain.data(), plain.data() + g.cellCount(), given.data())) << "trial " << trial;
    ASSERT_EQ(expected.marked, touch.marked) << "trial " << trial;
    ASSERT_EQ(expected.watched_cleared, touch.watched_cleared) << "trial " << trial;
    ASSERT_EQ(expected.watched_free, touch.watched_free) << "trial " << trial;
    ASSERT_EQ(expected.watched_hit, touch.watched_hit) << "trial " << trial;
    ASSERT_EQ(expected.min_x, touch.min_x);
    ASSERT_EQ(expected.max_y, touch.max_y);
    watch.point_cells.pop_back();
    EXPECT_THROW(applyScan(given, obs, limits, watch), std::invalid_argument);
  }
}
