#include "sharing_layer/proposals.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

namespace sharing_layer
{
ProposalStrategy parseProposalStrategy(const std::string& name)
{
  if (name == "sectors")
  {
    return ProposalStrategy::Sectors;
  }
  if (name == "clusters")
  {
    return ProposalStrategy::Clusters;
  }
  throw std::invalid_argument("proposal_strategy must be \"sectors\" or \"clusters\", got \"" + name + "\"");
}

Sector sectorOf(double x, double y, double rx, double ry)
{
  const double dx = x - rx;
  const double dy = y - ry;
  if (std::fabs(dx) >= std::fabs(dy))
  {
    return dx < 0.0 ? Sector::West : Sector::East;
  }
  return dy > 0.0 ? Sector::North : Sector::South;
}

Subsection boundingSubsection(const GridGeometry& g, const std::vector<std::uint32_t>& cells, double padding)
{
  if (cells.empty())
  {
    throw std::invalid_argument("boundingSubsection: no cells");
  }
  unsigned int min_x = std::numeric_limits<unsigned int>::max(), min_y = min_x, max_x = 0, max_y = 0;
  for (std::uint32_t index : cells)
  {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    min_x = std::min(min_x, mx);
    min_y = std::min(min_y, my);
    max_x = std::max(max_x, mx);
    max_y = std::max(max_y, my);
  }
  return Subsection(g.origin_x + min_x * g.resolution - padding, g.origin_y + min_y * g.resolution - padding,
                    g.origin_x + (max_x + 1) * g.resolution + padding,
                    g.origin_y + (max_y + 1) * g.resolution + padding);
}

std::vector<Proposal> proposeBySectors(const GridGeometry& g, const std::vector<std::uint32_t>& cells,
                                       double robot_x, double robot_y, double padding)
{
  std::vector<std::uint32_t> by_sector[4];
  for (std::uint32_t index : cells)
  {
    unsigned int mx = 0, my = 0;
    g.indexToCells(index, mx, my);
    double wx = 0.0, wy = 0.0;
    g.mapToWorld(mx, my, wx, wy);
    by_sector[static_cast<int>(sectorOf(wx, wy, robot_x, robot_y))].push_back(index);
  }
  std::vector<Proposal> proposals;
  for (auto& sector_cells : by_sector)
  {
    if (sector_cells.empty())
    {
      continue;
    }
    std::sort(sector_cells.begin(), sector_cells.end());
    Proposal proposal;
    proposal.rectangle = boundingSubsection(g, sector_cells, padding);
    proposal.cells = std::move(sector_cells);
    proposals.push_back(std::move(proposal));
  }
  return proposals;
}

std::vector<Proposal> proposeByClusters(const GridGeometry& g, const std::vector<std::uint32_t>& cells,
                                        unsigned int max_gap, std::size_t min_cells, double padding)
{
  std::vector<std::uint32_t> sorted(cells);
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  std::unordered_map<std::uint32_t, std::size_t> position;
  position.reserve(sorted.size());
  for (std::size_t i = 0; i < sorted.size(); ++i)
  {
    position[sorted[i]] = i;
  }
  const int gap = static_cast<int>(std::max(1u, max_gap));
  std::vector<int> label(sorted.size(), -1);
  std::vector<Proposal> proposals;
  std::vector<std::size_t> stack;
  for (std::size_t seed = 0; seed < sorted.size(); ++seed)
  {
    if (label[seed] >= 0)
    {
      continue;
    }
    const int id = static_cast<int>(proposals.size());
    std::vector<std::uint32_t> group;
    label[seed] = id;
    stack.assign(1, seed);
    while (!stack.empty())
    {
      const std::size_t current = stack.back();
      stack.pop_back();
      group.push_back(sorted[current]);
      unsigned int mx = 0, my = 0;
      g.indexToCells(sorted[current], mx, my);
      for (int dy = -gap; dy <= gap; ++dy)
      {
        for (int dx = -gap; dx <= gap; ++dx)
        {
          const long nx = static_cast<long>(mx) + dx;
          const long ny = static_cast<long>(my) + dy;
          if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= g.size_x || ny >= g.size_y)
          {
            continue;
          }
          const auto found = position.find(g.getIndex(static_cast<unsigned int>(nx), static_cast<unsigned int>(ny)));
          if (found != position.end() && label[found->second] < 0)
          {
            label[found->second] = id;
            stack.push_back(found->second);
          }
        }
      }
    }
    std::sort(group.begin(), group.end());
    Proposal proposal;
    proposal.rectangle = boundingSubsection(g, group, padding);
    proposal.cells = std::move(group);
    proposals.push_back(std::move(proposal));
  }
  proposals.erase(std::remove_if(proposals.begin(), proposals.end(),
                                 [min_cells](const Proposal& p) { return p.cells.size() < min_cells; }),
                  proposals.end());
  return proposals;
}

}  // namespace sharing_layer
