#include "sharing_layer/fleet_robots.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <stdexcept>

namespace sharing_layer
{
void FleetRobotParams::validate() const
{
  if (!std::isfinite(margin) || margin < 0.0 || margin > kMaxFootprintExtent)
  {
    throw std::invalid_argument("robot_exclusion_margin must be 0.." + std::to_string(kMaxFootprintExtent) +
                                " m, got " + std::to_string(margin));
  }
  if (!std::isfinite(timeout) || timeout < 0.0)
  {
    throw std::invalid_argument("robot_timeout must be finite and >= 0 s, got " + std::to_string(timeout));
  }
  if (!std::isfinite(trail) || trail < 0.0 || trail > kMaxTrail)
  {
    throw std::invalid_argument("robot_exclusion_trail must be 0.." + std::to_string(kMaxTrail) + " s, got " +
                                std::to_string(trail));
  }
}

FleetRobots::FleetRobots(const GridGeometry& geometry, const FleetRobotParams& params)
  : geometry_(geometry), params_(params)
{
  params_.validate();
}

void FleetRobots::setParams(const FleetRobotParams& params)
{
  params.validate();
  params_ = params;
  rebuild();
}

void FleetRobots::check(const FleetRobot& robot)
{
  if (robot.name.empty())
  {
    throw std::invalid_argument("fleet robot: empty name");
  }
  const std::string what = "fleet robot " + robot.name + ": ";
  if (!std::isfinite(robot.stamp))
  {
    throw std::invalid_argument(what + "stamp not finite");
  }
  if (robot.footprint.empty() || robot.footprint.size() > kMaxFootprintPoints)
  {
    throw std::invalid_argument(what + "footprint has " + std::to_string(robot.footprint.size()) +
                                " vertices, expected 1.." + std::to_string(kMaxFootprintPoints));
  }
  double min_x = robot.footprint.front().first, max_x = min_x;
  double min_y = robot.footprint.front().second, max_y = min_y;
  for (const auto& p : robot.footprint)
  {
    if (!std::isfinite(p.first) || !std::isfinite(p.second))
    {
      throw std::invalid_argument(what + "footprint vertex not finite");
    }
    min_x = std::min(min_x, p.first);
    max_x = std::max(max_x, p.first);
    min_y = std::min(min_y, p.second);
    max_y = std::max(max_y, p.second);
  }
  if (max_x - min_x > kMaxFootprintExtent || max_y - min_y > kMaxFootprintExtent)
  {
    throw std::invalid_argument(what + "footprint " + std::to_string(max_x - min_x) + " x " +
                                std::to_string(max_y - min_y) + " m is larger than " +
                                std::to_string(kMaxFootprintExtent) + " m: not a robot");
  }
}

void FleetRobots::include(const std::vector<std::uint32_t>& cells)
{
  if (excluded_.empty())
  {
    excluded_.assign(geometry_.cellCount());
  }
  for (std::uint32_t index : cells)
  {
    excluded_.set(index);
  }
}

void FleetRobots::release(const std::vector<std::uint32_t>& cells)
{
  if (excluded_.empty())
  {
    return;
  }
  for (std::uint32_t index : cells)
  {
    excluded_.reset(index);
  }
  // One bit per cell instead of a count of the robots over it: where two footprints overlap, the other robot's
  // cells are set again (a few hundred cells per robot in view).
  for (const auto& entry : cells_)
  {
    if (&entry.second != &cells)
    {
      for (std::uint32_t index : entry.second)
      {
        excluded_.set(index);
      }
    }
  }
}

namespace
{
/// Largest move (m) between two footprints of one robot taken as driving; a longer one is a jump (relocalised,
/// restarted) and is not extrapolated.
constexpr double kMaxExtrapolatedMove = 2.0;

std::pair<double, double> centroid(const std::vector<std::pair<double, double>>& polygon)
{
  double x = 0.0, y = 0.0;
  for (const auto& p : polygon)
  {
    x += p.first;
    y += p.second;
  }
  return { x / polygon.size(), y / polygon.size() };
}
}  // namespace

bool FleetRobots::drivable(const std::deque<PastFootprint>& past, std::pair<double, double> here, double stamp)
{
  return std::all_of(past.begin(), past.end(), [&](const PastFootprint& kept) {
    const double reach = kMaxTrailSpeed * std::max(0.0, stamp - kept.stamp) + kTrailSlack;
    return std::hypot(here.first - kept.centroid.first, here.second - kept.centroid.second) <= reach;
  });
}

std::vector<std::uint32_t> FleetRobots::unite(const std::vector<const std::vector<std::uint32_t>*>& parts)
{
  std::uint32_t lo = std::numeric_limits<std::uint32_t>::max(), hi = 0;
  std::size_t total = 0;
  for (const std::vector<std::uint32_t>* part : parts)
  {
    if (!part->empty())
    {
      lo = std::min(lo, part->front());  // each part is sorted
      hi = std::max(hi, part->back());
      total += part->size();
    }
  }
  std::vector<std::uint32_t> cells;
  if (total == 0)
  {
    return cells;
  }
  cells.reserve(total);
  // A second of footprints overlaps itself ten times over: a bit per cell between the lowest and the highest
  // index (the rows the trail spans) is cheaper than sorting them all, unless those rows are far apart.
  const std::uint64_t span = static_cast<std::uint64_t>(hi) - lo + 1;
  if (span > 64 * total)
  {
    for (const std::vector<std::uint32_t>* part : parts)
    {
      cells.insert(cells.end(), part->begin(), part->end());
    }
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    return cells;
  }
  scratch_.assign(static_cast<std::size_t>((span + 63) / 64), 0);
  for (const std::vector<std::uint32_t>* part : parts)
  {
    for (std::uint32_t index : *part)
    {
      scratch_[(index - lo) / 64] |= std::uint64_t{ 1 } << ((index - lo) % 64);
    }
  }
  for (std::size_t w = 0; w < scratch_.size(); ++w)
  {
    for (std::uint64_t bits = scratch_[w]; bits != 0; bits &= bits - 1)
    {
      cells.push_back(lo + static_cast<std::uint32_t>(w * 64 + __builtin_ctzll(bits)));
    }
  }
  return cells;
}

void FleetRobots::update(const FleetRobot& robot)
{
  const auto known = robots_.find(robot.name);
  const auto motion = motion_.find(robot.name);
  update(robot, known == robots_.end() ? nullptr : &known->second,
         motion == motion_.end() ? std::make_pair(0.0, 0.0) : motion->second);
}

void FleetRobots::update(const FleetRobot& robot, const FleetRobot* previous, std::pair<double, double> motion)
{
  check(robot);
  std::vector<const std::vector<std::uint32_t>*> parts;
  std::vector<std::uint32_t> ahead_cells;
  const auto here = centroid(robot.footprint);
  bool jumped = false;
  // A driving robot is where its next advert will put it before that advert arrives: the footprint moved
  // on by as much as it moved since the previous advert is excluded too (the cells a moving robot's front
  // covers until the next refresh, else marked and shared as an obstacle). The same advert passed on again
  // (same stamp) keeps the motion; a new advert from a robot that stood still ends it.
  if (previous != nullptr && !previous->footprint.empty())
  {
    const auto before = centroid(previous->footprint);
    const std::pair<double, double> step = { here.first - before.first, here.second - before.second };
    jumped = std::hypot(step.first, step.second) > kMaxExtrapolatedMove;
    if (previous->stamp != robot.stamp)
    {
      motion = step;
    }
  }
  const double moved = std::hypot(motion.first, motion.second);
  if (!(moved > 0.5 * geometry_.resolution && moved <= kMaxExtrapolatedMove))
  {
    motion = { 0.0, 0.0 };
  }
  motion_[robot.name] = motion;
  if (motion.first != 0.0 || motion.second != 0.0)
  {
    std::vector<std::pair<double, double>> ahead(robot.footprint);
    for (auto& p : ahead)
    {
      p.first += motion.first;
      p.second += motion.second;
    }
    ahead_cells = rasterize(geometry_, ahead, params_.margin);
    parts.push_back(&ahead_cells);
  }
  // Its footprint now (the trail's last), and behind it where it was while the scans the layer has yet to mark
  // were taken. A footprint holds from its stamp until the next one's, so it is dropped once the next one is
  // older than the trail. The same footprint again is not rasterized again.
  std::deque<PastFootprint>& past = trail_[robot.name];
  if (jumped || (!past.empty() && robot.stamp < past.back().stamp) || !drivable(past, here, robot.stamp))
  {
    past.clear();
  }
  if (past.empty() || past.back().footprint != robot.footprint)
  {
    past.push_back(PastFootprint{ robot.stamp, robot.footprint, here,
                                  rasterize(geometry_, robot.footprint, params_.margin) });
  }
  while (past.size() >= 2 && (past[1].stamp <= robot.stamp - params_.trail || past.size() > kMaxTrailFootprints))
  {
    past.pop_front();
  }
  for (const PastFootprint& footprint : past)
  {
    parts.push_back(&footprint.cells);
  }
  std::vector<std::uint32_t> cells = unite(parts);
  auto found = cells_.find(robot.name);
  if (found != cells_.end())
  {
    release(found->second);
  }
  include(cells);
  cells_[robot.name] = std::move(cells);
  robots_[robot.name] = robot;
}

void FleetRobots::replaceAll(const std::vector<FleetRobot>& robots)
{
  for (const FleetRobot& robot : robots)
  {
    check(robot);
  }
  const std::map<std::string, FleetRobot> previous = robots_;
  const std::map<std::string, std::pair<double, double>> motions = motion_;
  clearCells();
  robots_.clear();
  motion_.clear();
  for (const FleetRobot& robot : robots)
  {
    const auto known = previous.find(robot.name);
    const auto motion = motions.find(robot.name);
    update(robot, known == previous.end() ? nullptr : &known->second,
           motion == motions.end() ? std::make_pair(0.0, 0.0) : motion->second);
  }
  for (auto it = trail_.begin(); it != trail_.end();)  // the trails of robots the message left out
  {
    it = robots_.count(it->first) != 0 ? std::next(it) : trail_.erase(it);
  }
}

bool FleetRobots::forget(const std::string& name)
{
  auto found = cells_.find(name);
  if (found == cells_.end())
  {
    return false;
  }
  release(found->second);
  cells_.erase(found);
  robots_.erase(name);
  motion_.erase(name);
  trail_.erase(name);
  return true;
}

void FleetRobots::setGeometry(const GridGeometry& geometry)
{
  excluded_.release();  // sized for the old grid; rebuild() clears the cell lists
  geometry_ = geometry;
  rebuild();
}

void FleetRobots::rebuild()
{
  const std::map<std::string, FleetRobot> known = robots_;
  const std::map<std::string, std::pair<double, double>> motions = motion_;
  clearCells();
  robots_.clear();
  motion_.clear();
  for (auto& entry : trail_)
  {
    for (PastFootprint& past : entry.second)
    {
      past.cells = rasterize(geometry_, past.footprint, params_.margin);
    }
  }
  for (const auto& entry : known)
  {
    const auto motion = motions.find(entry.first);
    update(entry.second, nullptr, motion != motions.end() ? motion->second : std::make_pair(0.0, 0.0));
  }
}

void FleetRobots::clearCells()
{
  if (!excluded_.empty())
  {
    for (const auto& entry : cells_)
    {
      for (std::uint32_t index : entry.second)
      {
        excluded_.reset(index);
      }
    }
  }
  cells_.clear();
}

void FleetRobots::clear()
{
  clearCells();
  robots_.clear();
  motion_.clear();
  trail_.clear();
}

std::vector<std::string> FleetRobots::expire(double now_s)
{
  std::vector<std::string> gone;
  if (params_.timeout <= 0.0 || !std::isfinite(now_s))
  {
    return gone;
  }
  for (const auto& entry : robots_)
  {
    // A stamp far in the future means the clock went backwards (a restarted simulation): as stale.
    if (std::fabs(now_s - entry.second.stamp) > params_.timeout)
    {
      gone.push_back(entry.first);
    }
  }
  for (const std::string& name : gone)
  {
    forget(name);
  }
  return gone;
}

std::vector<std::uint32_t> FleetRobots::excludedCells() const
{
  std::vector<std::uint32_t> cells;
  for (const auto& entry : cells_)
  {
    cells.insert(cells.end(), entry.second.begin(), entry.second.end());
  }
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  return cells;
}

std::vector<std::string> FleetRobots::robotsAt(std::uint32_t index) const
{
  std::vector<std::string> names;
  if (!excludes(index))
  {
    return names;
  }
  for (const auto& entry : cells_)
  {
    if (std::binary_search(entry.second.begin(), entry.second.end(), index))
    {
      names.push_back(entry.first);
    }
  }
  return names;
}

std::vector<std::string> FleetRobots::names() const
{
  std::vector<std::string> out;
  for (const auto& entry : robots_)
  {
    out.push_back(entry.first);
  }
  return out;
}

namespace
{
/// Crossing-number test; points on the outline may go either way (the margin covers them).
bool insidePolygon(const std::vector<std::pair<double, double>>& poly, double x, double y)
{
  bool inside = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++)
  {
    const double xi = poly[i].first, yi = poly[i].second, xj = poly[j].first, yj = poly[j].second;
    if ((yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi)
    {
      inside = !inside;
    }
  }
  return inside;
}

double segmentDistanceSq(double px, double py, double ax, double ay, double bx, double by)
{
  const double vx = bx - ax, vy = by - ay;
  const double len_sq = vx * vx + vy * vy;
  double t = len_sq > 0.0 ? ((px - ax) * vx + (py - ay) * vy) / len_sq : 0.0;
  t = std::min(1.0, std::max(0.0, t));
  const double dx = ax + t * vx - px, dy = ay + t * vy - py;
  return dx * dx + dy * dy;
}
}  // namespace

std::vector<std::uint32_t> FleetRobots::rasterize(const GridGeometry& g,
                                                  const std::vector<std::pair<double, double>>& footprint,
                                                  double margin)
{
  std::vector<std::uint32_t> cells;
  if (footprint.empty())
  {
    return cells;
  }
  double min_x = footprint.front().first, max_x = min_x;
  double min_y = footprint.front().second, max_y = min_y;
  for (const auto& p : footprint)
  {
    min_x = std::min(min_x, p.first);
    max_x = std::max(max_x, p.first);
    min_y = std::min(min_y, p.second);
    max_y = std::max(max_y, p.second);
  }
  // Cells whose centre may lie within the bounding box grown by the margin, clipped to the grid.
  const double x0 = std::floor((min_x - margin - g.origin_x) / g.resolution - 0.5);
  const double x1 = std::ceil((max_x + margin - g.origin_x) / g.resolution - 0.5);
  const double y0 = std::floor((min_y - margin - g.origin_y) / g.resolution - 0.5);
  const double y1 = std::ceil((max_y + margin - g.origin_y) / g.resolution - 0.5);
  if (x1 < 0.0 || y1 < 0.0 || x0 >= g.size_x || y0 >= g.size_y)
  {
    return cells;
  }
  const unsigned int cx0 = static_cast<unsigned int>(std::max(0.0, x0));
  const unsigned int cy0 = static_cast<unsigned int>(std::max(0.0, y0));
  const unsigned int cx1 = static_cast<unsigned int>(std::min<double>(g.size_x - 1, x1));
  const unsigned int cy1 = static_cast<unsigned int>(std::min<double>(g.size_y - 1, y1));
  const double margin_sq = margin * margin;
  const bool polygon = footprint.size() >= 3;
  for (unsigned int my = cy0; my <= cy1; ++my)
  {
    for (unsigned int mx = cx0; mx <= cx1; ++mx)
    {
      double wx = 0.0, wy = 0.0;
      g.mapToWorld(mx, my, wx, wy);
      bool covered = polygon && insidePolygon(footprint, wx, wy);
      for (std::size_t i = 0; !covered && i < footprint.size(); ++i)
      {
        const auto& a = footprint[i];
        const auto& b = footprint[(i + 1) % footprint.size()];
        covered = segmentDistanceSq(wx, wy, a.first, a.second, b.first, b.second) <= margin_sq;
      }
      if (covered)
      {
        cells.push_back(g.getIndex(mx, my));
      }
    }
  }
  return cells;  // row by row: already sorted
}

}  // namespace sharing_layer
