#include "fleet_nav/grid_planner.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <queue>
#include <stdexcept>
#include <utility>

namespace fleet_nav
{
namespace
{
constexpr std::uint8_t kLethal = 254;
constexpr std::uint8_t kUnknown = 255;
constexpr double kSqrt2 = 1.41421356237309504880;

enum : std::uint8_t
{
  kUnseen = 0,
  kOpen = 1,
  kClosed = 2
};
}  // namespace

std::string describe(PlanStatus status)
{
  switch (status)
  {
    case PlanStatus::Ok:
      return "ok";
    case PlanStatus::StartOffGrid:
      return "the start is outside the costmap";
    case PlanStatus::GoalOffGrid:
      return "the goal is outside the costmap";
    case PlanStatus::GoalBlocked:
      return "the goal lies in an obstacle or its inscribed radius";
    case PlanStatus::NoPath:
      return "no path between start and goal";
  }
  return "unknown status";
}

void PlannerParams::validate() const
{
  if (!(neutral_cost > 0.0) || !std::isfinite(neutral_cost))
  {
    throw std::invalid_argument("neutral_cost must be > 0, got " + std::to_string(neutral_cost));
  }
  if (!(cost_factor >= 0.0) || !std::isfinite(cost_factor))
  {
    throw std::invalid_argument("cost_factor must be >= 0, got " + std::to_string(cost_factor));
  }
  if (lethal_cost < 1 || lethal_cost > kLethal)
  {
    throw std::invalid_argument("lethal_cost must be 1..254, got " + std::to_string(lethal_cost));
  }
}

GridPlanner::GridPlanner(const PlannerParams& params) : params_(params)
{
  params_.validate();
}

double GridPlanner::stepCost(std::uint8_t cost) const
{
  const double c = cost == kUnknown ? params_.unknown_cost : cost;
  return params_.neutral_cost + params_.cost_factor * c;
}

bool GridPlanner::blocked(std::uint8_t cost) const
{
  if (cost == kUnknown)
  {
    return !params_.allow_unknown;
  }
  return cost >= params_.lethal_cost;
}

PlanStatus GridPlanner::makePlan(const std::uint8_t* costs, unsigned int size_x, unsigned int size_y,
                                 std::uint32_t start, std::uint32_t goal, std::vector<std::uint32_t>& path,
                                 const CellWindow* window)
{
  if (costs == nullptr || size_x == 0 || size_y == 0)
  {
    throw std::invalid_argument("GridPlanner::makePlan: empty costmap");
  }
  path.clear();
  expansions_ = 0;
  const std::size_t n = static_cast<std::size_t>(size_x) * size_y;
  CellWindow win{ 0, 0, size_x, size_y };
  if (window != nullptr)
  {
    win.min_x = std::min(window->min_x, size_x);
    win.min_y = std::min(window->min_y, size_y);
    win.max_x = std::min(window->max_x, size_x);
    win.max_y = std::min(window->max_y, size_y);
  }
  auto inside = [&](unsigned int x, unsigned int y) {
    return x >= win.min_x && x < win.max_x && y >= win.min_y && y < win.max_y;
  };
  if (start >= n || !inside(start % size_x, start / size_x))
  {
    return PlanStatus::StartOffGrid;
  }
  if (goal >= n || !inside(goal % size_x, goal / size_x))
  {
    return PlanStatus::GoalOffGrid;
  }
  if (blocked(costs[goal]))
  {
    return PlanStatus::GoalBlocked;
  }
  if (g_.size() != n)
  {
    g_.assign(n, 0.0f);
    parent_.assign(n, 0);
    state_.assign(n, kUnseen);
    touched_.clear();
  }
  for (std::uint32_t i : touched_)
  {
    state_[i] = kUnseen;
  }
  touched_.clear();

  const unsigned int gx = goal % size_x, gy = goal / size_x;
  auto heuristic = [&](unsigned int x, unsigned int y) {
    const double dx = std::abs(static_cast<double>(x) - gx);
    const double dy = std::abs(static_cast<double>(y) - gy);
    return params_.neutral_cost * (std::max(dx, dy) + (kSqrt2 - 1.0) * std::min(dx, dy));
  };
  using Entry = std::pair<float, std::uint32_t>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> open;
  g_[start] = 0.0f;
  parent_[start] = start;
  state_[start] = kOpen;
  touched_.push_back(start);
  open.emplace(static_cast<float>(heuristic(start % size_x, start / size_x)), start);

  static const int kDx[8] = { 1, -1, 0, 0, 1, 1, -1, -1 };
  static const int kDy[8] = { 0, 0, 1, -1, 1, -1, 1, -1 };
  while (!open.empty())
  {
    const std::uint32_t u = open.top().second;
    open.pop();
    if (state_[u] == kClosed)
    {
      continue;
    }
    state_[u] = kClosed;
    ++expansions_;
    if (u == goal)
    {
      break;
    }
    const unsigned int ux = u % size_x, uy = u / size_x;
    // Escaping: a start in the inscribed zone may leave through inscribed (never lethal) cells.
    const unsigned int sx0 = start % size_x, sy0 = start / size_x;
    const bool escaping = blocked(costs[u]);
    auto near_start = [&](std::uint32_t i) {
      const unsigned int ix = i % size_x, iy = i / size_x;
      return std::max(ix > sx0 ? ix - sx0 : sx0 - ix, iy > sy0 ? iy - sy0 : sy0 - iy) <= params_.escape_cells;
    };
    auto passable = [&](std::uint32_t i) {
      const std::uint8_t c = costs[i];
      if (!blocked(c))
      {
        return true;
      }
      return escaping && c < kLethal && near_start(i);
    };
    for (int k = 0; k < 8; ++k)
    {
      const long nx = static_cast<long>(ux) + kDx[k];
      const long ny = static_cast<long>(uy) + kDy[k];
      if (nx < 0 || ny < 0 || !inside(static_cast<unsigned int>(nx), static_cast<unsigned int>(ny)))
      {
        continue;
      }
      const std::uint32_t v = static_cast<std::uint32_t>(ny) * size_x + static_cast<std::uint32_t>(nx);
      if (state_[v] == kClosed || !passable(v))
      {
        continue;
      }
      const bool diagonal = k >= 4;
      if (diagonal && (!passable(uy * size_x + static_cast<std::uint32_t>(nx)) ||
                       !passable(static_cast<std::uint32_t>(ny) * size_x + ux)))
      {
        continue;  // no corner cutting
      }
      const double g = g_[u] + (diagonal ? kSqrt2 : 1.0) * stepCost(costs[v]);
      if (state_[v] == kUnseen || g < g_[v])
      {
        if (state_[v] == kUnseen)
        {
          touched_.push_back(v);
        }
        g_[v] = static_cast<float>(g);
        parent_[v] = u;
        state_[v] = kOpen;
        open.emplace(static_cast<float>(g + heuristic(static_cast<unsigned int>(nx), static_cast<unsigned int>(ny))),
                     v);
      }
    }
  }
  if (state_[goal] != kClosed)
  {
    return PlanStatus::NoPath;
  }
  last_cost_ = g_[goal];
  for (std::uint32_t i = goal;; i = parent_[i])
  {
    path.push_back(i);
    if (i == start)
    {
      break;
    }
  }
  std::reverse(path.begin(), path.end());
  return PlanStatus::Ok;
}

long firstBlocked(const std::uint8_t* costs, std::size_t cell_count, const std::vector<std::uint32_t>& path,
                  std::size_t from, std::size_t count, std::uint8_t lethal_cost)
{
  const std::size_t end = std::min(path.size(), from + count);
  for (std::size_t i = from; i < end; ++i)
  {
    if (path[i] >= cell_count)
    {
      throw std::invalid_argument("firstBlocked: path cell " + std::to_string(path[i]) + " outside the grid of " +
                                  std::to_string(cell_count) + " cells");
    }
    const std::uint8_t c = costs[path[i]];
    if (c >= lethal_cost && c != 255)
    {
      return static_cast<long>(i);
    }
  }
  return -1;
}

}  // namespace fleet_nav
