#ifndef SHARING_LAYER_PROPOSALS_H
#define SHARING_LAYER_PROPOSALS_H

#include <cstdint>
#include <string>
#include <vector>

#include "sharing_layer/grid_geometry.h"
#include "sharing_layer/subsection.h"

namespace sharing_layer
{
/// @brief How candidate cells are grouped into proposals.
enum class ProposalStrategy
{
  Sectors,   ///< the thesis: four sectors split by the diagonals through the robot
  Clusters,  ///< one proposal per connected group of cells
};

/// @brief Parses "sectors" or "clusters"; @throws std::invalid_argument naming the bad value.
ProposalStrategy parseProposalStrategy(const std::string& name);

/// @brief Sectors of the thesis, split by y = (x - rx) + ry and y = -(x - rx) + ry.
enum class Sector
{
  East = 0,   ///< dx >= |dy|, dx > 0 (the diagonals themselves belong to east and west)
  North = 1,  ///< dy > |dx|
  West = 2,   ///< -dx >= |dy|, dx < 0
  South = 3,  ///< -dy > |dx|
};

/// @brief The sector of the point (x, y) seen from the robot at (rx, ry); the robot's own point is East.
Sector sectorOf(double x, double y, double rx, double ry);

/// @brief A new obstacle the layer suggests: candidate cells and their bounding rectangle.
struct Proposal
{
  std::vector<std::uint32_t> cells;  ///< sorted
  Subsection rectangle;              ///< cell-edge bounding box of the cells, grown by the padding
};

/// @brief Bounding box of cells (cell edges), grown by padding metres on every side.
Subsection boundingSubsection(const GridGeometry& geometry, const std::vector<std::uint32_t>& cells, double padding);

/// @brief One proposal per non-empty sector, in East, North, West, South order.
std::vector<Proposal> proposeBySectors(const GridGeometry& geometry, const std::vector<std::uint32_t>& cells,
                                       double robot_x, double robot_y, double padding);

/**
 * @brief One proposal per group of cells connected within max_gap cells (Chebyshev distance;
 * 1 = 8-connectivity); groups smaller than min_cells are dropped. Sorted by first cell.
 */
std::vector<Proposal> proposeByClusters(const GridGeometry& geometry, const std::vector<std::uint32_t>& cells,
                                        unsigned int max_gap, std::size_t min_cells, double padding);

}  // namespace sharing_layer

#endif  // SHARING_LAYER_PROPOSALS_H
